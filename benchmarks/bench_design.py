"""Design benchmark: `gecgen design` choosing N of K candidates, time and peak memory.

    python benchmarks/bench_design.py             # prints a table, updates docs/benchmarks.md

Each case runs `gecgen design ... --json` in its own process (its peak resident memory is its
own), after one warm-up run that compiles the generated code and caches the structural analysis,
as a user's second run would find them.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_runtime import cpu_model, write_section  # noqa: E402

CASES = [
    # (label, robot, errors, poses, candidates, extra options, target seconds)
    ("industrial6r, constant model", "industrial6r.yaml", "constant.errors.yaml", 50, 10_000, [], 10),
    ("PPS, default model, 3 targets, 0/70 kg", "pps.yaml", "pps.errors.yaml", 200, 100_000,
     ["--targets", "t1,t2,t3", "--payload-kg", "0,70", "--gravity", "0,-9.81,0"], 120),
]


def run(robot: str, errors: str, poses: int, candidates: int, extra: list[str], out: Path) -> dict:
    cmd = ["/usr/bin/time", "-f", "%e %M", sys.executable, "-m", "gecgen.cli", "design", str(ROOT / "robots" / robot),
           "--errors", str(ROOT / "robots" / errors), "--poses", str(poses), "--candidates", str(candidates), *extra,
           "-o", str(out), "--json"]
    done = subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=ROOT)
    seconds, kb = done.stderr.strip().splitlines()[-1].split()
    return {"seconds": float(seconds), "peak_mb": int(kb) / 1024, **json.loads(done.stdout)}


def main():
    tmp = ROOT / "out" / "bench"
    tmp.mkdir(parents=True, exist_ok=True)
    rows = []
    for label, robot, errors, poses, candidates, extra, target in CASES:
        run(robot, errors, 10 if "pps" not in robot else 30, 500, extra, tmp / "design-warm.csv")  # warm the caches
        load = os.getloadavg()[0]  # other processes on the 2 cores slow every step
        r = run(robot, errors, poses, candidates, extra, tmp / "design.csv")
        rows.append((label, poses, candidates, target, load, r))
        print(f"{label:40s} {poses:4d} of {candidates:7d}: {r['seconds']:7.1f} s  peak {r['peak_mb']:6.0f} MB  "
              f"load {load:.1f}  value {r['log_det']:.2f} (random {r['random_log_det']:.2f})  swaps {r['swaps']} "
              f"passes {r['passes']} rounds {r['rounds']}", flush=True)
    cpu = cpu_model()
    lines = ["## Design: choosing the poses to measure", "",
             f"Machine: {cpu}, {len(os.sched_getaffinity(0))} cores, shared with other jobs (load average when each "
             "case started in the table). Regenerate: `python benchmarks/bench_design.py`. Each case is a fresh "
             "`gecgen design ... --json` process (imports, sampling the candidates, H_e of every candidate in blocks, "
             "the rank test, greedy start, exchanges, the random comparison and the validation figures, writing the "
             "CSV), after a warm-up run that compiled the generated code; time is wall clock, peak the process's "
             "maximum resident memory (`/usr/bin/time`).", "",
             "| case | poses | candidates | load average | time (s) | target (s) | peak memory (MB) | identifiable | "
             "log det design / random | predicted std RMS design / random (mm) | swaps, passes, rounds |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for label, poses, candidates, target, load, r in rows:
        std = r["predicted_std"]
        lines.append(f"| {label} | {poses} | {candidates:,} | {load:.1f} | {r['seconds']:.1f} | {target} | "
                     f"{r['peak_mb']:.0f} | {r['n_identifiable']} | {r['log_det']:.1f} / {r['random_log_det']:.1f} | "
                     f"{std['rms_mm']:.4f} / {std['random_rms_mm']:.4f} | "
                     f"{r['swaps']}, {r['passes']}, {r['rounds']} |")
    lines += ["", "Targets: 50 of 10,000 for industrial6r with the constant model under 10 s; 200 of 100,000 for "
                  "the PPS default model under 2 minutes. Candidates beyond 10,000 are screened (the pool of largest "
                  "gain, one refresh from all of them after the exchange: `rounds`), never all held at once."]
    write_section("design", "\n".join(lines))


if __name__ == "__main__":
    started = time.perf_counter()
    main()
    print(f"benchmark took {time.perf_counter() - started:.0f} s")
