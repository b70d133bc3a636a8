"""Does `gecgen accuracy --cameras` overclaim? Its statement against the compensated error of simulated
truths; writes the section "Does the statement from images hold?" of docs/camera.md.

    python scripts/reproduce_camera_accuracy.py [--seeds 5]

For two arms (robots/industrial6r.truth.yaml with the constant error model, which misses its gravity
compliance; robots/fanuc.truth.yaml with its own error model, which has its J2/J3 coupling), both
set-ups (two fixed cameras seeing four markers; a camera on the tool seeing a board) and each seed (the
truth's constant errors and offsets drawn again, new noise, a new rig):
1. 60 training images over a region of joint space kept away from the arm's singular postures (the
   elbow bent, the wrist turned away from q5 = 0), a few degrees wider than the volume on every joint;
2. calibrate (the pixel fit, `gecgen identify --cameras`'s path) and state the accuracy over the volume
   from 60 held-out images drawn at random inside it (`verify.images.accuracy_from_images`, what
   `gecgen accuracy --cameras` runs);
3. command the truth to the compensated joints of every sample of the volume and take its error against
   the nominal targets (`reproduce_volume.compensated_on_truth`), in the calibration's world (the truth's
   world carried there through the first camera's, or the board's, true and fitted poses: what the
   calibration's own instrument would see).
The statement holds when the true worst over the samples compensated lies within its bound, and no
*meets* is signed where the true worst passes the tolerance.
"""
from __future__ import annotations

import argparse
import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from gecgen.fit.camera import calibration_of, fit_pixels
from gecgen.model import load_robot
from gecgen.model.cameras import Board, Camera
from gecgen.model.kinematics import tool_pose
from gecgen.model.validation import read_yaml
from gecgen.model.volume import load_volume
from gecgen.runtime.compiled import FAILED
from gecgen.simulate import load_truth
from gecgen.simulate.camera import eye_in_hand, eye_to_hand, in_view, simulate_pixels
from gecgen.symbolic.terms import load_error_model
from gecgen.verify.images import accuracy_from_images
from reproduce_camera import DIST, PLATE, write_section
from reproduce_volume import compensated_on_truth, verdict_at

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "camera_accuracy"
HEADING = "## Does the statement from images hold?"
NOISE_PX = 0.2
TOLERANCES = (0.5, 1.0, 1.5, 2.0, 2.5)
CONFIDENCE, DRAWS, SAMPLES = 0.95, 2000, 200
TRAIN, HELD = 60, 60
#: deg: the training region is the volume widened by this on every joint (compensation moves the joints a little)
WIDER = 3.0
#: per arm: the robot, truth and error model files, and the volume's centre and half-widths (deg): the elbow
#: bent well away from stretched (industrial6r's a3 = -90, where its forearm lines up with the upper arm) and
#: q5 away from 0
ARMS = {
    "industrial6r": ("industrial6r.yaml", "industrial6r.truth.yaml", "constant.errors.yaml",
                     [0, -70, -40, 0, 50, 0], [8, 6, 8, 30, 15, 40]),
    # the elbow through stretched: compensation fails at some samples, and the statement must say at how many
    "industrial6r, elbow through stretched": ("industrial6r.yaml", "industrial6r.truth.yaml", "constant.errors.yaml",
                                              [0, -80, -100, 0, 30, 0], [8, 6, 12, 30, 15, 40]),
    "fanuc": ("fanuc.yaml", "fanuc.truth.yaml", "fanuc.errors.yaml",
              [0, 10, -20, 0, -50, 0], [8, 6, 8, 30, 15, 40]),
}


def volume_file(robot, name: str, mount: str, centre, half) -> Path:
    """The volume (YAML) of centre +- half (deg) over the robot's joints, at every target of the robot."""
    ranges = ", ".join(f"{j.name}: [{c - h:g}, {c + h:g}]" for j, c, h in zip(robot.joints, centre, half))
    path = OUT / f"{name.split(',')[0]}.{mount}.volume.yaml"
    path.write_text(f"angle_unit: deg\ntargets: [{', '.join(robot.targets)}]\njoints: {{{ranges}}}\n"
                    f"samples: {SAMPLES}\n")
    return path


def rig_of(robot, truth, mount: str, centre, half, rng):
    """(robot with the set-up's targets, rig, training joints, held-out joints in the volume, map of the
    truth's world into the fit's given the fit's poses). Fixed cameras look at the tool at the centre."""
    q0, span = np.radians(centre), np.radians(np.asarray(half) + WIDER)
    if mount == "world":
        h = PLATE / 2
        robot = replace(robot, targets={"m1": (h, h, 0.1), "m2": (-h, h, 0.1), "m3": (-h, -h, 0.1),
                                        "m4": (h, -h, 0.1)})
        at = tool_pose(robot, q0[None])[0][:3, 3]
        cams = [Camera(f"cam{k + 1}", 1800.0, 1800.0, 640.0, 480.0, DIST, 1280, 960) for k in range(2)]
        rig, q = eye_to_hand(robot, truth, cams, at + np.array([[-0.1, -2.4, 0.7], [-0.1, 2.4, 0.7]]), at, q0, span,
                             TRAIN, rng)
    else:
        cam = Camera("cam", 1400.0, 1400.0, 640.0, 480.0, DIST, 1280, 960, "tool")
        rig, q = eye_in_hand(robot, truth, cam, Board(9, 6, 0.04), q0, span, TRAIN, rng)
    return robot, rig, q, in_view(robot, truth, rig, q0, np.radians(half), HELD, rng)


def into_fit(rig, fit):
    """The map of points (N, 3) from the truth's world into the fit's: through the first camera (fixed
    cameras) or the board, at its true pose and where the fit put it."""
    if rig.mount == "world":
        name = next(iter(rig.cameras))
        (Rt, tt), (Rf, tf) = rig.poses[name], fit.poses[name]
        return lambda p: (p @ Rt.T + tt - tf) @ Rf
    (Rb, tb), (Rbf, tbf) = rig.board_pose, fit.board
    return lambda p: (p - tb) @ Rb @ Rbf.T + tbf  # x_b = Rb^T (p - tb), then Rbf x_b + tbf


def one(arm: str, mount: str, seed: int) -> dict:
    """One truth of `arm` seen from `mount` ("world": two fixed cameras; "tool": a carried camera): the statement
    at the largest tolerance, and the truth's compensated error over its samples (mm) against the cameras (the
    board) and in the truth's own base frame."""
    robot_file, truth_file, model_file, centre, half = ARMS[arm]
    robot = load_robot(ROOT / "robots" / robot_file)
    spec = read_yaml(ROOT / "robots" / truth_file, "truth file")
    truth = load_truth({**spec, "seed": 1000 + seed}, robot)
    rng = np.random.default_rng(seed)
    robot, rig, q, held = rig_of(robot, truth, mount, centre, half, rng)
    model = load_error_model(ROOT / "robots" / model_file, robot)
    train = simulate_pixels(robot, truth, rig, q, NOISE_PX, rng)
    val = simulate_pixels(robot, truth, rig, held, NOISE_PX, rng)
    fit = fit_pixels(robot, model, train, rig.cameras, rig.board)
    cal = calibration_of(robot, model, fit, rig.cameras, rig.board)
    volume = load_volume(volume_file(robot, arm, mount, centre, half), cal.robot)
    samples, st, cm, info = accuracy_from_images(cal, "calibration", volume, train, val, rig.cameras, rig.board,
                                                 max(TOLERANCES), CONFIDENCE, DRAWS, np.random.default_rng(seed))
    true, status = compensated_on_truth(cal.robot, truth, cm, cal.c, samples, volume)
    err = 1e3 * np.linalg.norm(into_fit(rig, fit)(true) - samples.world, axis=1)
    base = 1e3 * np.linalg.norm(true - samples.world, axis=1)  # in the truth's own base frame, for comparison
    ok = ~np.isin(status, FAILED)
    return {"arm": arm, "mount": mount, "seed": seed, "samples": len(err), "failed": int((~ok).sum()),
            "said_failed": any(f"does not converge at {int((~ok).sum())} of" in r for r in st.reasons),
            "true_worst": float(err[ok].max()), "base_worst": float(base[ok].max()),
            "true_median": float(np.median(err[ok])),
            "per_point_covers": float(np.mean(err[ok] <= st.per_point_mm[ok])), "bound": st.bound_mm,
            "lower": st.lower_mm, "parametric": st.parametric_mm, "sigma_u": st.unmodelled_mm,
            "verdict": st.verdict, "reasons": list(st.reasons), "points": info.points, "std_mm": list(info.std_mm),
            "measured": None if st.measured is None else st.measured.to_dict(),
            "true_share": None if st.measured is None or st.measured.error_mm is None else
            float(np.mean(err[ok] <= st.measured.error_mm))}


def write(results: list[dict]):
    rows = []
    for arm in ARMS:
        for mount, label in (("world", "two fixed cameras"), ("tool", "a camera on the tool")):
            r = [x for x in results if x["arm"] == arm and x["mount"] == mount]
            if not r:
                continue
            worst, bound = np.array([x["true_worst"] for x in r]), np.array([x["bound"] for x in r])
            m = [x for x in r if x["measured"] and x["measured"]["error_mm"] is not None]
            cells = []
            for t in TOLERANCES:
                meets = [x for x in r if verdict_at(x, t) == "meets"]
                fails = [x for x in r if verdict_at(x, t) == "does not meet"]
                cells.append(f"{len(meets)} ({sum(x['true_worst'] > t for x in meets)}) / "
                             f"{len(fails)} ({sum(x['true_worst'] <= t for x in fails)})")
            rows.append(
                f"| {arm}, {label} | {len(r)} | {sum(x['failed'] for x in r)} of {sum(x['samples'] for x in r)} "
                f"({sum(x['said_failed'] or not x['failed'] for x in r)} of {len(r)} said) | "
                f"{int((worst <= bound).sum())} of {len(r)} | {np.median(worst):.3f} ({worst.max():.3f}) | "
                f"{sum(x['base_worst'] <= x['bound'] for x in r)} of {len(r)}; "
                f"{np.median([x['base_worst'] for x in r]):.2f} | "
                f"{np.median(bound):.2f} ({bound.min():.2f} - {bound.max():.2f}) | "
                f"{np.median(bound / worst):.1f} ({(bound / worst).min():.1f} - {(bound / worst).max():.1f}) | "
                f"{np.median([x['parametric'] for x in r]):.2f} | {np.median([x['sigma_u'] for x in r]):.3f} | "
                f"{np.median([x['std_mm'][0] for x in r]):.2f} | "
                + (f"{np.median([x['measured']['error_mm'] for x in m]):.3f}, "
                   f"{sum(x['true_share'] >= x['measured']['share'] for x in m)} of {len(m)}" if m else "-")
                + " | " + " | ".join(cells) + " |")
    lines = [
        HEADING, "",
        f"Written by `scripts/reproduce_camera_accuracy.py` (its docstring gives the set-up): {NOISE_PX} px, "
        f"{TRAIN} training and {HELD} held-out images, the held-out ones drawn at random inside the volume, "
        f"{SAMPLES} volume samples, {CONFIDENCE:.0%} confidence, {DRAWS} draws. The truth is commanded to the "
        "compensated joints of every sample and its error taken against the nominal target in the calibration's "
        "world, reached from the truth's through the first camera's (the board's) true and fitted poses: the "
        "error against the cameras (the board), as the statement means it. Samples where compensation fails are counted (the statement must say how many) and left out of "
        "the true worst. *meets* at each tolerance is the verdict's rule read from the same statement "
        "(scripts/reproduce_volume.py, `verdict_at`); wrong: signed while the true worst passes the tolerance.",
        "",
        "| arm, set-up | seeds | samples not compensated (statements that say so) | true worst within the bound | "
        "true worst, median (largest), mm | in the robot's own base frame: within the bound; true worst, median, "
        "mm | bound, median (range), mm | bound / true worst, median (range) | "
        "from the coefficients alone, median, mm | unmodelled sigma, median, mm | held-out point 1 sigma, median, "
        "mm | measured 95 % error, median mm; truths where 95 % of the samples lie within it | "
        + " | ".join(f"at {t} mm: *meets* (wrong) / *does not meet* (wrong)"
                     for t in TOLERANCES) + " |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|" + "---|" * len(TOLERANCES),
        *rows, "",
        *findings(results),
    ]
    write_section(HEADING, lines)
    print("\n".join(lines))


def findings(results: list[dict]) -> list[str]:
    """What the table shows, in figures read from it."""
    def of(mount, singular=False):
        return [x for x in results if x["mount"] == mount and ("stretched" in x["arm"]) == singular]

    def ratio(r):
        return np.median([x["bound"] / x["true_worst"] for x in r])

    clean = of("world") + of("tool")
    through = of("world", True) + of("tool", True)
    covered = sum(x["true_worst"] <= x["bound"] for x in results)
    meets = [(x, t) for x in results for t in TOLERANCES if verdict_at(x, t) == "meets"]
    refuted = [(x, t) for x in of("world") + of("tool") for t in TOLERANCES if verdict_at(x, t) == "does not meet"]
    base = [x for x in results if x["base_worst"] > x["bound"]]
    return [
        f"- **Coverage**: against the cameras (the board), the true worst of the samples compensated lies within the "
        f"bound in {covered} of {len(results)} statements; the measured statement (95 % of the volume within the "
        f"k-th largest held-out error) held for the truth's samples in "
        f"{sum(x['true_share'] is not None and x['true_share'] >= 0.95 for x in results)} of {len(results)}. "
        f"*meets* is signed in {len(meets)} of the {len(results) * len(TOLERANCES)} readings at "
        f"{', '.join(map(str, TOLERANCES))} mm, wrongly in {sum(x['true_worst'] > t for x, t in meets)}; it needs "
        f"the bound within the tolerance, which happens from about 2 mm here.",
        f"- **How conservative**: the bound is {ratio(of('world')):.1f} times the true worst in the median with two "
        f"fixed cameras and {ratio(of('tool')):.1f} times with a camera on the tool (volumes away from singular "
        f"postures). The coefficients' draws are taken with the first camera's (the board's) fitted pose and "
        f"bounded against it (`verify.images.against_reference`), where the images measure the robot and where "
        f"the truth's error is read here; bounded in the robot's own frame instead, they held where the base sits "
        f"against the cameras as well, which no image sees, and made the bound many times larger.",
        f"- **does not meet from the draws alone** (their low quantile above the tolerance) is said in "
        f"{len(refuted)} readings of the volumes away from singular postures, wrongly in "
        f"{sum(x['true_worst'] <= t for x, t in refuted)}.",
        f"- **The frame**: the statement is about positions against the first camera (the board); in the robot's "
        f"own base frame, which the images do not fix, the truth's worst passes the bound in {len(base)} of "
        f"{len(results)} statements (`meaning` in the JSON says what the mm are against).",
        f"- **Singular postures**: where the volume takes the elbow through stretched, compensation fails at "
        f"{sum(x['failed'] for x in through)} of {sum(x['samples'] for x in through)} samples; every one of those "
        f"{len(through)} statements says at how many of its samples (and so says *cannot tell*); the volumes away "
        f"from it fail at {sum(x['failed'] for x in clean)} of {sum(x['samples'] for x in clean)}.",
        "",
    ]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--arms", nargs="*", default=list(ARMS))
    parser.add_argument("--render", action="store_true", help="write the doc from the last run's results")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    saved = OUT / "results.json"
    if args.render:
        write(json.loads(saved.read_text()))
        return
    warnings.simplefilter("ignore")
    results = []
    for arm in args.arms:
        for mount in ("world", "tool"):
            for seed in range(args.seeds):
                r = one(arm, mount, seed)
                results.append(r)
                print(arm, mount, seed, {k: r[k] for k in ("failed", "true_worst", "bound", "verdict")}, flush=True)
                saved.write_text(json.dumps(results))
    write(results)


if __name__ == "__main__":
    main()
