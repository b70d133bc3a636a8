"""Fleet benchmark: 20 robots calibrated one after another, then as tasks on a local Dask cluster.

    python benchmarks/bench_fleet.py [--robots 20] [--workers 2]    # prints a table, updates docs/benchmarks.md

Each robot: industrial6r with its own truth draw (robots/industrial6r.truth.yaml, the seed per robot)
and 60 random poses, 20 % held out, calibrate as a user runs it (every candidate model). The first
robot's models are compiled before timing (a fleet is one robot type: its code is cached on disk), and
each run starts from a copy of that cache: the models diagnose finds for the other robots are compiled
in every run alike. One after another: `calibrate_one` of every row in this process, first each
calibrate in one process (GECGEN_WORKERS=1: the robots' work as a single core does it, the baseline
the fleet's scaling is measured against), then as `gecgen calibrate` runs alone (its folds and
figures side by side on the cores, `runtime.processes`); fleet: `calibrate_fleet` with a local
cluster (its start-up counted), whose workers run each calibrate in one process. The results must be
identical: every coefficient of every calibration file.
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
        for copy in ("cache-side", "cache-dask"):
            shutil.copytree(tmp / "cache", tmp / copy)

        def one_after_another(out: str, gecgen_workers: str | None) -> tuple[list[dict], float]:
            """Every robot calibrated here, with GECGEN_WORKERS set to gecgen_workers (None: unset)."""
            os.environ.pop("GECGEN_WORKERS", None)
            if gecgen_workers:
                os.environ["GECGEN_WORKERS"] = gecgen_workers
            t0 = time.perf_counter()
            results = [calibrate_one(row, str(tmp / out)) for row in read_manifest(tmp / "fleet.csv")]
            os.environ.pop("GECGEN_WORKERS", None)
            return results, time.perf_counter() - t0

        sequential, t_seq = one_after_another("seq", "1")
        os.environ["GECGEN_CACHE"] = str(tmp / "cache-side")
        alone, t_alone = one_after_another("alone", None)
        os.environ["GECGEN_CACHE"] = str(tmp / "cache-dask")  # the workers inherit it
        t0 = time.perf_counter()
        fleet = calibrate_fleet(tmp / "fleet.csv", tmp / "dask", workers=args.workers)
        t_fleet = time.perf_counter() - t0
        runs = (sequential, alone, fleet)
        ok = all([r["status"] for r in run] == ["ok"] * args.robots for run in runs)
        same = ok and all(coefficients(tmp / "seq" / f"r{k}") == coefficients(tmp / out / f"r{k}")
                          for k in range(args.robots) for out in ("alone", "dask"))
    print(f"{args.robots} robots: one after another {t_seq:.1f} s in one process each, {t_alone:.1f} s as calibrate "
          f"runs alone; on Dask ({args.workers} workers) {t_fleet:.1f} s: speed-up {t_seq / t_fleet:.2f}x and "
          f"{t_alone / t_fleet:.2f}x, identical results: {same}")
    lines = ["## Fleet: many robots on Dask", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, load average {load_average:.1f} when the "
             "benchmark started. Regenerate: `python benchmarks/bench_fleet.py`. "
             f"{args.robots} industrial6r robots, each its own truth draw and 60 random poses (20 % held out), "
             "calibrate as a user runs it (every candidate model); the first robot's models compiled before timing, "
             "each run from a copy of that cache. One after "
             "another in this process: each calibrate in one process (GECGEN_WORKERS=1, what the fleet's workers "
             "run), and as `gecgen calibrate` runs alone (its folds and figures side by side on the cores); then "
             "`gecgen fleet` on a local cluster (its start-up counted).", "",
             "| robots | one after another, one process each (s) | one after another, as calibrate runs alone (s) | "
             "on Dask (s) | workers | speed-up over one process each | over calibrate alone | identical coefficients |",
             "|---|---|---|---|---|---|---|---|",
             f"| {args.robots} | {t_seq:.1f} | {t_alone:.1f} | {t_fleet:.1f} | {args.workers} | "
             f"{t_seq / t_fleet:.2f}x | "
             f"{t_alone / t_fleet:.2f}x | {'yes' if same else 'NO'} |", "",
             f"Target: at least 1.7x with 2 workers over one robot after another, identical results: "
             f"{'met' if t_seq / t_fleet >= 1.7 else 'not met'} against the robots one after another in one "
             "process each, the baseline the target was set on (calibrate then ran in one process). calibrate "
             "alone now runs its own folds and figures side by side, so a robot alone already keeps both cores "
             "busy for much of its time, and on this 2-core machine the fleet cannot be 1.7x faster than that: "
             "its gain there is the column over calibrate alone. A fleet's gain is a cluster's machines."]
    write_section("fleet", "\n".join(lines))


if __name__ == "__main__":
    main()
