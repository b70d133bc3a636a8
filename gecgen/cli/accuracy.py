"""`gecgen accuracy CALIB VOLUME DATA [--val VAL] [--tolerance-mm T] [--noise-mm S] [--plot MAP.png]`.

The accuracy statement over a declared volume (gecgen/model/volume.py for the file,
gecgen/verify/volume.py for the method): the volume is sampled, the compensated error's worst over it
is bounded with a stated confidence from the coefficients' covariance and the residual the model
leaves, and judged against the tolerance: meets, does not meet, or cannot tell; and where in the
volume the error is largest.
"""
from __future__ import annotations

from pathlib import Path

from gecgen.cli.common import (CALIBRATION_HELP, DATA_HELP, MAX_SEED, not_from_pixels, number, progress_status, say,
                               warned, whole)
from gecgen.cli.human import warning_lines

#: Monte Carlo draws of the coefficient and unmodelled errors
DRAWS = 2000


def add_parser(command):
    """Register `accuracy` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("accuracy", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("volume", help="volume file (YAML: angle_unit, joints, targets or tool_box, place_at, payload_kg, "
                                  "samples; docs/reference.md, \"Accuracy over a volume\")")
    p.add_argument("data", help=DATA_HELP + "; the data the calibration was fitted to: the coefficients' covariance "
                                            "is taken from it pose by pose, and, without --val, the error the "
                                            "model does not describe")
    p.add_argument("--tolerance-mm", type=number(0, above=True),
                   help="the largest compensated point error the volume may have, mm")
    p.add_argument("--confidence", type=number(0.5, 1, above=True), default=0.95,
                   help="confidence of the stated bound (default 0.95)")
    p.add_argument("--noise-mm", type=number(0, 100),
                   help="the instrument's noise per point and coordinate in the data, mm (1 sigma); without it the "
                        "whole residual counts as unmodelled error")
    p.add_argument("--repeatability-mm", type=number(0, 100), default=0.0,
                   help="the robot's repeatability per coordinate, mm (1 sigma: ISO 9283 RP / 3 / sqrt(3) roughly); "
                        "taken off the residual as it moves every target of a pose alike. The bound is on the "
                        "systematic error: a single visit adds the repeatability")
    p.add_argument("--val", metavar="DATA", help="measurements held out from the fit, in the calibration's tracker "
                                                 "frame: their residual, instead of DATA's, sets the error the model "
                                                 "does not describe (best taken inside the volume)")
    p.add_argument("--share", type=number(0, 0.9999, above=True), default=0.95,
                   help="with --val: the share of the volume the statement measured at the held-out poses inside "
                        "it is about (default 0.95; at --confidence c it needs n poses with 1 - share^n >= c: 59 "
                        "for the defaults)")
    p.add_argument("--draws", type=whole(100, 1_000_000), default=DRAWS, help=f"Monte Carlo draws (default {DRAWS})")
    p.add_argument("--seed", type=whole(0, MAX_SEED), default=0, help="seed of the samples and draws")
    p.add_argument("--plot", metavar="PNG", help="map of where in the volume the error bound is largest")
    p.add_argument("--report", metavar="DIR", help="folder for report.md and report.html: the statement, its reasons, "
                                                   "where it is worst (the map) and what it was read from")
    g = p.add_argument_group("with cameras (docs/reference.md, \"Cameras\"): DATA and --val are pixel files")
    g.add_argument("--cameras", metavar="FILE", help="camera file of the calibration's cameras: the held-out markers "
                                                     "(--val) seen by two fixed cameras or more are triangulated "
                                                     "through the poses and intrinsics it fitted (a camera on the "
                                                     "tool: its pose from the board), and the statement is read from "
                                                     "those positions")
    g.add_argument("--board", metavar="FILE", help="board file of a camera on the tool: the held-out images' "
                                                   "camera poses from the board give the targets' positions")


def run(args) -> dict:
    with warned() as caught, progress_status(not args.json) as status:
        say(status, f"reading {args.calibration} and the data")
        return _stated(args, caught, status)


def _stated(args, caught: list, status) -> dict:
    """The statement, its result, map and report; caught: the warnings said on the way (`warned`);
    says how far it is on `status` (`common.progress_status`)."""
    import numpy as np

    from gecgen.api import load_calibration
    from gecgen.model.validation import require
    from gecgen.model.volume import load_volume
    from gecgen.report.verdict import accuracy_next_step
    from gecgen.verify.volume import accuracy

    if args.cameras or args.board:
        calib, volume, samples, statement, measured_by = _from_images(args, status)
    else:
        cal = load_calibration(args.calibration)
        calib = cal.calibration_
        not_from_pixels(calib.report, args.calibration, "accuracy")
        _without_aux(calib, args.calibration)
        volume = load_volume(args.volume, calib.robot)
        data, y = _positions(args.data, calib)
        held_out = _positions(args.val, calib) if args.val else None
        say(status, f"bounding the compensated error over {args.volume} ({args.draws} draws of the coefficients)")
        samples, statement, _ = accuracy(calib, volume, data, y, held_out,
                                         None if args.noise_mm is None else 1e-3 * args.noise_mm,
                                         1e-3 * args.repeatability_mm, args.tolerance_mm,
                                         args.confidence, args.draws, np.random.default_rng(args.seed), args.share)
        measured_by = None
    k = statement.worst
    units = [(180 / np.pi, "deg") if j.kind == "R" else (1.0, "m") for j in calib.robot.joints]
    worst = {"bound_mm": float(statement.per_point_mm[k]), "worst_in_draws": statement.worst_share,
             "explanation": f"The sample where the bound is reached: the bound, {statement.bound_mm:.3g} mm, is "
                            f"the {statement.confidence:.0%} quantile of the worst error over all {len(samples.q)} "
                            f"samples at once, and of the draws whose worst reaches it this sample is the worst in "
                            f"{statement.worst_share:.0%}. Its own {statement.confidence:.0%} quantile "
                            f"({statement.per_point_mm[k]:.3g} mm, bound_mm here) can be lower: one sample's error "
                            f"passes its own quantile in {1 - statement.confidence:.0%} of the draws, the worst of all "
                            f"samples passes it more often",
             "joints": {j.name: float(scale * v) for j, (scale, _), v in zip(calib.robot.joints, units, samples.q[k])},
             "joint_units": {j.name: unit for j, (_, unit) in zip(calib.robot.joints, units)},
             "payload_kg": float(samples.payload_kg[k]), "world_m": samples.world[k].tolist(),
             **({"tool_point_m": samples.point[k].tolist()} if volume.tool_box is not None else
                {"target": list(calib.robot.targets)[samples.target[k]]})}
    result = {"robot": calib.robot.name, "volume": str(args.volume), "samples": len(samples.q),
              "unreachable": samples.unreachable, **statement.to_dict(),
              "residual_from": str(args.val or args.data), "held_out": bool(args.val), "worst_at": worst,
              **({"measurement": "pixels", "measured_by": measured_by.to_dict(),
                  "meaning": MEANING["tool" if args.board else "world"]} if measured_by else {})}
    kept = [("--noise-mm", args.noise_mm, None), ("--repeatability-mm", args.repeatability_mm, 0.0),
            ("--confidence", args.confidence, 0.95), ("--share", args.share, 0.95)]
    rig = "".join(f" {o} {v}" for o, v in (("--cameras", args.cameras), ("--board", args.board)) if v)
    assessment = accuracy_next_step(result, args.calibration, args.volume, args.data,
                                    "".join(f" {o} {v:g}" for o, v, default in kept if v != default) + rig)
    result["next_step"], result["warnings"] = assessment.next_step, warning_lines(caught)
    if args.plot or args.report:
        from gecgen.model.files import write_atomically
        from gecgen.report import content, plots, write

        say(status, "drawing the map of the bound over the volume, writing the outputs")
        figure = plots.volume_map(calib.robot, volume, samples, statement)
        if args.plot:
            write_atomically(Path(args.plot), figure.png)
            result["plot"] = str(args.plot)
        if args.report:
            result.update(write(content.accuracy(result, figure, assessment, warning_lines(caught)), args.report))
    return result


#: what the statement from images is about, said with its figures: fixed cameras, a camera on the tool
MEANING = {"world": "the compensated position error of the markers (the robot file's targets) in mm, over the "
                    "volume, read from held-out markers triangulated by two fixed cameras or more, and bounded "
                    "against the first camera (as the fit placed it: where the robot's base sits against the "
                    "cameras, which the images fix only as well as the fit does, is not in it); not the tool's "
                    "orientation, and not what one camera alone sees (a pixel fixes a marker across its ray, not "
                    "along it)",
           "tool": "the compensated position error of the robot file's targets in mm, over the volume, read from "
                   "the tool poses the carried camera measures from the board at held-out poses (its pose from the "
                   "board's corners, carried through the board's and the camera's poses the calibration fitted), "
                   "bounded against the board (as the fit placed it: where the robot's base sits against the board, "
                   "which the images fix only as well as the fit does, is not in it); an error the calibration "
                   "shares with the camera's fitted pose on the tool is not seen"}


def _without_aux(calib, where: str):
    from gecgen.model.validation import require

    require(not calib.model.aux, f"{where}: its model uses auxiliary signals ({', '.join(calib.model.aux)}), which "
                                 f"a volume file cannot range over yet; state the accuracy of a model without them")


def _from_images(args, status):
    """The statement from images (`verify.images.accuracy_from_images`): (calibration, volume, samples,
    statement, `verify.images.Positions`)."""
    import numpy as np

    from gecgen.cli.pixels import cameras_given, recorded_rig
    from gecgen.model.pixels import read_pixels
    from gecgen.model.validation import require
    from gecgen.model.volume import load_volume
    from gecgen.verify.images import accuracy_from_images

    cameras_given(args)
    given = [o for o, v in (("--noise-mm", args.noise_mm is not None), ("--repeatability-mm", args.repeatability_mm))
             if v]
    require(not given, f"{given[0] if given else ''} is not supported with --cameras: the triangulated points' noise "
                       f"is counted as model error (safe); leave it out")
    require(args.val, "--cameras: the statement in mm is read from held-out images (markers triangulated by two "
                      "cameras or more): give them as --val PIXELS.csv")
    calibration, cameras, board = recorded_rig(args)
    _without_aux(calibration, args.calibration)
    volume = load_volume(args.volume, calibration.robot)
    train, val = (read_pixels(f, calibration.robot, cameras, board) for f in (args.data, args.val))
    say(status, f"bounding the compensated error over {args.volume} ({args.draws} draws of the coefficients)")
    samples, statement, _, info = accuracy_from_images(calibration, args.calibration, volume, train, val, cameras,
                                                       board, args.tolerance_mm, args.confidence, args.draws,
                                                       np.random.default_rng(args.seed), args.share)
    return calibration, volume, samples, statement, info


def _positions(path: str, calib):
    """Measurements at path and their points in the calibration's world (m); positions only."""
    from gecgen.model.measurements import read_measurements
    from gecgen.model.validation import require
    from gecgen.fit.identify import to_world

    data = read_measurements(path, calib.robot)
    require(data.relative is None and data.orientation is None,
            f"{path}: point, plane or orientation rows: a statement over a volume is read from measured positions "
            f"only, and is not supported for calibrations from sockets, planes or poses yet")
    return data, to_world(calib.frames, data, "calibrate with it")
