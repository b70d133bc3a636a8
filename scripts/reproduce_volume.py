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
import re
import time
import warnings
from pathlib import Path

import numpy as np

from gecgen.api import Calibrator
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.validation import read_yaml
from gecgen.model.volume import load_volume
from gecgen.fit.identify import to_world
from gecgen.runtime.processes import mapped
from gecgen.verify.volume import accuracy, random_poses
from gecgen.simulate import (Design, joined, load_truth, one_at_a_time, paper_data, paper_pps, paper_split, simulate,
                             true_tool_points)

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


#: the roll and pitch sweeps added to the paper's set b (one at a time from home, both payloads), rad
ROLL_PITCH_STEP = np.radians(1.0)
#: held-out configurations drawn at random over the volume, each with one payload drawn from its list
IN_VOLUME = 120


def training(robot, truth, seed: int, roll_pitch: bool):
    """(training, validation half) of the paper's design on the truth robot; with roll_pitch, set b
    also sweeps roll and pitch (the paper's never moves them, but compensation does)."""
    rng = np.random.default_rng(seed)
    if not roll_pitch:
        return paper_data(robot, truth, rng)
    design = joined(paper_pps(robot), one_at_a_time(robot, {5: ROLL_PITCH_STEP, 6: ROLL_PITCH_STEP}, (0.0, 70.0)))
    data = simulate(robot, truth, design, rng)
    train, val = paper_split(design, rng)
    return data.subset(train), data.subset(val)


def in_volume(robot, truth, volume, seed: int):
    """IN_VOLUME held-out poses drawn at random over the volume (configuration and payload), measured
    at the paper's three targets on the truth robot."""
    rng = np.random.default_rng(10_000 + seed)
    q, payload = random_poses(robot, volume, IN_VOLUME, rng)
    return simulate(robot, truth, Design(q, payload, volume.payload_at, ("t1", "t2", "t3"), np.array(["v"] * len(q))),
                    rng)


def compensated_on_truth(robot, truth, cm, c: np.ndarray, samples, volume) -> tuple[np.ndarray, np.ndarray]:
    """Where the truth robot puts each sample's stated point (N, 3), m, in its own world, when commanded to
    the joints the calibration (compiled model cm, coefficients c) compensates the sample's nominal
    joints to, and compensate's status per sample (N,). The controller reads the sensor: compensation
    is done again with what it reads where the robot went."""
    w = samples.w
    for _ in range(2):
        q_c, status = cm.compensate(samples.q, w, None, c)
        true, w = true_tool_points(robot, truth, q_c, samples.payload_kg, volume.payload_at, samples.point)
    return true, status


def one_truth(robot, spec, seed: int, cases: dict, volume, noise: tuple[float, float]) -> dict:
    """Every case (label -> (truth spec change, error model, noise stated, roll and pitch swept in the
    training design, residual from: None the training data, "paper" the paper's validation half,
    "volume" poses drawn at random over the volume)) on truth `seed`: the statement and the true worst
    compensated error over the same samples."""
    out, fits = {}, {}
    for label, (change, model, stated, roll_pitch, held_out) in cases.items():
        truth = load_truth({**spec, **change, "seed": 1000 + seed}, robot)
        key = (str(change), model.source, roll_pitch)
        if key not in fits:
            train, val = training(robot, truth, seed, roll_pitch)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fits[key] = Calibrator(model).fit(robot, train), val
        cal, val = fits[key]
        calib = cal.calibration_
        world = cal.data_, to_world(calib.frames, cal.data_)
        held = in_volume(robot, truth, volume, seed) if held_out == "volume" else val
        samples, st, cm = accuracy(calib, volume, *world, (held, to_world(calib.frames, held)) if held_out else None,
                                   noise[0] if stated else None,
                                   noise[1] if stated else 0.0, TOLERANCE_MM, CONFIDENCE, DRAWS,
                                   np.random.default_rng(seed))
        # where compensation fails, the statement says so
        true, _ = compensated_on_truth(robot, truth, cm, calib.c, samples, volume)
        err = 1e3 * np.linalg.norm(true - samples.world, axis=1)
        out[label] = {"bound": st.bound_mm, "lower": st.lower_mm, "parametric": st.parametric_mm,
                      "sigma_u": st.unmodelled_mm, "verdict": st.verdict, "true_worst": float(err.max()),
                      "per_point_covers": float(np.mean(err <= st.per_point_mm)), "kept": len(calib.kept),
                      "measured": None if st.measured is None else st.measured.to_dict(),
                      "true_share": None if st.measured is None or st.measured.error_mm is None else
                      float(np.mean(err <= st.measured.error_mm)), "reasons": list(st.reasons)}
    return out


def timed_truth(*args) -> dict:
    """one_truth and the time it took (s), for the doc's running time however many ran side by side."""
    start = time.perf_counter()
    result = one_truth(*args)
    return {"result": result, "elapsed_s": time.perf_counter() - start}


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


#: what keeps a statement from being signed: a name, and how its reason starts or what it holds
WHY = {
    "the bound above 0.5 mm": lambda r: r.startswith("the bound, "),
    "training residuals alone": lambda r: "rests on the training residuals alone" in r,
    "compensated commands leave the trained ranges": lambda r: "compensated command leaves the ranges" in r,
    "too few held-out poses in the volume": lambda r: "a statement that rests on no model" in r,
    "measured error above 0.5 mm": lambda r: "measured poses do not support it" in r,
    "samples outside the trained ranges": lambda r: r.startswith("samples outside the ranges"),
    "loop gain": lambda r: "loop gain" in r,
    "compensation does not converge": lambda r: "does not converge" in r,
    "too few poses for the covariance": lambda r: "the covariance taken pose by pose needs" in r,
}


#: the reasons that leave no verdict but "cannot tell", and those that keep a bound from being signed (`state`)
BLOCKS = ("loop gain", "compensation does not converge", "too few poses for the covariance")
DOUBTS = ("training residuals alone", "compensated commands leave the trained ranges",
          "samples outside the trained ranges", "too few held-out poses in the volume")
#: tolerances (mm) the verdicts are read again at, from the same statements: where some truths pass them
TOLERANCES = (0.2, 0.25, 0.3, 0.4, 0.5)


def verdict_at(case: dict, tolerance_mm: float) -> str:
    """The verdict `gecgen accuracy` gives a statement of this run against another tolerance: its rule
    (`verify.volume.state`) on the bound, the low quantile, the measured error and the reasons that
    do not depend on the tolerance."""
    said = [r for r in case["reasons"]]
    if any(WHY[n](r) for n in BLOCKS for r in said):
        return "cannot tell"
    if case["lower"] > tolerance_mm:
        return "does not meet"
    m = case["measured"]
    if (any(WHY[n](r) for n in DOUBTS for r in said) or case["bound"] > tolerance_mm
            or (m is not None and (m["error_mm"] is None or m["error_mm"] > tolerance_mm))):
        return "cannot tell"
    return "meets"


def tolerance_table(results: list[dict], labels) -> list[str]:
    """Per case and tolerance: *meets* signed, and wrongly (the truth's worst above the tolerance)."""
    rows = []
    for label in labels:
        cells = []
        for t in TOLERANCES:
            meets = [x[label] for x in results if verdict_at(x[label], t) == "meets"]
            above = sum(x[label]["true_worst"] > t for x in results)
            cells.append(f"{len(meets)} ({sum(c['true_worst'] > t for c in meets)} wrong; {above} above)")
        rows.append(f"| {label} | " + " | ".join(cells) + " |")
    return ["| case | " + " | ".join(f"{t} mm" for t in TOLERANCES) + " |", "|---|" + "---|" * len(TOLERANCES),
            *rows]


def signed(results: list[dict], labels) -> tuple[int, int, int]:
    """(statements, signed *meets*, wrong *meets*) over the cases `labels`."""
    cases = [x[label] for x in results for label in labels]
    meets = [c for c in cases if c["verdict"] == "meets"]
    return len(cases), len(meets), sum(c["true_worst"] > TOLERANCE_MM for c in meets)


def why_table(results: list[dict], labels) -> list[str]:
    """Per case: how many truths were not signed *meets*, and how many of them give each reason."""
    counts = {label: {name: sum(x[label]["verdict"] != "meets" and any(test(r) for r in x[label]["reasons"])
                                for x in results) for name, test in WHY.items()} for label in labels}
    names = [n for n in WHY if any(counts[label][n] for label in labels)]
    return ["| case | not signed | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names),
            *[f"| {label} | {sum(x[label]['verdict'] != 'meets' for x in results)} | "
              + " | ".join(str(counts[label][n]) for n in names) + " |" for label in labels]]


def measured_table(results: list[dict], labels) -> list[str]:
    """Per case with held-out poses: the measured statement, against the truth's share of the volume's
    samples within its error."""
    rows = []
    for label in labels:
        m = [x[label]["measured"] for x in results if x[label]["measured"] is not None]
        if not m:
            continue
        stated = [(mm, x[label]["true_share"]) for x in results if (mm := x[label]["measured"])["rank"] is not None]
        n = np.array([mm["n"] for mm in m])
        row = f"| {label} | {np.median(n):.0f} ({n.min()} - {n.max()}) | {m[0]['needed']} | {len(stated)} | "
        if stated:
            share = np.array([t for _, t in stated])
            rank = np.array([mm["rank"] for mm, _ in stated])
            row += (f"{np.median(rank):.0f} | {np.median([mm['achieved_confidence'] for mm, _ in stated]):.1%} | "
                    f"{np.median([mm['error_mm'] for mm, _ in stated]):.3f} | "
                    f"{np.median(share):.1%} ({share.min():.1%}) | "
                    f"{int((share >= m[0]['share']).sum())} of {len(stated)} |")
        else:
            row += "- | - | - | - | - |"
        rows.append(row)
    return ["| case | held-out poses inside the volume, median (range) | needed | truths with a measured statement | "
            "rank used, median | its confidence, median | error within which 95 % is stated, median (mm) | true share "
            "of the samples within it, median (lowest) | truths where it holds 95 % |",
            "|---|---|---|---|---|---|---|---|---|", *rows]


def _figures(results: list[dict], label: str) -> dict:
    worst = np.array([x[label]["true_worst"] for x in results])
    bound = np.array([x[label]["bound"] for x in results])
    return {"covered": float(np.mean(worst <= bound)), "ratio": float(np.median(bound / worst)),
            "lo": float(np.min(bound / worst)), "hi": float(np.max(bound / worst)),
            "worst": float(np.median(worst)),
            "meets_signed": sum(x[label]["verdict"] == "meets" for x in results)}


def signed_summary(results: list[dict], labels) -> list[str]:
    """How often *meets* is signed, and how often wrongly (the truth's worst above the tolerance)."""
    total, meets, wrong = signed(results, labels)
    per_case = "; ".join(f"{label}: {m} ({w} wrong)" for label in labels
                         for _, m, w in [signed(results, [label])] if m)
    return [f"**How often it is signed:** *meets* is signed in {meets} of the {total} statements "
            f"({len(labels)} cases x {len(results)} truths), wrongly in {wrong}"
            + (f" ({wrong / meets:.1%} of those signed)" if meets else "") + (f": {per_case}." if per_case else ".")]


def _why(results: list[dict], label: str, name: str) -> int:
    """Truths of a case not signed *meets* for the reason `name` of WHY (among others)."""
    return sum(x[label]["verdict"] != "meets" and any(WHY[name](r) for r in x[label]["reasons"]) for x in results)


#: the reasons a statement's measured part and the compensated commands add: without them, the bound alone signs
NEW = ("compensated commands leave the trained ranges", "too few held-out poses in the volume",
       "measured error above 0.5 mm")


def bound_alone(results: list[dict], label: str) -> tuple[int, int]:
    """(truths, wrong) that the bound alone would sign: within the tolerance, and no reason but NEW's."""
    alone = [x[label] for x in results if x[label]["bound"] <= TOLERANCE_MM and not any(
        test(r) for name, test in WHY.items() if name not in NEW for r in x[label]["reasons"])]
    return len(alone), sum(c["true_worst"] > TOLERANCE_MM for c in alone)


def discussion(results: list[dict]) -> list[str]:
    """What the tables say, with their figures."""
    geo, diag = _figures(results, "geometric truth, constant model"), _figures(results, "full truth, diagnosed model")
    bare = _figures(results, "full truth, diagnosed model, noise not stated")
    paper = "full truth, diagnosed model, --val the validation half"
    val = _figures(results, paper)
    default = _figures(results, "full truth, default GEC model")
    swept = {"geometric": "geometric truth, constant model, roll and pitch swept, --val in the volume",
             "diagnosed": "full truth, diagnosed model, roll and pitch swept, --val in the volume"}
    sw = {k: _figures(results, label) | dict(zip(("n", "meets", "wrong"), signed(results, [label])))
          for k, label in swept.items()}
    total, meets, wrong = signed(results, [label for label in results[0]])
    at = [(verdict_at(x[label], t), x[label]["true_worst"] > t) for x in results for label in x for t in TOLERANCES]
    tight = (sum(v == "meets" for v, _ in at), sum(v == "meets" and above for v, above in at))
    wrong_at = [(t, sum(verdict_at(x[swept["diagnosed"]], t) == "meets" for x in results),
                 sum(verdict_at(x[swept["diagnosed"]], t) == "meets" and x[swept["diagnosed"]]["true_worst"] > t
                     for x in results)) for t in TOLERANCES]
    edge = {k: _why(results, label, "compensated commands leave the trained ranges") for k, label in swept.items()}
    couch = {k: sum(x[label]["verdict"] != "meets" and any(re.search(r"per input: q4 \d+ \(of", r)
                                                            for r in x[label]["reasons"]) for x in results)
             for k, label in swept.items()}
    held = {}
    for k, label in swept.items():
        share = [x[label]["true_share"] for x in results if x[label]["true_share"] is not None]
        held[k] = (sum(t >= 0.95 for t in share), len(share), min(share) if share else float("nan"))
    n = len(results)
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
        "longitudinal axis extended, 70 kg, the top of the box, while at the measured targets, over the whole "
        "design, the effect stays inside the noise: no residual at the training poses can show it. This is why "
        "`gecgen accuracy` never says *meets* from training residuals alone.",
        f"- **With the paper's validation half** (`--val`: 56 poses, 28 configurations at the vertices of the "
        f"treatment volume with both payloads) the bound holds the true worst in {val['covered']:.0%} of the truths, "
        f"{val['ratio']:.1f} times it in the median, and the statement is signed in {val['meets_signed']} of {n}. "
        f"Two things keep it unsigned: the paper's design never moves roll and pitch, which compensation moves at "
        f"every sample ({_why(results, paper, 'compensated commands leave the trained ranges')} of {n}: the error "
        f"of that motion is in no bound), and 56 poses inside the volume are fewer than the 59 that the largest "
        f"error needs to state 95 % of it at 95 % confidence "
        f"({_why(results, paper, 'too few held-out poses in the volume')} of {n}). Signed on the bound alone, as "
        f"`gecgen accuracy` did before it asked for the measured statement, it would say *meets* in "
        f"{bound_alone(results, paper)[0]} truths, wrongly in {bound_alone(results, paper)[1]}"
        + (": the vertices reach the corner where the effect is largest, but 56 poses pin its size loosely and the "
           "corner's worst configuration is not among them." if bound_alone(results, paper)[1] else "."),
        f"- **The default GEC model** (quadratic in each joint and linear in all six wrench components) is never "
        f"signed: its fx and fz terms read the couch's tilt through the force sensor, the loop gain of wrench -> "
        f"errors -> wrench comes near 1 ({_why(results, 'full truth, default GEC model', 'loop gain')} of {n}), and "
        f"its true worst in the volume is {default['worst']:.1f} mm in the median, against 0.6 mm at the paper's "
        "validation vertices, which share the training poses' configurations. With the loop gain the model's own "
        "figures cannot be trusted, so the statement says *cannot tell*, never *does not meet* beside that reason.",
        f"- **Roll and pitch swept, and {IN_VOLUME} poses held out at random over the volume**: the statement "
        f"is signed in {sw['geometric']['meets']} of {n} truths where the model describes the robot "
        f"({sw['geometric']['wrong']} wrong) and in {sw['diagnosed']['meets']} of {n} where it misses an effect "
        f"({sw['diagnosed']['wrong']} wrong); the bound holds the true worst in {sw['geometric']['covered']:.0%} and "
        f"{sw['diagnosed']['covered']:.0%}. The measured statement (95 % of the volume within the k-th largest "
        f"held-out error) holds for the truth's samples in {held['geometric'][0]} of {held['geometric'][1]} and "
        f"{held['diagnosed'][0]} of {held['diagnosed'][1]} truths (lowest true share {held['geometric'][2]:.1%} and "
        f"{held['diagnosed'][2]:.1%}). Unsigned for compensated commands leaving a trained range: "
        f"{edge['geometric']} and {edge['diagnosed']} of {n}; in {couch['geometric']} and {couch['diagnosed']} of "
        "them only the couch angle leaves it, at a few samples of the volume's edge, where compensation asks for "
        "more than +-90 deg: the declared range is the joint's limit, so the controller cannot correct those "
        "samples, and the reasons say to narrow the declared range.",
        "- **Where *meets* is wrong**: at 0.5 mm no truth of these cases passes the tolerance, so no *meets* can be "
        "wrong there. Read against tighter tolerances, where the diagnosed model's true worst passes it in some "
        "truths, *meets* is wrong in "
        + ", ".join(f"{w} of {m} signed at {t} mm" for t, m, w in wrong_at if w)
        + ": the measured statement covers 95 % of the volume (it held in every truth, so where *meets* is wrong "
        "the true worst lies in the 5 % it leaves out), and the bound, read from the same held-out poses, holds "
        f"the true worst in {sw['diagnosed']['covered']:.0%} of the truths: the worst over the whole volume is "
        "what neither pins where the model misses an effect."
        if any(w for _, _, w in wrong_at) else
        "- **Where *meets* is wrong**: in none of the truths, at 0.5 mm or at the tighter tolerances.",
        "",
        "## Against the target",
        "",
        "The targets: *meets* wrong in at most 5 % of the statements signed; the true worst within the bound in at "
        "least 95 % of the truths; a bound at most 1.5 times the true worst in the median, on the PPS with the "
        "paper's design. Measured above:",
        "",
        f"- *meets* is signed in {meets} of {total} statements, wrongly in {wrong}"
        + (f" ({wrong / meets:.1%})" if meets else "") + f"; read against {min(TOLERANCES)} to "
        f"{max(TOLERANCES)} mm, wrongly in {tight[1]} of the {tight[0]} signed"
        + (f" ({tight[1] / tight[0]:.1%})" if tight[0] else "") + ". The 5 % target holds at 0.5 mm, where no "
        "truth could make *meets* wrong, and over the tolerances pooled; it does not hold for the model that misses "
        "an effect at each tighter tolerance where it is signed and wrong (above). Stating a larger share of the "
        "volume (`--share 0.99` needs 299 poses inside it) is what would reach further into its corners.",
        f"- 95 % coverage is reached where the model describes the robot ({geo['covered']:.0%}), not where it misses "
        f"an effect the design cannot see ({diag['covered']:.0%} from the training residuals, {val['covered']:.0%} "
        f"with the validation half, {sw['diagnosed']['covered']:.0%} with roll and pitch swept and poses held out "
        "over the volume).",
        f"- 1.5 times is not reached: {geo['ratio']:.1f} times where the coverage holds. Drawing the unmodelled error "
        "independently at every sample is what keeps coverage at all; a smooth field drawn with a correlation "
        "length would be tighter, but the data give no correlation length to draw it with, and a wrong one would "
        "cost the coverage.",
        "",
        "The figure defended here: the bound holds the true worst (at least 95 %) when the model describes the robot "
        f"over the volume, at {geo['lo']:.1f} to {geo['hi']:.1f} times it; a statement is signed (*meets*) only "
        "when held-out poses measured inside the volume support it without a model, and the calibration's poses "
        "moved every joint compensation moves; and the corner a design never reached is named as the limit. What "
        "would close the gap: a design that measures the volume's corners (the largest payload at the longest "
        "reach and the extreme couch angles) and a target high on the couch, so that the tilt's lever arm is seen "
        "at the measured points.",
        "",
    ]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truths", type=int, default=50)
    parser.add_argument("--render", action="store_true", help="write the doc from the last run's results")
    parser.add_argument("--resume", action="store_true", help="keep the truths an interrupted run finished "
                                                              "(out/volume/truths/SEED.json)")
    parser.add_argument("--available", action="store_true", help="with --resume: the doc from the truths finished "
                                                                 "so far, computing none")
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
        "geometric truth, constant model": ({"sources": []}, const, True, False, None),
        "full truth, diagnosed model": ({}, diagnosed, True, False, None),
        "full truth, diagnosed model, noise not stated": ({}, diagnosed, False, False, None),
        "full truth, diagnosed model, --val the validation half": ({}, diagnosed, True, False, "paper"),
        "full truth, default GEC model": ({}, default, True, False, None),
        "geometric truth, constant model, roll and pitch swept, --val in the volume": (
            {"sources": []}, const, True, True, "volume"),
        "full truth, diagnosed model, roll and pitch swept, --val in the volume": ({}, diagnosed, True, True, "volume"),
    }
    saved = OUT / "results.json"
    if args.render:  # the doc again from the last run's results
        run = json.loads(saved.read_text())
    else:
        each = OUT / "truths"
        each.mkdir(exist_ok=True)
        done = {}
        for seed in range(args.truths) if args.resume else ():
            path = each / f"{seed}.json"
            if path.exists() and set((old := json.loads(path.read_text()))["result"]) == set(cases):
                done[seed] = old
        todo = [] if args.available else [seed for seed in range(args.truths) if seed not in done]
        # the truths side by side in forked processes (GECGEN_WORKERS of them), each seeded: the same results
        with mapped([(timed_truth, (robot, spec, seed, cases, volume, noise)) for seed in todo]) as results:
            for seed, result in zip(todo, results):
                done[seed] = result
                (each / f"{seed}.json").write_text(json.dumps(result))
                print(seed, {k: (round(v["true_worst"], 3), round(v["bound"], 3), v["verdict"])
                             for k, v in result["result"].items()}, flush=True)
        run = {"results": [done[seed]["result"] for seed in sorted(done)],
               "elapsed_s": sum(r["elapsed_s"] for r in done.values())}
        saved.write_text(json.dumps(run))
    results, elapsed = run["results"], run["elapsed_s"]
    lines = [
        "# Accuracy over a declared volume: is the statement honest?",
        "",
        "Regenerate with `python scripts/reproduce_volume.py` "
        f"({elapsed / 60:.0f} min for {len(results)} truths, the time of each truth summed, on the 2-core machine "
        "shared with other work; `GECGEN_WORKERS` of them run side by side). The volume is "
        "`robots/pps.volume.yaml`: any point of the seed paper's treatment volume (50 x 50 cm on the couch, 40 cm "
        "high) brought to the isocenter at any couch angle from -90 to 90 deg, with 0 and 70 kg; "
        f"{volume.samples} configurations, each with both payloads. For each truth (the PPS truth file with its random "
        "constant errors and joint offsets drawn from a new seed, and new noise), the paper's design is simulated, "
        "its training part calibrated, and `gecgen accuracy` states the worst compensated error for "
        f"{TOLERANCE_MM} mm at {CONFIDENCE:.0%} confidence, with the measurement noise stated "
        f"({1e3 * noise[0]:.3f} mm tracker noise per point, {1e3 * noise[1]:.3f} mm repeatability per pose, per "
        "coordinate: the truth file's). The truth robot is "
        "then commanded to the compensated joints of every sample and its true (systematic) error measured. The "
        "last two cases sweep roll and pitch as well in the training design (each alone from home, "
        f"{np.degrees(ROLL_PITCH_STEP):.0f} deg steps over its limits, both payloads: compensation moves them, the "
        f"paper's design never does), and hold out {IN_VOLUME} poses drawn at random over the volume "
        "(`gecgen.verify.volume.random_poses`: a configuration and one payload each), measured at the three targets.",
        "",
        *signed_summary(results, list(cases)),
        "",
        "| case | truths | true worst within the bound | bound / true worst, median (range) | true worst, "
        "median (mm) | bound, median (mm) | from the coefficients alone (mm) | unmodelled sigma (mm) | samples within "
        "their own bound | meets / does not / cannot tell | truly within 0.5 mm | wrong verdicts |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        *[row for label in cases for row in table(results, label)],
        "",
        "What keeps a statement from being signed (truths, a statement may give several reasons):",
        "",
        *why_table(results, list(cases)),
        "",
        "The statement measured at the held-out poses inside the volume, without a model (95 % of the volume at "
        "95 % confidence, by order statistics), against the truth:",
        "",
        *measured_table(results, list(cases)),
        "",
        f"At {TOLERANCE_MM} mm every truth but the default model's is truly within the tolerance, so no *meets* "
        "there could be wrong. The same statements read against tighter tolerances (the verdict's rule applied to "
        "the bound, the measured error and the reasons of this run, which do not depend on the tolerance), where "
        "the truth's worst passes the tolerance in some truths: *meets* signed (of them wrong; truths whose true "
        "worst is above the tolerance):",
        "",
        *tolerance_table(results, list(cases)),
        "",
        *discussion(results),
    ]
    (ROOT / "docs" / "volume.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
