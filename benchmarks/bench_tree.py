"""Tree benchmark: diagnose on a 19-joint two-armed tree, time and peak memory.

    python benchmarks/bench_tree.py               # prints a table, updates docs/benchmarks.md

TALOS's upper body (tests/data/talos): torso (2 joints), left arm (7) and its gripper joint (1), right
arm (7), head (2), one marker per branch tip; truth: geometric errors, torso_2 and both shoulders
compliant under the URDF's masses. 500 training poses, 200 held out; diagnose from constant errors.
Each run is a fresh process (its own peak memory), after one warm-up run that builds the code cache.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_runtime import cpu_model, write_section  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "talos"
ROBOT = """name: talos19
angle_unit: rad
urdf: {urdf}
base_link: base_link
branches:
  left: {{tip_link: gripper_left_motor_double_link, targets: {{lh: [0.0, 0.02, -0.10]}}}}
  right: {{tip_link: arm_right_7_link, targets: {{rh: [0.0, -0.02, -0.10]}}}}
  head: {{tip_link: head_2_link, targets: {{hd: [0.1, 0.0, 0.05]}}}}
"""
TRUTH = {"seed": 5, "gravity": [0, 0, -9.81], "masses": "urdf",
         "constant": {"translation_std": 5.0e-4, "rotation_std": 3.0e-4}, "joint_offsets": {"std": 3.0e-4},
         "sources": [{"type": "compliance", "joint": 2, "compliance": 6.0e-5},    # torso_2
                     {"type": "compliance", "joint": 4, "compliance": 4.0e-5},    # arm_left_2
                     {"type": "compliance", "joint": 12, "compliance": 4.0e-5}],  # arm_right_2
         "noise": {"repeatability": 3.0e-5, "tracker": 5.0e-5}}

CASE = r"""
import json, resource, sys, time, warnings
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.measurements import read_measurements
from gecgen.loop.diagnose import diagnose
t0 = time.perf_counter()
robot = load_robot(sys.argv[1])
train, val = (read_measurements(p, robot) for p in sys.argv[2:4])
model = load_error_model(None, robot)
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    d = diagnose(robot, model, train, val)
t1 = time.perf_counter()
print(json.dumps({"total_s": t1 - t0, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "n": robot.n, "effects": [e.error for e in d.effects], "before": d.before["val_rms_mm"],
                  "after": d.after["val_rms_mm"], "candidates": d.candidates_tested}))
"""


def main():
    import numpy as np

    from gecgen.model import load_robot
    from gecgen.model.measurements import write_measurements
    from gecgen.simulate import load_truth, random_design, simulate

    tmp = ROOT / "out" / "bench"
    tmp.mkdir(parents=True, exist_ok=True)
    robot_file = tmp / "talos19.yaml"
    robot_file.write_text(ROBOT.format(urdf=DATA / "talos_reduced.urdf"))
    robot = load_robot(robot_file)
    truth = load_truth(TRUTH, robot)
    rng = np.random.default_rng(0)
    files = []
    for name, n in (("train", 500), ("val", 200)):
        files.append(tmp / f"talos19_{name}.csv")
        write_measurements(files[-1], robot, simulate(robot, truth, random_design(robot, n, rng), rng))
    floor = 1e3 * np.sqrt(3 * (truth.tracker ** 2 + truth.repeatability ** 2))
    load_average = os.getloadavg()[0]
    runs = []
    for _ in range(3):  # the first builds the code cache
        out = subprocess.run([sys.executable, "-c", CASE, str(robot_file), *map(str, files)], capture_output=True,
                             text=True, check=True)
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print(runs[-1])
    cold, warm = runs[0], min(runs[1:], key=lambda r: r["total_s"])
    lines = ["## Trees: diagnose on a 19-joint two-armed robot", "",
             f"Machine: {cpu_model()}, {len(os.sched_getaffinity(0))} cores, load average {load_average:.1f} when the "
             "benchmark started. Regenerate: `python benchmarks/bench_tree.py`. TALOS's upper body "
             "(tests/data/talos): torso 2 joints, left arm 7 and its gripper joint 1, right arm 7, head 2: 19 joints "
             "in three branches, one marker per tip; truth: geometric errors, torso_2 and both shoulders compliant "
             "under the URDF's masses, 50 um tracker and 30 um repeatability noise (noise floor "
             f"{floor:.4f} mm). 500 training and 200 held-out poses; `diagnose` from constant errors (120 "
             "coefficients) in a fresh process, reading the CSVs included; peak = the process's maximum resident "
             "memory. The dictionary holds every frame's whole load (docs/frame-loads.md); target: warm, at most "
             "twice the time of the dictionary with the joints' loads alone on the same machine.", "",
             "| run | total (s) | peak memory (MB) | candidates screened | held-out before (mm) | after (mm) | "
             "after / floor | effects |",
             "|---|---|---|---|---|---|---|---|"]
    for label, r in (("first (builds and compiles the code)", cold), ("warm cache (best of 2)", warm)):
        lines.append(f"| {label} | {r['total_s']:.1f} | {r['peak_mb']:.0f} | {r['candidates']} | {r['before']:.3f} | "
                     f"{r['after']:.4f} | {r['after'] / floor:.3f} | {', '.join(r['effects'])} |")
    write_section("tree", "\n".join(lines))


if __name__ == "__main__":
    main()
