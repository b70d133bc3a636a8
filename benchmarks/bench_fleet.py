"""Fleet benchmark: 20 robots calibrated one after another, then as tasks on a local Dask cluster.

    python benchmarks/bench_fleet.py [--robots 20] [--workers 2]    # prints a table, updates docs/benchmarks.md

Each robot: industrial6r with its own truth draw (robots/industrial6r.truth.yaml, the seed per robot)
and 60 random poses, 20 % held out, calibrate as a user runs it (every candidate model). The first
robot's models are compiled before timing (a fleet is one robot type: its code is cached on disk), and
each run starts from a copy of that cache: the models diagnose finds for the other robots are compiled
in both runs alike. Sequential:
`calibrate_one` of every row in this process; fleet: `calibrate_fleet` with a local cluster (its
start-up counted). The results must be identical: every coefficient of every calibration file.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runtime import cpu_model, write_section  # noqa: E402

from gecgen.cli import main as gecgen  # noqa: E402
from gecgen.cli.fleet import calibrate_fleet, calibrate_one, read_manifest  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "robots" / "industrial6r.yaml"


def coefficients(folder: Path) -> list[float]:
    return [c["value"] for c in json.loads((folder / "calibration.json").read_text())["coefficients"]]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", type=int, default=20)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    load_average = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        rows = ["name,robot,train,holdout"]
        for k in range(args.robots):
            assert gecgen(["simulate", str(ROBOT), "--poses", "60", "--seed", str(k), "-o", str(tmp / f"r{k}.csv")]) == 0
            rows.append(f"r{k},{ROBOT},r{k}.csv,0.2")
        (tmp / "fleet.csv").write_text("\n".join(rows) + "\n")
        os.environ["GECGEN_CACHE"] = str(tmp / "cache")
        calibrate_one(read_manifest(tmp / "fleet.csv")[0], str(tmp / "warm"))  # the code compiled once
        shutil.copytree(tmp / "cache", tmp / "cache-dask")
        t0 = time.perf_counter()
        sequential = [calibrate_one(row, str(tmp / "seq")) for row in read_manifest(tmp / "fleet.csv")]
        t_seq = time.perf_counter() - t0
        os.environ["GECGEN_CACHE"] = str(tmp / "cache-dask")  # the workers inherit it
        t0 = time.perf_counter()
        fleet = calibrate_fleet(tmp / "fleet.csv", tmp / "dask", workers=args.workers)
        t_fleet = time.perf_counter() - t0
        ok = [r["status"] for r in sequential] == [r["status"] for r in fleet] == ["ok"] * args.robots
        same = ok and all(coefficients(tmp / "seq" / f"r{k}") == coefficients(tmp / "dask" / f"r{k}")
                          for k in range(args.robots))
    print(f"{args.robots} robots: one after another {t_seq:.1f} s, on Dask ({args.workers} workers) {t_fleet:.1f} s, "
          f"speed-up {t_seq / t_fleet:.2f}x, identical results: {same}")
    lines = ["## Fleet: many robots on Dask", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, load average {load_average:.1f} when the "
             "benchmark started. Regenerate: `python benchmarks/bench_fleet.py`. "
             f"{args.robots} industrial6r robots, each its own truth draw and 60 random poses (20 % held out), "
             "calibrate as a user runs it (every candidate model); the compiled code built before timing. One after "
             "another in one process, then `gecgen fleet` on a local cluster (its start-up counted).", "",
             "| robots | one after another (s) | on Dask (s) | workers | speed-up | identical coefficients |",
             "|---|---|---|---|---|---|",
             f"| {args.robots} | {t_seq:.1f} | {t_fleet:.1f} | {args.workers} | {t_seq / t_fleet:.2f}x | "
             f"{'yes' if same else 'NO'} |", "",
             "Target (issue 23): at least 1.7x with 2 workers, identical results."]
    write_section("fleet", "\n".join(lines))


if __name__ == "__main__":
    main()
