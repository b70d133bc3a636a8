"""A two-armed tree with an elastic trunk: TALOS's upper body (tests/data/talos, truth talos.truth.yaml:
geometric errors, torso_2 bending under both arms, both shoulders under their arm) calibrated as one
tree, against torso + one arm fitted as two serial robots from the same measurements. Each seed: a new
pose set and noise draw; diagnose from constant errors on both. Writes docs/trees.md.

    python scripts/reproduce_tree.py [--seeds 5] [--train 300] [--val 150]
"""
import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import gecgen
from gecgen.model import load_robot
from gecgen.model.measurements import Measurements
from gecgen.model.validation import read_yaml
from gecgen.simulate import load_truth, random_design, simulate

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "talos"
CONSTANT = ROOT / "robots" / "constant.errors.yaml"
ARMS = {"left": [0, 1, *range(2, 9)], "right": [0, 1, *range(9, 16)]}


def part(m: Measurements, tree, robot, cols) -> Measurements:
    names = np.array([tree.target_names[t] for t in m.target])
    keep = np.isin(names, list(robot.targets))
    return Measurements(q=m.q[:, cols], w=m.w, aux=m.aux, aux_names=m.aux_names, pose_ids=m.pose_ids,
                        pose=m.pose[keep], target=np.array([robot.target_names.index(n) for n in names[keep]]),
                        xyz=m.xyz[keep], source=m.source)


def per_hand(robot, cal, val) -> dict[str, float]:
    """Held-out RMS (mm) of each branch's points under a fitted tree model."""
    err = np.linalg.norm(cal.predict(val.q)[val.pose, val.target] - val.xyz, axis=1)
    side = np.array([robot.branch_of(robot.target_names[t]) for t in val.target])
    return {b.name: float(1e3 * np.sqrt(np.mean(err[side == k] ** 2))) for k, b in enumerate(robot.branches)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--train", type=int, default=300)
    ap.add_argument("--val", type=int, default=150)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    tree = load_robot(DATA / "talos.yaml")
    truth = load_truth(read_yaml(DATA / "talos.truth.yaml", "truth"), tree)
    floor = 1e3 * np.sqrt(3 * (truth.tracker ** 2 + truth.repeatability ** 2))
    serials = {side: load_robot(DATA / f"talos_{side}.yaml") for side in ARMS}
    rows = []
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        train, val = (simulate(tree, truth, random_design(tree, n, rng), rng) for n in (args.train, args.val))
        t0 = time.perf_counter()
        d = gecgen.Diagnoser(errors=CONSTANT).fit(tree, train, val=val)
        seconds = time.perf_counter() - t0
        refit = gecgen.Calibrator(errors=d.error_model_).fit(tree, train)
        hands = per_hand(tree, refit, val)
        serial, squares, points = {}, 0.0, 0
        for side, cols in ARMS.items():
            robot = serials[side]
            s = gecgen.Diagnoser(errors=CONSTANT).fit(robot, part(train, tree, robot, cols),
                                                     val=part(val, tree, robot, cols)).diagnosis_
            serial[side] = s.after["val_rms_mm"]
            n = len(robot.targets) * val.n_poses
            squares, points = squares + n * serial[side] ** 2, points + n
        both = float(np.sqrt(squares / points))
        rows.append(dict(seed=seed, before=d.diagnosis_.before["val_rms_mm"], tree=d.diagnosis_.after["val_rms_mm"],
                         hands=hands, serial=serial, both=both, seconds=seconds,
                         effects=", ".join(f"{e.error} ({e.family})" for e in d.effects_)))
        print(rows[-1])
    ratio = np.array([r["tree"] / floor for r in rows])
    gain = np.array([r["both"] / r["tree"] for r in rows])
    lines = [
        "# Trees: one fit for a two-armed robot",
        "",
        "TALOS's upper body (`tests/data/talos/talos.yaml`, from example-robot-data): torso_1 and torso_2 carry",
        "two 7-joint arms; one marker on the left hand, two on the right; 16 joints, 17 frames, 102",
        "constant coefficients of which the tree's structure leaves 69 identifiable (checked against the",
        "numerical rank of H_e in tests/test_tree.py; torso + left arm alone has 39, torso + right arm 41:",
        "their 80 count the trunk's 11 twice). Its truth (`talos.truth.yaml`, masses from the URDF):",
        "geometric errors (0.5 mm, 0.3 mrad per frame, 0.3 mrad joint offsets), torso_2 bending under the",
        "weight of both arms (6e-5 rad/N m), each shoulder (arm_X_2) under its arm's (4e-5 rad/N m); noise",
        f"50 um tracker and 30 um repeatability per coordinate: the noise floor is {floor:.4f} mm RMS per point.",
        "",
        f"Each seed: {args.train} training and {args.val} held-out random poses of the whole tree; `diagnose`",
        "from constant errors, on the tree, and on torso + left arm and torso + right arm as two serial",
        "robots (`talos_left.yaml`, `talos_right.yaml`) fitted from the same measurements (each arm's points",
        "and joints). Made by",
        f"`python scripts/reproduce_tree.py --seeds {args.seeds} --train {args.train} --val {args.val}`.",
        "",
        "| seed | held-out before (mm) | tree after (mm) | tree / floor | tree: left hand, right hand (mm) "
        "| serial: left, right (mm) | serial both hands (mm) | serial / tree | tree diagnose (s) | effects the tree found |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['seed']} | {r['before']:.3f} | {r['tree']:.4f} | {r['tree'] / floor:.3f} | "
                     f"{r['hands']['left']:.4f}, {r['hands']['right']:.4f} | {r['serial']['left']:.3f}, "
                     f"{r['serial']['right']:.3f} | {r['both']:.3f} | {r['both'] / r['tree']:.2f} | {r['seconds']:.1f} "
                     f"| {r['effects']} |")
    lines += [
        "",
        f"Over {args.seeds} seeds: the tree's held-out RMS is {ratio.mean():.3f}x the noise floor on average "
        f"(worst {ratio.max():.3f}x);",
        f"the two serial fits leave {gain.mean():.2f}x the tree's error on average (least {gain.min():.2f}x). The",
        "serial fits see the other arm's weight as a rigid mass at its zero pose (the URDF's links off their",
        "chain): the torso's bend under the moving other arm is invisible to them, and the torso's errors are",
        "fitted twice and disagree. The tree's per-hand figures are from a refit of the diagnosed model",
        "(`Calibrator(errors=diagnoser.error_model_)`), scored on each branch's held-out points.",
        "",
    ]
    (ROOT / "docs" / "trees.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
