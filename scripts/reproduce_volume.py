"""Is the accuracy statement over a declared volume honest? Measure it on simulated PPS truths; write
docs/volume.md.

    python scripts/reproduce_volume.py [--truths 50]

For each of --truths seeded truths (robots/pps.truth.yaml with its random constant errors and joint
offsets drawn again from a new seed, and new noise):
1. simulate the seed paper's design, keep its training part (set b and half of set a);
2. calibrate with each model (`gecgen identify`'s path: the Calibrator, insignificant coefficients held
   at zero);
3. state the worst compensated error over robots/pps.volume.yaml (the treatment volume at the
   isocenter, every couch angle, 0 and 70 kg) for 0.5 mm, with the noise the user states (tracker and
   repeatability of the truth file);
4. command the truth robot to the compensated joints of every sample of that volume and take the
   worst true (systematic) error: the figure the statement is about.
The statement is honest when the true worst lies within the bound in at least 95 % of the truths;
useful when the bound is not far above it (the issue asks for at most 1.5x in the median).
"""
from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

from gecgen.api import Calibrator
from gecgen.model import load_error_model, load_robot
from gecgen.model.validation import read_yaml
from gecgen.model.volume import load_volume
from gecgen.runtime.identify import to_world
from gecgen.runtime.volume import accuracy
from gecgen.simulate import load_truth, paper_data, true_tool_points

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "volume"
TOLERANCE_MM = 0.5
CONFIDENCE = 0.95
DRAWS = 2000


def diagnosed_model(robot, truth) -> Path:
    """The model `gecgen diagnose` builds from constant errors on one simulated training set (seed 1),
    applied to every truth: the effects are the truth file's, the constants its random draws."""
    from gecgen.api import Diagnoser

    path = OUT / "pps.diagnosed.errors.yaml"
    if not path.exists():
        train, _ = paper_data(robot, truth, np.random.default_rng(1))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            Diagnoser(ROOT / "robots" / "constant.errors.yaml").fit(robot, train).save(path)
    return path


def one_truth(robot, spec, seed: int, cases: dict, volume, noise: tuple[float, float]) -> dict:
    """Every case (label -> (truth spec change, error model, noise stated, residual from the paper's
    validation half instead of the training data)) on truth `seed`: the
    statement and the true worst compensated error over the same samples."""
    out, fits = {}, {}
    for label, (change, model, stated, held_out) in cases.items():
        truth = load_truth({**spec, **change, "seed": 1000 + seed}, robot)
        key = (str(change), model.source)
        if key not in fits:
            train, val = paper_data(robot, truth, np.random.default_rng(seed))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fits[key] = Calibrator(model).fit(robot, train), val
        cal, val = fits[key]
        calib = cal.calibration_
        world = cal.data_, to_world(calib.frames, cal.data_)
        samples, st, cm = accuracy(calib, volume, *world, (val, to_world(calib.frames, val)) if held_out else None,
                                   noise[0] if stated else None,
                                   noise[1] if stated else 0.0, TOLERANCE_MM, CONFIDENCE, DRAWS,
                                   np.random.default_rng(seed))
        w = samples.w  # the controller reads the sensor: compensate with what it reads where the robot goes
        for _ in range(2):
            q_c, _ = cm.compensate(samples.q, w, None, calib.c)  # where it fails, the statement says so
            true, w = true_tool_points(robot, truth, q_c, samples.payload_kg, volume.payload_at, samples.point)
        err = 1e3 * np.linalg.norm(true - samples.world, axis=1)
        out[label] = {"bound": st.bound_mm, "lower": st.lower_mm, "parametric": st.parametric_mm,
                      "sigma_u": st.unmodelled_mm, "verdict": st.verdict, "true_worst": float(err.max()),
                      "per_point_covers": float(np.mean(err <= st.per_point_mm)), "kept": len(calib.kept)}
    return out


def table(results: list[dict], label: str) -> list[str]:
    r = {k: np.array([x[label][k] for x in results]) for k in ("bound", "lower", "parametric", "sigma_u",
                                                                 "true_worst", "per_point_covers", "kept")}
    covered = r["true_worst"] <= r["bound"]
    ratio = r["bound"] / r["true_worst"]
    verdicts = {v: sum(x[label]["verdict"] == v for x in results) for v in ("meets", "does not meet", "cannot tell")}
    truly = int((r["true_worst"] <= TOLERANCE_MM).sum())
    wrong = sum(x[label]["verdict"] == "meets" and x[label]["true_worst"] > TOLERANCE_MM for x in results)
    wrong += sum(x[label]["verdict"] == "does not meet" and x[label]["true_worst"] <= TOLERANCE_MM for x in results)
    return [f"| {label} | {len(results)} | {covered.mean():.0%} ({covered.sum()}) | {np.median(ratio):.2f} "
            f"({ratio.min():.2f} - {ratio.max():.2f}) | {np.median(r['true_worst']):.3f} | {np.median(r['bound']):.3f} "
            f"| {np.median(r['parametric']):.3f} | {np.median(r['sigma_u']):.3f} "
            f"| {np.median(r['per_point_covers']):.1%} "
            f"| {verdicts['meets']} / {verdicts['does not meet']} / {verdicts['cannot tell']} | {truly} | {wrong} |"]


def _figures(results: list[dict], label: str) -> dict:
    worst = np.array([x[label]["true_worst"] for x in results])
    bound = np.array([x[label]["bound"] for x in results])
    return {"covered": float(np.mean(worst <= bound)), "ratio": float(np.median(bound / worst)),
            "lo": float(np.min(bound / worst)), "hi": float(np.max(bound / worst)),
            "worst": float(np.median(worst)),
            "meets_wrong": sum(x[label]["verdict"] == "meets" and x[label]["true_worst"] > TOLERANCE_MM
                               for x in results)}


def discussion(results: list[dict]) -> list[str]:
    """What the table says, with its figures."""
    geo, diag = _figures(results, "geometric truth, constant model"), _figures(results, "full truth, diagnosed model")
    bare = _figures(results, "full truth, diagnosed model, noise not stated")
    val = _figures(results, "full truth, diagnosed model, --val the validation half")
    default = _figures(results, "full truth, default GEC model")
    return [
        "## What it shows",
        "",
        f"- **Where the model describes the robot** (only geometric errors, constant model) the bound holds the true "
        f"worst in {geo['covered']:.0%} of the truths, {geo['ratio']:.1f} times it in the median. The bound is loose "
        "because the unmodelled error is taken at its upper 95 % confidence limit (396 poses leave about 13 % of "
        "the noise's variance in doubt in every direction) and drawn independently at 2000 samples; the true worst "
        f"({geo['worst']:.3f} mm) is the coefficients' error alone.",
        f"- **Where the model misses an effect** (the diagnosed model, fitted on one simulated robot and applied to "
        f"all: it lacks part of what the patient's weight does, the couch's droop growing as the cube of the "
        f"longitudinal extension and the roll and pitch giving under the load) the bound from the training "
        f"residuals holds the true worst in only "
        f"{diag['covered']:.0%} ({bare['covered']:.0%} without the noise stated). The true worst "
        f"({diag['worst']:.3f} mm in the median) sits in one corner of the volume: couch angle near +-90 deg, "
        "longitudinal axis extended, 70 kg, the top of the box. There the effect reaches 0.3 to 0.7 mm, while at the "
        "measured targets, over the whole design, it stays inside the 0.11 mm noise: no residual at the training "
        "poses can show it. This is why `gecgen accuracy` never says *meets* from training residuals alone.",
        f"- **With held-out poses** (`--val`: the paper's validation half, 56 configurations at the vertices of the "
        f"treatment volume) the bound holds the true worst in {val['covered']:.0%} of the truths, "
        f"{val['ratio']:.1f} times it in the median; {val['meets_wrong']} of the 50 *meets* were wrong. The vertices "
        "reach the corner where the effect is largest, but 56 poses pin its size loosely and the corner's worst "
        "configuration is not among them.",
        f"- **The default GEC model** (quadratic in each joint and linear in all six wrench components) is never "
        f"signed: its fx and fz terms read the couch's tilt through the force sensor, the loop gain of wrench -> "
        f"errors -> wrench comes near 1, and its true worst in the volume is {default['worst']:.1f} mm in the "
        "median, against 0.6 mm at the paper's validation vertices, which share the training poses' configurations. "
        "The statement says *cannot tell* (the loop gain), or *does not meet* where its coefficients' own "
        "uncertainty already passes 0.5 mm.",
        "",
        "## Against the target",
        "",
        "The issue asks for the true worst within the bound in at least 95 % of the truths and a bound at most 1.5 "
        "times the true worst in the median, on the PPS with the paper's design. Measured above:",
        "",
        f"- 95 % coverage is reached where the model describes the robot ({geo['covered']:.0%}), not where it misses "
        f"an effect the design cannot see ({diag['covered']:.0%} from the training residuals, {val['covered']:.0%} "
        "with the validation half).",
        f"- 1.5 times is not reached: {geo['ratio']:.1f} times where the coverage holds. Drawing the unmodelled error "
        "independently at every sample is what keeps coverage at all; a smooth field drawn with a correlation "
        "length would be tighter, but the data give no correlation length to draw it with, and a wrong one would "
        "cost the coverage.",
        "",
        "The figure defended here: the bound holds the true worst (at least 95 %) when the model describes the robot "
        f"over the volume, at {geo['lo']:.1f} to {geo['hi']:.1f} times it; a statement is signed (*meets*) only "
        "with held-out poses measured "
        "inside the volume; and the corner a design never reached is named as the limit. What would close the gap: "
        "a design that measures the volume's corners (the largest payload at the longest reach and the extreme "
        "couch angles) and a target high on the couch, so that the tilt's lever arm is seen at the measured "
        "points.",
        "",
    ]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=50)
    parser.add_argument("--render", action="store_true", help="write the doc from the last run's results")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    robot = load_robot(ROOT / "robots" / "pps.yaml")
    spec = read_yaml(ROOT / "robots" / "pps.truth.yaml", "truth")
    noise = (float(spec["noise"]["tracker"]), float(spec["noise"]["repeatability"]))
    volume = load_volume(ROOT / "robots" / "pps.volume.yaml", robot)
    const = load_error_model(ROOT / "robots" / "constant.errors.yaml", robot)
    diagnosed = load_error_model(diagnosed_model(robot, load_truth(spec, robot)), robot)
    default = load_error_model(ROOT / "robots" / "pps.errors.yaml", robot)
    cases = {
        "geometric truth, constant model": ({"sources": []}, const, True, False),
        "full truth, diagnosed model": ({}, diagnosed, True, False),
        "full truth, diagnosed model, noise not stated": ({}, diagnosed, False, False),
        "full truth, diagnosed model, --val the validation half": ({}, diagnosed, True, True),
        "full truth, default GEC model": ({}, default, True, False),
    }
    saved = OUT / "results.json"
    if args.render:  # the doc again from the last run's results
        run = json.loads(saved.read_text())
    else:
        start = time.perf_counter()
        results = []
        for seed in range(args.truths):
            results.append(one_truth(robot, spec, seed, cases, volume, noise))
            print(seed, {k: (round(v["true_worst"], 3), round(v["bound"], 3), v["verdict"])
                         for k, v in results[-1].items()}, flush=True)
        run = {"results": results, "elapsed_s": time.perf_counter() - start}
        saved.write_text(json.dumps(run))
    results, elapsed = run["results"], run["elapsed_s"]
    lines = [
        "# Accuracy over a declared volume: is the statement honest?",
        "",
        "Regenerate with `python scripts/reproduce_volume.py` "
        f"({elapsed / 60:.0f} min on the 2-core machine for {len(results)} truths). The volume is "
        "`robots/pps.volume.yaml`: any point of the seed paper's treatment volume (50 x 50 cm on the couch, 40 cm "
        "high) brought to the isocenter at any couch angle from -90 to 90 deg, with 0 and 70 kg; "
        f"{volume.samples} configurations, each with both payloads. For each truth (the PPS truth file with its random "
        "constant errors and joint offsets drawn from a new seed, and new noise), the paper's design is simulated, "
        "its training part calibrated, and `gecgen accuracy` states the worst compensated error for "
        f"{TOLERANCE_MM} mm at {CONFIDENCE:.0%} confidence, with the measurement noise stated "
        f"({1e3 * noise[0]:.3f} mm tracker noise per point, {1e3 * noise[1]:.3f} mm repeatability per pose, per "
        "coordinate: the truth file's). The truth robot is "
        "then commanded to the compensated joints of every sample and its true (systematic) error measured.",
        "",
        "| case | truths | true worst within the bound | bound / true worst, median (range) | true worst, "
        "median (mm) | bound, median (mm) | from the coefficients alone (mm) | unmodelled sigma (mm) | samples within "
        "their own bound | meets / does not / cannot tell | truly within 0.5 mm | wrong verdicts |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        *[row for label in cases for row in table(results, label)],
        "",
        *discussion(results),
    ]
    (ROOT / "docs" / "volume.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
