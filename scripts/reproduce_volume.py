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
from gecgen.simulate import load_truth, paper_pps, paper_split, simulate, true_tool_points

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
        design = paper_pps(robot)
        rng = np.random.default_rng(1)
        data = simulate(robot, truth, design, rng)
        train, _ = paper_split(design, rng)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            Diagnoser(ROOT / "robots" / "constant.errors.yaml").fit(robot, data.subset(train)).save(path)
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
            design = paper_pps(robot)
            rng = np.random.default_rng(seed)
            data = simulate(robot, truth, design, rng)
            train, val = paper_split(design, rng)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fits[key] = Calibrator(model).fit(robot, data.subset(train)), data.subset(val)
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
            f"| {np.median(r['parametric']):.3f} | {np.median(r['sigma_u']):.3f} | {np.median(r['per_point_covers']):.1%} "
            f"| {verdicts['meets']} / {verdicts['does not meet']} / {verdicts['cannot tell']} | {truly} | {wrong} |"]


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
    ]
    (ROOT / "docs" / "volume.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
