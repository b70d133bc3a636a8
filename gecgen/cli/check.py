"""`gecgen check CALIB DATA [--tolerance-mm T] [--baseline BASE.csv [--noise-mm S]] [--history H.csv] [--label L]`:
a QA check of a calibrated robot.

A short measurement taken later (5 to 10 poses: a daily check of a patient positioner) against the
calibration, in its tracker frame (gecgen/verify/drift.py): pass or fail against the tolerance,
whether the difference is beyond the calibration's noise, and what it looks like (the tracker moved:
a rigid motion; the robot changed: the joint whose offset explains it). With --history, the check is
appended to a CSV of checks and the history is plotted beside it (H.png).
"""
from __future__ import annotations

import csv
import io
import math
from datetime import datetime, timezone
from pathlib import Path

from gecgen.cli.common import CALIBRATION_HELP, DATA_HELP, not_from_pixels, number

#: rad or m: a baseline's reading of a pose may differ from the check's by this much (a servo's
#: standstill error is a few 1e-5); the calibrated model carries the points across the difference
JOINT_MATCH = 1e-3
HISTORY = ["time_utc", "label", "n_points", "rms_mm", "max_mm", "tolerance_mm", "verdict", "beyond_noise",
           "p_value", "looks_like"]


def add_parser(command):
    """Register `check` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("check", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("data", help=DATA_HELP + "; measured in the calibration's tracker frame")
    p.add_argument("--tolerance-mm", type=number(0, above=True), help="largest point error that passes, mm")
    p.add_argument("--baseline", metavar="BASE", help="the same poses measured right after the calibration (a "
                                                      "measurement file, pose ids and targets those of DATA): the "
                                                      "change is judged against it point by point, so the model's "
                                                      "misfit at the check poses cancels")
    p.add_argument("--noise-mm", type=number(0, 1000, above=True),
                   help="with --baseline: the noise of one measurement per coordinate, mm (instrument and robot "
                        "repeatability); default the calibration's sigma, which also holds its misfit (safe)")
    p.add_argument("--history", help="CSV of checks to append this one to (created if absent); plotted beside it")
    p.add_argument("--label", help="this check's name in the history (default: the data file's name)")
    g = p.add_argument_group("with a camera (docs/reference.md, \"Cameras\"): DATA is a pixel file of new images")
    g.add_argument("--cameras", metavar="FILE", help="camera file of the calibration's cameras: DATA's image points "
                                                     "are judged with the poses and intrinsics it fitted, and each "
                                                     "camera's pose is refitted to tell a moved camera from a "
                                                     "changed robot")
    g.add_argument("--board", metavar="FILE", help="board file of the chessboard a camera on the tool sees")
    g.add_argument("--val", metavar="PIXELS", help="held-out images taken with the calibration (not fitted to): "
                                                   "their residual, the model's misfit away from the training poses "
                                                   "in it, is what DATA is judged against (default: the validation "
                                                   "images' a calibrate --cameras with --val or --holdout recorded, "
                                                   "else the calibration's training residual, which is strict)")


def run(args) -> dict:
    if args.cameras or args.board:
        return _pixels(args)
    from gecgen.api import load_calibration
    from gecgen.model.measurements import read_measurements
    from gecgen.model.validation import require

    require(not args.val, "--val gives held-out images: it goes with --cameras; for tracker data compare against "
                          "a --baseline")
    from gecgen.verify.drift import at_check_joints, check
    from gecgen.fit.identify import to_world
    from gecgen.fit.inputs import checked

    cal = load_calibration(args.calibration)
    calib = cal.calibration_
    not_from_pixels(calib.report, args.calibration, "check")
    data = read_measurements(args.data, calib.robot)
    require(data.relative is None and data.orientation is None,
            f"{args.data}: a check compares measured positions; give rows with x y z only")
    sigma_m = 1e-3 * float(cal.report_["sigma_mm"])
    require(sigma_m > 0, f"{args.calibration}: its fit left no residual (sigma 0): noise cannot be told from a change; "
                         f"check against a calibration from measured data")
    cm = checked(calib.model, calib.robot, data)
    y = to_world(calib.frames, data, "measure the check from the calibration's tracker stationing")
    require(args.noise_mm is None or args.baseline, "--noise-mm goes with --baseline: without one the change is "
                                                    "judged against the calibration's own sigma")
    _history_is_csv(args)
    baseline = None
    if args.baseline:
        points, q_base = _baseline(args.baseline, calib, data)
        baseline = at_check_joints(cm, data, calib.c, points, q_base)
    noise_m = sigma_m if args.noise_mm is None else 1e-3 * args.noise_mm
    verdict = check(cm, data, y, calib.c, noise_m if baseline is not None else sigma_m, args.tolerance_mm, baseline)
    result = {"robot": calib.robot.name, "data": str(args.data), "n_points": len(data.xyz),
              "calibration_sigma_mm": 1e3 * sigma_m,
              **({"baseline": str(args.baseline), "noise_mm": 1e3 * noise_m} if baseline is not None else {}),
              **verdict.to_dict()}
    return _recorded(args, result)


def _recorded(args, result: dict) -> dict:
    """result, with the check appended to --history when given."""
    if args.history:
        result["history"] = _append(Path(args.history), args.label or Path(args.data).name, result)
    return result


def _history_is_csv(args):
    from gecgen.model.validation import require

    # the plot is written beside the history as H.png: a history of that name would be replaced by it
    require(not args.history or Path(args.history).suffix.lower() != ".png",
            f"--history {args.history}: the history is a CSV of checks (its plot is written beside it as .png); give "
            f"a .csv file")


def _pixels(args) -> dict:
    """`check CALIB PIXELS.csv --cameras FILE [--board FILE]`: new images of the calibrated robot judged
    with the cameras (and board) as the calibration recorded them (`verify.drift.check_pixels`)."""
    from gecgen.cli.pixels import cameras_given, recorded_rig
    from gecgen.model.pixels import read_pixels
    from shlex import quote

    from gecgen.model.validation import require
    from gecgen.report.verdict import pixel_check_next_step
    from gecgen.verify.drift import check_pixels, pixel_reference

    cameras_given(args)
    require(not (args.baseline or args.noise_mm is not None),
            f"{'--baseline' if args.baseline else '--noise-mm'} is not supported with --cameras: new images are "
            f"judged against the calibration's own residual (px); leave it out")
    _history_is_csv(args)
    calibration, cameras, board = recorded_rig(args)
    data = read_pixels(args.data, calibration.robot, cameras, board)
    report = calibration.report
    require(report.get("sigma_px", 0) > 0, f"{args.calibration}: its fit left no residual (sigma 0 px): noise "
                                           f"cannot be told from a change; check against a calibration from "
                                           f"measured images")
    reference, against = None, ("the calibration's training residual (strict: new poses carry the model's misfit "
                                "away from the training poses; give held-out images as --val)")
    recorded = report.get("validation_px")
    if args.val:
        reference = pixel_reference(calibration, args.calibration, read_pixels(args.val, calibration.robot, cameras,
                                                                                board), cameras, board)
        against = f"the held-out images {args.val}"
    elif isinstance(recorded, dict) and recorded.get("sigma_px", 0) > 0 and recorded.get("dof", 0) > 0:
        reference = float(recorded["sigma_px"]), float(recorded["dof"])
        against = f"the calibration's validation images ({recorded.get('images')})"
    verdict = check_pixels(calibration, args.calibration, data, cameras, board, args.tolerance_mm, reference)
    train = report.get("train", {})
    result = {"robot": calibration.robot.name, "data": str(args.data), "measurement": "pixels",
              "n_poses": data.n_poses, "n_points": len(data.uv),
              "calibration": {"sigma_px": report["sigma_px"], "train_rms_px": train.get("rms_px"),
                              "train_rms_mm_at_target": train.get("rms_mm_at_target"),
                              **({"val_sigma_px": reference[0]} if reference else {})},
              "judged_against": against,
              **verdict.to_dict()}
    rig = f"--cameras {quote(args.cameras)}" + (f" --board {quote(args.board)}" if args.board else "")
    result["next_step"] = pixel_check_next_step(result, rig)
    return _recorded(args, result)


def _baseline(path: str, calib, data):
    """The baseline's points (R, 3, world) in the order of data's rows, matched by pose id and target,
    and the baseline's joint readings at each of data's poses (P, n). Readings further from the
    check's than JOINT_MATCH are not the same pose: another run's poses with the check's pose ids
    would be compared point by point with points elsewhere."""
    import numpy as np

    from gecgen.model.measurements import read_measurements
    from gecgen.model.validation import ModelError, require
    from gecgen.fit.identify import to_world

    base = read_measurements(path, calib.robot)
    require(base.relative is None and base.orientation is None,
            f"{path}: a baseline gives measured positions; give rows with x y z only")
    y = to_world(calib.frames, base, "measure the baseline from the calibration's tracker stationing")
    at = {(int(base.pose_ids[base.pose[r]]), int(base.target[r])): r for r in range(len(base.xyz))}
    rows = [at.get((int(data.pose_ids[data.pose[r]]), int(data.target[r]))) for r in range(len(data.xyz))]
    for r, k in enumerate(rows):
        require(k is not None, f"{data.source}: row {data.file_rows[r]}: pose {data.pose_ids[data.pose[r]]} target "
                               f"{calib.robot.target_names[data.target[r]]} is not in the baseline {path}; measure "
                               f"the baseline's poses and targets")
    rows = np.array(rows, int)
    q_base = np.empty_like(data.q)
    q_base[data.pose] = base.q[base.pose[rows]]
    far = np.abs(q_base - data.q)
    if far.max(initial=0.0) > JOINT_MATCH:
        k, j = np.unravel_index(int(np.argmax(far)), far.shape)
        r = int(np.argmax(data.pose == k))
        raise ModelError(f"{data.source}: row {data.file_rows[r]}: pose {data.pose_ids[k]} has q{j + 1} = "
                         f"{data.q[k, j]:.6g} but the baseline {path} has {q_base[k, j]:.6g} ({far[k, j]:.3g} apart, "
                         f"more than {JOINT_MATCH:g} rad or m): not the same pose; measure the baseline's poses")
    return y[rows], q_base


def _append(path: Path, label: str, result: dict) -> dict:
    """Append the check to the history CSV at path and plot the history beside it (path.png)."""
    from gecgen.model.files import write_atomically
    from gecgen.model.validation import read_text, require

    rows = []
    if path.exists():
        rows = list(csv.reader(io.StringIO(read_text(path, "history of checks"))))
        require(rows and rows[0] == HISTORY, f"{path}: not a history of gecgen check (its header should be "
                                             f"{','.join(HISTORY)}); give a new file or that history")
        rows = rows[1:]
        for k, row in enumerate(rows):
            numbers = [row[3], row[4], *([row[5]] if row[5] else [])] if len(row) == len(HISTORY) else ["-"]
            require(all(map(_number, numbers)),
                    f"{path}: row {k + 2}: not a check as gecgen check writes it ({len(HISTORY)} columns, rms_mm, "
                    f"max_mm and tolerance_mm numbers); restore the row or remove it")
    looks = result["looks_like"]
    rows.append([datetime.now(timezone.utc).isoformat(timespec="seconds"), label, str(result["n_points"]),
                 f"{result['rms_mm']:.4g}", f"{result['max_mm']:.4g}",
                 "" if result["tolerance_mm"] is None else f"{result['tolerance_mm']:.4g}", result["verdict"],
                 str(result["beyond_noise"]).lower(), f"{result['p_value']:.3g}",
                 looks["kind"] + (f" {looks['joint']}" if looks["kind"] == "joint" else "")])
    text = io.StringIO()
    csv.writer(text, lineterminator="\n").writerows([HISTORY, *rows])
    # the plot first and the history last: a check that fails on the way is not left in the history,
    # where a rerun would record it twice
    plot = path.with_suffix(".png")
    _plot(rows, plot)
    write_atomically(path, text.getvalue())
    return {"file": str(path), "checks": len(rows), "plot": str(plot)}


def _number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def _plot(rows: list[list[str]], path: Path):
    """The history's RMS and largest error per check, and the tolerance where given."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gecgen.model.files import write_atomically

    k = range(1, len(rows) + 1)
    fig, ax = plt.subplots(figsize=(8, 3.2))
    ax.plot(k, [float(r[3]) for r in rows], "o-", label="RMS point error")
    ax.plot(k, [float(r[4]) for r in rows], "s-", label="largest point error")
    tolerances = [(i, float(r[5])) for i, r in zip(k, rows) if r[5]]
    if tolerances:
        ax.plot(*zip(*tolerances), "k--", label="tolerance")
    ax.set_xticks(list(k), [r[1] for r in rows], rotation=30, ha="right", fontsize=7)
    ax.set_ylabel("mm")
    ax.set_title("QA checks")
    ax.legend(fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    write_atomically(path, buf.getvalue())
