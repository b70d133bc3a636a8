"""First run of a robot: `gecgen identify` with an empty code cache (cold) and again with its code
compiled (warm), each a whole fresh process.

    python benchmarks/bench_first_run.py          # prints a table, updates docs/benchmarks.md

Cases: the TIAGo training file imported as docs/real-data-tiago.md does (37 postures, four markers,
the default model robots/tiago.errors.yaml) and 450 simulated PPS poses with the default model.
Cold is a fresh cache folder each time (best of 3): generating, printing and compiling the C;
warm reuses it (best of 5). A warm run loads neither sympy nor the emitter.
"""
from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runtime import ROOT, cpu_model, simulated_csv, write_section  # noqa: E402

COLD, WARM = 3, 5


def run(args: list[str], cache: Path) -> tuple[float, float]:
    """(wall time, CPU time of the process and its children: the compiler's too), s."""
    before, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    subprocess.run([shutil.which("gecgen"), *args], capture_output=True, check=True, cwd=ROOT,
                   env={**os.environ, "GECGEN_CACHE": str(cache)})
    wall, after = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def cold_and_warm(args: list[str]) -> tuple[float, float, float, float]:
    """Best wall and CPU times, cold then warm, s."""
    cold = []
    with tempfile.TemporaryDirectory(prefix="gecgen-bench-") as tmp:
        for k in range(COLD):
            cold.append(run(args, Path(tmp) / f"cache{k}"))
        warm = [run(args, Path(tmp) / "cache0") for _ in range(WARM)]
    return (min(w for w, _ in cold), min(c for _, c in cold), min(w for w, _ in warm), min(c for _, c in warm))


def main():
    load_average = os.getloadavg()[0]
    out = ROOT / "out" / "bench"
    out.mkdir(parents=True, exist_ok=True)
    tiago = out / "tiago-train.csv"
    subprocess.run([shutil.which("gecgen"), "import", "robots/tiago.yaml", "tests/data/tiago-mocap/train_2021-11-30.csv",
                    "--mapping", "robots/tiago.import.yaml", "-o", str(tiago)], capture_output=True, check=True, cwd=ROOT)
    pps = out / "first-run-pps450.csv"
    simulated_csv(pps, 450)
    cases = [("TIAGo, 37 postures x 4 markers", ["identify", "robots/tiago.yaml", str(tiago), "-o",
                                                 str(out / "tiago.calib.json")]),
             ("PPS, 450 simulated poses", ["identify", "robots/pps.yaml", str(pps), "-o", str(out / "pps.calib.json")])]
    rows = [(name, *cold_and_warm(args)) for name, args in cases]
    for name, cold, cold_cpu, warm, warm_cpu in rows:
        print(f"{name:34s} cold {cold:6.2f} s ({cold_cpu:.2f} s CPU)   warm {warm:6.2f} s ({warm_cpu:.2f} s CPU)")
    lines = ["## First run: identify with and without its code compiled", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, load average {load_average:.1f} when the "
             "benchmark started. Regenerate: `python benchmarks/bench_first_run.py`. `gecgen identify` with the "
             "robot's default error model, a whole fresh process each: cold with an empty code cache (best of "
             f"{COLD}: the C is generated, printed and compiled), warm with it compiled (best of {WARM}: no sympy, "
             "jinja2 or emitter loaded). TIAGo: the training file imported as docs/real-data-tiago.md does. "
             "Wall times depend on the machine's load; the CPU time (the process and the compiler it runs, user "
             "and system) much less.",
             "", "| robot and data | cold wall (s) | cold CPU (s) | warm wall (s) | warm CPU (s) |", "|---|---|---|---|---|"]
    lines += [f"| {name} | {cold:.2f} | {cold_cpu:.2f} | {warm:.2f} | {warm_cpu:.2f} |"
              for name, cold, cold_cpu, warm, warm_cpu in rows]
    write_section("first-run", "\n".join(lines))


if __name__ == "__main__":
    main()
