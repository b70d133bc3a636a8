"""Calibration without a tracker, measured: a simulated Panda (robots/panda.truth.yaml: geometric errors,
joints 2, 4, 6 twisting under gravity) calibrated from a two-socket plate and from three planes, next
to a tracker calibration from as many configurations; and the MUKCa project's real Panda (two sockets,
tests/data/mukca_panda6) next to that project's own calibration. Writes docs/tracker-free.md.

    python scripts/reproduce_tracker_free.py [--seeds 5]
"""
import argparse
import importlib.util
import subprocess
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

import gecgen
from gecgen.model import load_robot
from gecgen.model.kinematics import target_positions
from gecgen.model.validation import read_yaml
from gecgen.simulate import load_truth, random_design, simulate
from gecgen.simulate.fixtures import Fixtures, simulate_fixtures

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "robots" / "panda_ball.yaml"
MUKCA = ROOT / "tests" / "data" / "mukca_panda6"
#: a stiffness per joint that gravity loads (joint 1's axis is vertical: never)
ELASTIC = {"default": ["1"], "frames": {j: {"er": ["1", f"gravity_torque(q{j})"]} for j in range(2, 8)}}


def fit(data, errors):
    return gecgen.Calibrator(errors=str(errors)).fit(ROBOT, data)


def relative_seed(robot, truth, fixtures, seed, errors, tracker_val):
    """One seed of a fixture calibration: held-out figures against the noise floor, and the held-out
    tracker points (registered: relative data fixes no base) next to a tracker calibration from as
    many configurations."""
    rng = np.random.default_rng(seed)
    train, _ = simulate_fixtures(robot, truth, fixtures, rng)
    val, floor = simulate_fixtures(robot, truth, fixtures, rng)
    cal = fit(train, errors)
    after = cal.score(val).after
    tracker = simulate(robot, truth, random_design(robot, train.n_poses, rng), rng)
    absolute = cal.score(tracker_val, register=True).after.rms_mm
    by_tracker = fit(tracker, errors).score(tracker_val, register=True).after.rms_mm
    unseen = [e["param"] for e in cal.report_["eliminated"] if e["reason"] == "relative"]
    return after, floor, absolute, by_tracker, unseen, train


def sockets(args, robot, truth, errors, tracker_val, lines):
    lines += ["## A two-socket plate, three placements", "",
              "Each seed: a plate with two sockets 50 mm apart placed at three random spots in reach (lying flat), "
              "25 configurations per socket from random starts (inverse kinematics of the truth robot), seating "
              "noise 10 um per coordinate, encoder noise 10 urad per joint; 150 configurations. Validated on three "
              "other placements of the plate (never used for training): the consistency (RMS distance of the "
              "ball's computed positions from their socket's mean) against what the seating and encoder noise "
              "alone give (the truth's own figure at the recorded joints), and the socket distance error (largest "
              "of the three). Then 100 held-out tracker points (tracker 50 um, repeatability 30 um): their RMS "
              "error after the socket calibration and after a tracker calibration from 150 random "
              "configurations, both scored with the tracker frame fitted to the points (sockets fix no base). "
              "Error model: constant errors plus a gravity stiffness on joints 2-7 (`gravity_torque(qj)`).", "",
              "| seed | consistency (mm) | noise alone (mm) | ratio | distance error (mm) | held-out tracker points, "
              "sockets (mm) | the same, tracker calibration (mm) |", "|---|---|---|---|---|---|---|"]
    ratios, blunder_data = [], None
    for seed in range(args.seeds):
        after, floor, absolute, by_tracker, unseen, train = relative_seed(
            robot, truth, Fixtures("ball", plates=3), seed, errors, tracker_val)
        ratios.append(after.consistency_mm / floor["consistency_mm"])
        lines.append(f"| {seed} | {after.consistency_mm:.4f} | {floor['consistency_mm']:.4f} | {ratios[-1]:.3f} | "
                     f"{after.distance_error_mm:.4f} | {absolute:.4f} | {by_tracker:.4f} |")
        blunder_data = blunder_data or (train, seed)
    lines += ["", f"Largest ratio {max(ratios):.3f} (the target: 1.3). What the data cannot see, named by the "
              f"redundancy analysis with reason `relative` in every seed: {', '.join(unseen)} (the six rigid motions "
              f"of the whole set; the distance fixes the scale).", ""]
    return blunder_data


def planes(args, robot, truth, errors, tracker_val, lines):
    lines += ["## Three planes", "",
              "Each seed: a table and two faces of a square standing on it, touched 30 or 100 times each within "
              "+-0.1 m of their common corner (touch noise 10 um along the normal, encoder noise 10 urad); "
              "validated on three new planes at another corner. Flatness: the RMS distance of the held-out touches "
              "from their own fitted plane. The tracker calibration has as many configurations.", "",
              "| touches per plane | seed | flatness (mm) | noise alone (mm) | ratio | held-out tracker points, "
              "planes (mm) | the same, tracker calibration (mm) |", "|---|---|---|---|---|---|---|"]
    ratios, seen = {}, {}
    cases = {30: Fixtures("ball", planes=3, touches=30), 100: Fixtures("ball", planes=3, touches=100),
             "30 + block": Fixtures("ball", planes=3, touches=30, relations=True, block_m=0.1)}
    for case, fixtures in cases.items():
        for seed in range(args.seeds):
            after, floor, absolute, by_tracker, unseen, _ = relative_seed(robot, truth, fixtures, 100 + seed, errors,
                                                                          tracker_val)
            ratios.setdefault(case, []).append(after.flatness_mm / floor["flatness_mm"])
            seen[case] = unseen
            lines.append(f"| {case} | {seed} | {after.flatness_mm:.4f} | {floor['flatness_mm']:.4f} | "
                         f"{ratios[case][-1]:.3f} | {absolute:.4f} | {by_tracker:.4f} |")
    lines += ["", f"Largest ratio {max(ratios[30]):.3f} with 30 touches per plane, {max(ratios[100]):.3f} with 100, "
              f"{max(ratios['30 + block']):.3f} with 30 and the relations (`30 + block`: the three planes declared "
              f"perpendicular, and a 100 mm block on the table whose far face, a fourth plane of 30 touches, is "
              f"declared parallel to the first face at 100 mm; unseen then: {', '.join(seen['30 + block'])}, "
              f"the offset fixing the scale). "
              f"A touch gives one equation (a socket's seat three), so 90 touches hold about 80 equations for the "
              f"model's 20-odd coefficients: the coefficients' own noise then adds to the held-out planes' "
              f"(sqrt(1 + 20/80) = 1.12 within the touched region, more beyond it). Unseen without relations "
              f"(reason `relative`): {', '.join(seen[30])}: the rigid motions and the scale - which is why the "
              f"held-out tracker points stay about 1 mm off after a planes-only calibration: the arm's size is "
              f"what planes without a known offset between them cannot measure; with the block's offset they "
              f"come out as after a tracker calibration.", ""]


def designed(args, robot, truth, errors, lines):
    """Configurations chosen by the fixture design from a larger recorded pool, against as many chosen
    at random from the same pool, scored on the same held-out fixtures."""
    from gecgen.symbolic.terms import load_error_model
    from gecgen.runtime.compiled import CompiledModel
    from gecgen.plan.fixture_design import design_fixtures, recorded_candidates

    cm = CompiledModel(robot, load_error_model(errors, robot))
    lines += ["## Designed configurations", "",
              "`gecgen design --fixtures` chooses which configurations to record (docs/reference.md, \"Designing "
              "for sockets and planes\"). Here it chooses from configurations already recorded - 150 per plane "
              "(three planes, as above) or 100 per socket (three plate placements) - as many as the tables above "
              "train on: 90 touches, or 150 seats; the comparison is the same number chosen at random from the "
              "same pool, spread evenly (the design's own start). Both are scored on the same held-out fixtures "
              "(30 touches a plane; 25 seats a socket). `predicted` is the design's own forecast of what the "
              "coefficients' uncertainty adds to a held-out residual (mm, at 10 um of seating noise).", "",
              "| fixtures | seed | designed: ratio to the noise floor | random: ratio | designed per fixture | "
              "predicted, designed / random (mm) |", "|---|---|---|---|---|---|"]
    worst = {}
    for kind, pool, held, n in (("planes", Fixtures("ball", planes=3, touches=150), Fixtures("ball", planes=3), 90),
                                ("sockets", Fixtures("ball", plates=3, per_socket=100), Fixtures("ball", plates=3),
                                 150)):
        measure = "flatness_mm" if kind == "planes" else "consistency_mm"
        for seed in range(args.seeds):
            rng = np.random.default_rng(100 + seed)
            recorded, _ = simulate_fixtures(robot, truth, pool, rng)
            val, floor = simulate_fixtures(robot, truth, held, rng)
            cands, poses = recorded_candidates(robot, recorded, 0)
            d = design_fixtures(cm, cands, n, 0, seed)
            ratio = {}
            for name, chosen in (("design", d.chosen), ("random", d.random)):
                train = recorded.subset(np.sort(np.concatenate([p[c] for p, c in zip(poses, chosen)])))
                ratio[name] = getattr(fit(train, errors).score(val).after, measure) / floor[measure]
                worst.setdefault((kind, name), []).append(ratio[name])
            lines.append(f"| {kind} | {seed} | {ratio['design']:.3f} | {ratio['random']:.3f} | "
                         f"{', '.join(str(len(c)) for c in d.chosen)} | {d.predicted_mm['design']:.4f} / "
                         f"{d.predicted_mm['random']:.4f} |")
    lines += ["", "Largest ratio, designed against random: " + "; ".join(
        f"{kind} {max(worst[(kind, 'design')]):.3f} against {max(worst[(kind, 'random')]):.3f} (mean "
        f"{np.mean(worst[(kind, 'design')]):.3f} against {np.mean(worst[(kind, 'random')]):.3f})"
        for kind in ("planes", "sockets")) + " (the target: 1.3).", ""]


def blunder(robot, train, seed, errors, lines):
    """A ball that did not seat: one configuration 2 mm off its socket."""
    val, _ = simulate_fixtures(robot, load_truth(read_yaml(ROOT / "robots" / "panda.truth.yaml", "truth"), robot),
                               Fixtures("ball", plates=3), np.random.default_rng(1000 + seed))
    clean = fit(train, errors)
    k = 7
    p = target_positions(robot, train.q[k:k + 1])[0, 0]
    q = train.q.copy()
    q[k, 0] += 0.002 / np.hypot(p[0], p[1])
    bad = fit(replace(train, q=q), errors)
    c0, c1 = (c.score(val).after.consistency_mm for c in (clean, bad))
    o = bad.report_["outliers"]
    effects = gecgen.Diagnoser(errors=str(errors)).fit(ROBOT, train, val=val).effects_
    lines += ["## Clean data stays clean", "",
              f"Seed {seed}'s clean socket data: identify names {len(clean.report_['outliers'])} outliers and "
              f"{len(clean.report_.get('suspect_poses', []))} suspect poses; `diagnose` from the declared model "
              f"(constant errors and the joint stiffnesses) adds {len(effects)} effect(s)"
              + (": " + ", ".join(f"{e.error} {list(e.terms)}" for e in effects) if effects else "") + ".", ""]
    lines += ["## A ball that did not seat", "",
              f"Seed {seed}'s training data with configuration {k} 2 mm off its socket (joint 1 turned by the "
              f"angle that moves the ball 2 mm): identify names {len(o)} outlier(s): row {o[0]['row']}, "
              f"{o[0]['residual_mm']:.3g} mm off (weight {o[0]['weight']:.3g}); the clean data names "
              f"{len(clean.report_['outliers'])}. Held-out consistency {c1:.4f} mm against {c0:.4f} mm clean "
              f"({100 * (c1 / c0 - 1):+.2f} %).", ""]


def mukca(lines):
    spec = importlib.util.spec_from_file_location("reference", MUKCA / "reference.py")
    reference = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(reference)
    calibrated = reference.load_joints(MUKCA / "calibrated.urdf")
    lines += ["## Real data: MUKCa's Panda panda_6", "",
              "Two sockets 50 mm apart, recorded at three plate placements (front 31 + 31 configurations, left "
              "30 + 30, right 44 + 33; tests/data/mukca_panda6, MIT licence). Imported with `gecgen import "
              "robots/panda_ball.yaml front/hole_0.csv front/hole_1.csv --sockets --socket-distance 0.05`, "
              "calibrated on front through the command line, scored on left and right with `gecgen evaluate`. "
              "MUKCa's own calibrated URDF trained on front too (its figures recomputed by "
              "tests/data/mukca_panda6/reference.py).", "",
              "| placement | model | consistency (mm) | distance error (mm) |", "|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)

        def gecgen_json(*a):
            import json
            out = subprocess.run([sys.executable, "-c", "from gecgen.cli import main; raise SystemExit(main())",
                                  *map(str, a), "--json"], capture_output=True, text=True, check=True)
            return json.loads(out.stdout)

        for place in ("front", "left", "right"):
            gecgen_json("import", ROBOT, MUKCA / place / "hole_0.csv", MUKCA / place / "hole_1.csv", "--sockets",
                        "--socket-distance", 0.05, "-o", tmp / f"{place}.csv")
        models = {"gecgen identify (default model: constant errors)": ["identify", ROBOT, tmp / "front.csv", "-o"],
                  "gecgen identify --keep-insignificant": ["identify", ROBOT, tmp / "front.csv",
                                                           "--keep-insignificant", "-o"]}
        scores = {}
        for name, cmd in models.items():
            gecgen_json(*cmd, tmp / "c.json")
            scores[name] = {place: gecgen_json("evaluate", tmp / "c.json", tmp / f"{place}.csv")
                            for place in ("front", "left", "right")}
        chosen = gecgen_json("calibrate", ROBOT, tmp / "front.csv", "-o", tmp / "cal")["model"]
        name = f"gecgen calibrate (chose `{chosen}`)"
        scores[name] = {place: gecgen_json("evaluate", tmp / "cal" / "calibration.json", tmp / f"{place}.csv")
                        for place in ("front", "left", "right")}
        for place in ("front", "left", "right"):
            q = [np.loadtxt(MUKCA / place / f"hole_{k}.csv", delimiter=",") for k in (0, 1)]
            theirs = reference.stats(*(reference.ball_positions(calibrated, qk) for qk in q))
            first = next(iter(scores.values()))[place]["before"]
            held = "" if place == "front" else " (held out)"
            lines.append(f"| {place}{held} | nominal | {first['consistency_mm']:.3f} | "
                         f"{first['distance_error_mm']:.3f} |")
            lines.append(f"| {place}{held} | MUKCa calibrated URDF | {theirs['rms']:.3f} | {theirs['dist_err']:.3f} |")
            for name, s in scores.items():
                a = s[place]["after"]
                lines.append(f"| {place}{held} | {name} | {a['consistency_mm']:.3f} | {a['distance_error_mm']:.3f} |")
    lines.append("")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    robot = load_robot(ROBOT)
    truth = load_truth(read_yaml(ROOT / "robots" / "panda.truth.yaml", "truth"), robot)
    tracker_val = simulate(robot, truth, random_design(robot, 100, np.random.default_rng(999)),
                           np.random.default_rng(998))
    with tempfile.TemporaryDirectory() as tmp:
        errors = Path(tmp) / "elastic.errors.yaml"
        errors.write_text(yaml.safe_dump(ELASTIC))
        lines = ["# Calibration without a tracker", "",
                 "Written by `python scripts/reproduce_tracker_free.py` (docs/reference.md, \"Sockets, distances and "
                 "planes\", says how the data is read and fitted). Simulated robot: robots/panda_ball.yaml (a ball "
                 "30 mm beyond the Panda's TCP) with robots/panda.truth.yaml.", ""]
        train, seed = sockets(args, robot, truth, errors, tracker_val, lines)
        planes(args, robot, truth, errors, tracker_val, lines)
        designed(args, robot, truth, errors, lines)
        blunder(robot, train, seed, errors, lines)
    mukca(lines)
    (ROOT / "docs" / "tracker-free.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
