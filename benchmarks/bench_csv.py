"""CSV benchmark: `read_measurements` on a 100,000-pose measurement file, the fast reader (pandas)
next to the csv module it falls back to (before the fast reader, every file was read that way).

    python benchmarks/bench_csv.py               # prints a table, updates docs/benchmarks.md

The file is what `gecgen simulate` writes for the PPS (robots/pps.truth.yaml with a thermal source
added, so it has an aux column; payloads 0 and 70 kg, so the wrench is not zero), three targets per
pose. Times are in-process, best of 3, with the modules (pandas among them) already imported, and
the first read of a fresh process, which imports pandas.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from contextlib import nullcontext
from pathlib import Path
from unittest import mock

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_compiler import best  # noqa: E402
from bench_runtime import cpu_model, write_section  # noqa: E402

from gecgen.model import load_robot  # noqa: E402
from gecgen.model.measurements import read_measurements, write_measurements  # noqa: E402
from gecgen.model.validation import read_yaml  # noqa: E402
from gecgen.simulate import load_truth, random_design, simulate  # noqa: E402

POSES = 100_000
TARGET_S = 1.0


def measurement_file(path: Path, robot, poses: int):
    spec = read_yaml(ROOT / "robots" / "pps.truth.yaml", "truth")
    spec["sources"].append({"type": "thermal", "error": "1.ez", "per_kelvin": 3.6e-5, "reference": 20, "start": 20,
                            "end": 26})
    rng = np.random.default_rng(1)
    design = random_design(robot, poses, rng, (0.0, 70.0), targets=("t1", "t2", "t3"))
    write_measurements(path, robot, simulate(robot, load_truth(spec, robot, "bench"), design, rng))


FIRST_READ = """
import sys, time
from gecgen.model import load_robot
from gecgen.model.measurements import read_measurements
robot = load_robot(sys.argv[1])
t = time.perf_counter()
read_measurements(sys.argv[2], robot)
print(time.perf_counter() - t)
"""


def first_read_seconds(robot: Path, path: Path) -> float:
    """The first `read_measurements` of a fresh process, which imports pandas: what a command pays."""
    done = subprocess.run([sys.executable, "-c", FIRST_READ, str(robot), str(path)], capture_output=True, text=True,
                          check=True, cwd=ROOT)
    return float(done.stdout)


def main():
    tmp = ROOT / "out" / "bench"
    tmp.mkdir(parents=True, exist_ok=True)
    robot_file = ROOT / "robots" / "pps.yaml"
    robot = load_robot(robot_file)
    path = tmp / f"pps_{POSES}_3targets.csv"
    measurement_file(path, robot, POSES)
    load = os.getloadavg()[0]
    first = first_read_seconds(robot_file, path)
    print(f"first read of a fresh process (imports pandas): {first:.2f} s  load {load:.1f}")
    data = read_measurements(path, robot)  # imports pandas here too
    header = path.open().readline().strip()
    rows = [f"| fast reader, first read of a fresh process | {data.n_poses:,} | {len(data.xyz):,} | {load:.1f} | "
            f"{first:.2f} | |"]
    for label, fast, target in (("fast reader (pandas)", True, f"{TARGET_S:g}"), ("csv module (the fallback; the only reader before)", False, "")):
        load = os.getloadavg()[0]  # other processes on the 2 cores slow every step
        with mock.patch("gecgen.model.table._plain_columns", return_value=None) if not fast else nullcontext():
            seconds = best(lambda: read_measurements(path, robot), repeats=3)
        rows.append(f"| {label} | {data.n_poses:,} | {len(data.xyz):,} | {load:.1f} | {seconds:.2f} | {target} |")
        print(f"{label:28s} {data.n_poses} poses, {len(data.xyz)} rows: {seconds:6.2f} s (best of 3)  load {load:.1f}",
              flush=True)
    mb = path.stat().st_size / 1e6
    lines = ["## CSV: reading a measurement file", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, shared with other jobs (load average "
             "when each case started in the table). Regenerate: `python benchmarks/bench_csv.py`. The file is what "
             f"`gecgen simulate` writes for the PPS: {data.n_poses:,} poses, 3 targets each ({len(data.xyz):,} rows, "
             f"{mb:.0f} MB), columns `{header}`. Time = `read_measurements` in process (reading, parsing, every check "
             "of the contract), best of 3, modules imported; the first read of a fresh process also imports pandas "
             f"(first row). The csv module reads the files the fast reader "
             "declines (quoted cells, a stray carriage return, ...; `gecgen/model/table.py`) and gives the text "
             "of the cells a message repeats.", "",
             "| reader | poses | rows | load average | time (s) | target (s) |", "|---|---|---|---|---|---|"]
    lines += rows
    lines += ["", f"Target: {POSES:,} poses under {TARGET_S:g} s with the fast reader."]
    write_section("csv", "\n".join(lines))


if __name__ == "__main__":
    started = time.perf_counter()
    main()
    print(f"benchmark took {time.perf_counter() - started:.0f} s")
