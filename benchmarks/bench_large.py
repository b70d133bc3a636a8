"""Large inputs: how time and memory grow with the data, the joints and the signals.

    python benchmarks/bench_large.py             # prints a table, updates docs/benchmarks.md

Each case is a `gecgen` command in its own process, as a user runs it; peak = that process's
maximum resident memory. The inputs are written into out/bench first:
- industrial6r measurements from `gecgen simulate` (its default error model, 330 coefficients),
  200,000 and 1,000,000 poses of one target: memory per row is the slope between the two;
- 200 of those poses with 10,000 auxiliary columns of noise (diagnose offers each as a candidate);
- a 100-joint DH chain (alternating +-90 degree twists), constant errors, structural redundancy
  with an empty code cache (the symbolic build and the C compile of its generated code) and warm.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_runtime import cpu_model, write_section  # noqa: E402

# the command's wall time and its maximum resident memory, measured from a parent that does nothing else
TIMED = r"""
import json, resource, subprocess, sys, time
t = time.perf_counter()
run = subprocess.run(sys.argv[1:], capture_output=True, text=True)
print(json.dumps({"s": time.perf_counter() - t, "peak_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
                  "rc": run.returncode, "stdout": run.stdout, "stderr": run.stderr[-2000:]}))
"""


def timed(*args: str, env: dict | None = None) -> dict:
    out = subprocess.run([sys.executable, "-c", TIMED, *args], capture_output=True, text=True, check=True,
                         env={**os.environ, **(env or {})})
    return json.loads(out.stdout)


def gecgen(*args: str) -> list[str]:
    return [str(Path(sys.executable).with_name("gecgen")), *args]


def chain_file(path: Path, n: int):
    rows = [f"  - {{name: j{i + 1}, type: R, theta: 0, d: 0.05, a: 0.03, alpha: {90 if i % 2 else -90}, "
            f"limits: [-170, 170]}}" for i in range(n)]
    path.write_text("\n".join([f"name: chain{n}", "angle_unit: deg", "joints:", *rows,
                               "targets:", "  smr: [0.05, 0.0, 0.10]"]) + "\n")


def with_aux(src: Path, dst: Path, n_aux: int):
    d = pd.read_csv(src)
    poses = d["pose"].unique()
    noise = np.random.default_rng(0).normal(size=(len(poses), n_aux))
    aux = pd.DataFrame(noise, columns=[f"s{i}" for i in range(n_aux)]).assign(pose=poses)
    d.merge(aux, on="pose").to_csv(dst, index=False)


def main():
    tmp = ROOT / "out" / "bench"
    tmp.mkdir(parents=True, exist_ok=True)
    robot, const = ROOT / "robots" / "industrial6r.yaml", ROOT / "robots" / "constant.errors.yaml"
    rows = []

    def case(label: str, result: dict, note: str = ""):
        if result["rc"] != 0:
            raise SystemExit(f"{label}: exit {result['rc']}: {result['stderr']}")
        rows.append((label, result, note))
        print(f"{label:72s} {result['s']:8.1f} s {result['peak_mb']:8.0f} MB  {note}")

    peak = {}
    for n in (200_000, 1_000_000):
        data = tmp / f"industrial6r_{n}.csv"
        if not data.exists():
            case(f"simulate industrial6r, {n:,} poses", timed(*gecgen("simulate", str(robot), "--poses", str(n),
                                                                       "--seed", "2", "-o", str(data))))
        r = timed(*gecgen("identify", str(robot), str(data), "-o", str(tmp / f"large_{n}.json")))
        case(f"identify industrial6r, default model, {n:,} rows", r,
             next(line for line in r["stdout"].splitlines() if line.startswith("train:")))
        peak[n] = r["peak_mb"]
    per_row = (peak[1_000_000] - peak[200_000]) / 800_000 * 1e3

    small = tmp / "industrial6r_200.csv"
    timed(*gecgen("simulate", str(robot), "--poses", "200", "--seed", "1", "-o", str(small)))
    wide = tmp / "industrial6r_200_aux10000.csv"
    with_aux(small, wide, 10_000)
    diagnose = gecgen("diagnose", str(robot), str(wide), "--errors", str(const), "-o", str(tmp / "wide.errors.yaml"))
    timed(*diagnose)  # its rounds' models compiled: the second run is timed
    r = timed(*diagnose)
    case("diagnose industrial6r, constant model, 200 poses, 10,000 aux columns", r,
         " ".join(line for line in r["stdout"].splitlines() if line.startswith(("after:", "effects:"))))

    chain = tmp / "chain100.yaml"
    chain_file(chain, 100)
    cache = Path(tempfile.mkdtemp(prefix="gecgen-bench-cache-"))
    try:
        for label in ("empty code cache", "warm"):
            r = timed(*gecgen("redundancy", str(chain), "--errors", str(const)), env={"GECGEN_CACHE": str(cache)})
            found = " ".join(line for line in r["stdout"].splitlines() if line.startswith("n_identifiable"))
            case(f"redundancy, 100-joint chain, constant errors (606), {label}", r, found)
    finally:
        shutil.rmtree(cache, ignore_errors=True)

    lines = ["## Large inputs: rows, auxiliary signals, joints", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, load average "
             f"{os.getloadavg()[0]:.1f} when the benchmark ended. Regenerate: `python benchmarks/bench_large.py`. "
             "Each case is the `gecgen` command in a fresh process; peak = its maximum resident memory.", "",
             "| case | wall time (s) | peak memory (MB) | result |", "|---|---|---|---|"]
    lines += [f"| {label} | {r['s']:.1f} | {r['peak_mb']:.0f} | {note} |" for label, r, note in rows]
    lines += ["", f"identify's memory grows by {per_row:.2f} kB per measured row (the slope from 200,000 to "
                  "1,000,000 rows): the rows themselves, their residuals and weights. Everything else streams: "
                  "the linear system through the QR in blocks of 2,000 poses, the data analysis and the "
                  "absurd-error check block by block, and the target placement (a starting point for the fit) "
                  "from about 20,000 rows spread through each stationing and target.",
              "", "The 100-joint chain's cold run is the one-time build of its code: the symbolic chain and "
                  "Jacobians, printed and compiled. It supports 10,000 load signals (100 wrench torques and 9,900 "
                  "gravity-regressor columns: their number grows with the square of the joints); the generated "
                  "code computes only those the error model uses (none here) and diagnose reads them all from "
                  "numpy. When every model's code carried all of them, they were more than half of its 40,000 "
                  "lines of C and the cold run took 103 s and 2,469 MB (gcc). A second run loads the compiled "
                  "library.",
              "", "Before the streaming and the batched screening (same machine, 2026-11-25): 200,000 rows took "
                  "44 s and 1,852 MB (the data analysis held every block of H, 8 kB a row with this model, and "
                  "the placement a dense Jacobian of every row); the 10,000-column diagnose 121.5 s (one "
                  "candidate at a time, 5 million small solves). The second audit measured 1,000,000 "
                  "rows at 5 minutes and 2.55 GB, and 11 minutes for a 100-joint URDF's redundancy."]
    write_section("large", "\n".join(lines))


if __name__ == "__main__":
    main()
