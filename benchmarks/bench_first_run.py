"""First run of a robot: `gecgen identify` and `gecgen calibrate` with an empty code cache (cold) and
again once its code is compiled (warm), each a whole fresh process.

    python benchmarks/bench_first_run.py          # prints a table, updates docs/benchmarks.md

Cases: the TIAGo training file imported as docs/real-data-tiago.md does (37 postures, four markers,
the default model robots/tiago.errors.yaml), identify and calibrate (with the validation file's
marker 1), and 450 simulated PPS poses with the default model. Cold is a fresh cache folder each
time: the model runs in numpy while a background process builds its C; "cold, C first" is the same
with GECGEN_BACKEND=c, the fit waiting for the C as before. Between runs the benchmark waits for
every background build to end, so none runs beside a measured run; warm reuses the first cold
run's cache.
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


def builds_running(cache: Path) -> bool:
    """Whether a background build (`python -m gecgen.runtime.background`) into cache runs."""
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            if b"gecgen.runtime.background" in (proc / "cmdline").read_bytes() and \
                    f"GECGEN_CACHE={cache}".encode() in (proc / "environ").read_bytes().split(b"\0") and \
                    (proc / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                return True
        except OSError:
            continue
    return False


def run(args: list[str], cache: Path, backend: str | None = None) -> tuple[float, float, float]:
    """(wall time, CPU time of the process and the children it waits for (a compiler it runs in the
    foreground, under GECGEN_BACKEND=c); wall time until its background builds ended), s."""
    env = {k: v for k, v in os.environ.items() if k != "GECGEN_BACKEND"} | {"GECGEN_CACHE": str(cache)}
    if backend:
        env["GECGEN_BACKEND"] = backend
    before, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    subprocess.run([shutil.which("gecgen"), *args], capture_output=True, check=True, cwd=ROOT, env=env)
    wall, after = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    while builds_running(cache):
        time.sleep(0.2)
    return wall, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, time.perf_counter() - t0


def measured(args: list[str], cold: int, warm: int) -> dict[str, tuple[float, ...]]:
    """Best (wall, CPU, until built) of the cold runs, the cold runs with the C first and the warm runs."""
    with tempfile.TemporaryDirectory(prefix="gecgen-bench-") as tmp:
        out = {"cold": [run(args, Path(tmp) / f"cache{k}") for k in range(cold)],
               "cold, C first": [run(args, Path(tmp) / f"c{k}", "c") for k in range(cold)]}
        run(args, Path(tmp) / "cache0")  # the builds the first run left to its next
        out["warm"] = [run(args, Path(tmp) / "cache0") for _ in range(warm)]
    return {key: tuple(min(r[k] for r in runs) for k in range(3)) for key, runs in out.items()}


def main():
    load_average = os.getloadavg()[0]
    out = ROOT / "out" / "bench"
    out.mkdir(parents=True, exist_ok=True)
    tiago, val = out / "tiago-train.csv", out / "tiago-val-m1.csv"
    for source, target, extra in (("train_2021-11-30", tiago, []), ("validation_2021-11-26", val, ["--targets", "m1"])):
        subprocess.run([shutil.which("gecgen"), "import", "robots/tiago.yaml", f"tests/data/tiago-mocap/{source}.csv",
                        "--mapping", "robots/tiago.import.yaml", *extra, "-o", str(target)], capture_output=True,
                       check=True, cwd=ROOT)
    pps = out / "first-run-pps450.csv"
    simulated_csv(pps, 450)
    cases = [("TIAGo identify, 37 postures x 4 markers", ["identify", "robots/tiago.yaml", str(tiago), "-o",
                                                          str(out / "tiago.calib.json")], 3, 5),
             ("TIAGo calibrate, with the other day's marker 1", ["calibrate", "robots/tiago.yaml", str(tiago), "--val",
                                                                 str(val), "-o", str(out / "tiago-calibrate")], 2, 2),
             ("PPS identify, 450 simulated poses", ["identify", "robots/pps.yaml", str(pps), "-o",
                                                    str(out / "pps.calib.json")], 3, 5)]
    rows = [(name, measured(args, cold, warm)) for name, args, cold, warm in cases]
    for name, m in rows:
        print(f"{name:48s} " + "   ".join(f"{key} {w:6.2f} s ({c:.2f} s CPU)" for key, (w, c, _) in m.items())
              + f"   C built after {m['cold'][2]:.1f} s")
    lines = ["## First run: with and without the robot's code compiled", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, load average {load_average:.1f} when the "
             "benchmark started. Regenerate: `python benchmarks/bench_first_run.py`. A whole fresh process each, "
             "with the robot's default error model. Cold: an empty code cache; the model runs in numpy (no sympy, "
             "jinja2 or emitter for identify: these default models' terms are read without sympy) while a background process builds its C, whose "
             "CPU time is not in the figures (\"C built after\": from the start of the run until that build "
             "ended). Cold, C first: GECGEN_BACKEND=c, the run waits for its C to be generated, printed and "
             "compiled. Warm: the first cold run's cache after one more run (calibrate compiles, one at a time, the "
             "models of its candidates that its first run left in numpy). calibrate prints the C of the model it "
             "chooses (its deliverable), checks its example command in numpy and leaves that model's compile to "
             "the background too; on two loaded cores the background build also competes with the run it serves, which shows in the "
             "cold wall times. "
             "Best of 3 cold and 5 warm for identify, 2 each for calibrate. TIAGo: the files imported as "
             "docs/real-data-tiago.md does. Wall times depend on the machine's load; the CPU time (the process "
             "and the compiler it waits for, user and system) much less.",
             "", "| command, robot and data | cold wall (s) | cold CPU (s) | C built after (s) | cold, C first: wall (s) "
             "| CPU (s) | warm wall (s) | warm CPU (s) |", "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {name} | {m['cold'][0]:.2f} | {m['cold'][1]:.2f} | {m['cold'][2]:.1f} | {m['cold, C first'][0]:.2f} "
              f"| {m['cold, C first'][1]:.2f} | {m['warm'][0]:.2f} | {m['warm'][1]:.2f} |" for name, m in rows]
    write_section("first-run", "\n".join(lines))


if __name__ == "__main__":
    main()
