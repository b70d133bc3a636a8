"""Start-up benchmark: how long a `gecgen` command takes before it does any work.

    python benchmarks/bench_startup.py            # prints a table, updates docs/benchmarks.md

Each case is a fresh `gecgen` process (the installed entry point), best of 7 wall times, and the
least CPU time (user + system) of the 7, which a loaded machine inflates less. The parser imports
only the chosen command's module, so `--version` and `--help` load no numerical library, nor most
commands' `--help`; a command loads what it computes with. The last case is a whole
command: `identify` of 450 simulated PPS poses with the default error model, its code compiled
(warm); then `evaluate` of that calibration on the same data and `compensate` of 20 of its poses.
"""
from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runtime import ROOT, cpu_model, simulated_csv, write_section  # noqa: E402

CASES = (["--version"], ["--help"], ["identify", "--help"], ["calibrate", "--help"], ["design", "--help"])
REPEATS = 7


def times_s(args: list[str]) -> tuple[float, float]:
    """(best wall time, least CPU time: user + system) of REPEATS runs of `gecgen args`."""
    wall = cpu = float("inf")
    for _ in range(REPEATS):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run([shutil.which("gecgen"), *args], capture_output=True, check=True)
        wall = min(wall, time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = min(cpu, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def main():
    load_average = os.getloadavg()[0]
    rows = [(" ".join(["gecgen", *args]), *times_s(args)) for args in CASES]
    data = ROOT / "out" / "bench" / "startup-pps450.csv"
    data.parent.mkdir(parents=True, exist_ok=True)
    simulated_csv(data, 450)
    identify = ["identify", str(ROOT / "robots" / "pps.yaml"), str(data), "-o", str(data.with_suffix(".json"))]
    subprocess.run([shutil.which("gecgen"), *identify], capture_output=True, check=True)  # its code compiled
    rows.append(("gecgen identify pps.yaml 450 poses", *times_s(identify)))
    calibration = str(data.with_suffix(".json"))
    commands = data.with_name("startup-pps-commands.csv")
    rows_csv = data.read_text().splitlines()
    joints = [k for k, name in enumerate(rows_csv[0].split(",")) if name[:1] == "q" and name[1:].isdigit()]
    # each pose's joints once (a pose has a row per target), the first 20
    poses = list(dict.fromkeys(",".join(line.split(",")[k] for k in joints) for line in rows_csv[1:]))[:20]
    commands.write_text("\n".join([",".join(rows_csv[0].split(",")[k] for k in joints), *poses]) + "\n")
    rows.append(("gecgen evaluate of it, 450 poses", *times_s(["evaluate", calibration, str(data)])))
    rows.append(("gecgen compensate of it, 20 poses",
                 *times_s(["compensate", calibration, str(commands), "-o", str(commands.with_suffix(".out.csv"))])))
    for command, seconds, cpu in rows:
        print(f"{command:36s} {seconds:.3f} s  cpu {cpu:.3f} s")
    lines = ["## Start-up: a command before its work", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, load average {load_average:.1f} when the "
             f"benchmark started, {os.getloadavg()[0]:.1f} when it ended. Regenerate: "
             "`python benchmarks/bench_startup.py`. A fresh `gecgen` process each, "
             f"best of {REPEATS} wall times, and the least CPU time (user + system) of the {REPEATS}, which the "
             "machine's load inflates less. The parser imports only the module of the command named, so "
             "`--version` and `--help` load no numerical library, nor the `--help` of identify, calibrate, "
             "diagnose, evaluate, compensate, check, accuracy and filter (before the parser was built per "
             "command: 1.22 s for `--version` on this machine, every command's imports paid). The last three rows "
             "are whole commands, their work included: `identify` of 450 simulated PPS poses with the default error "
             "model, its code compiled; then `evaluate` of its calibration on the same data and `compensate` of 20 of "
             "its poses.",
             "", "| command | wall time (s) | CPU time (s) |", "|---|---|---|"]
    lines += [f"| `{command}` | {seconds:.3f} | {cpu:.3f} |" for command, seconds, cpu in rows]
    version, identify_s = rows[0][1], rows[-3][1]
    lines += ["", f"Targets: `gecgen --version` <= 0.1 s ({'met' if version <= 0.1 else 'not met'}); "
                  f"`gecgen identify` of 450 PPS poses, warm, <= 1 s ({'met' if identify_s <= 1 else 'not met'})."]
    write_section("startup", "\n".join(lines))


if __name__ == "__main__":
    main()
