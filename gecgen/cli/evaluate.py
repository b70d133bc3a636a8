"""`gecgen evaluate CALIB DATA [--register [auto|always|never]]`: position errors of new data before and after the
calibration; `--cameras CAMERAS.yaml [--board BOARD.yaml]`: image points' residuals, px."""
from __future__ import annotations

from gecgen.cli.common import (CALIBRATION_HELP, DATA_HELP, add_orientation_length, add_tolerance, next_commands,
                               progress_status, say, warned)
from gecgen.cli.human import warning_lines
from gecgen.cli.register import add_register


def add_parser(command):
    """Register `evaluate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("evaluate", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("data", help=DATA_HELP)
    add_register(p, ("auto", "always", "never"), bare="always", default="never",
                 lead="always: DATA was measured from a new tracker stationing: fit only its frame (the "
                      "calibration's coefficients held) and score the uncalibrated model in its own fitted frame; "
                      "never: DATA is in the calibration's tracker frame; auto: as always when the frame fitted on "
                      "DATA is over 1 degree or 20 mm from the calibration's or a station is new, else as never")
    add_orientation_length(p, calibration_first=True)
    add_tolerance(p)
    p.add_argument("--report", metavar="DIR",
                   help="folder for report.md (PNG plots beside it) and report.html (self-contained)")
    g = p.add_argument_group("with a camera (docs/reference.md, \"Cameras\"): DATA is a pixel file")
    g.add_argument("--cameras", metavar="FILE", help="camera file of the calibration's cameras: DATA's image points "
                                                     "are scored with the poses and intrinsics it fitted")
    g.add_argument("--board", metavar="FILE", help="board file of the chessboard a camera on the tool sees")


def run(args) -> dict:
    if args.cameras or args.board:
        return _pixels(args)
    with warned() as caught:
        return _evaluated(args, caught)


def _pixels(args) -> dict:
    """Held-out image points before and after a pixel calibration (`fit.camera.score_pixels`)."""
    from gecgen.cli.pixels import cameras_given, recorded_rig
    from gecgen.fit.camera import score_pixels
    from gecgen.model.pixels import read_pixels
    from gecgen.model.validation import require

    cameras_given(args)
    for option, default in (("register", "never"), ("tolerance_mm", None), ("report", None),
                            ("orientation_length", None)):
        require(getattr(args, option) == default, f"--{option.replace('_', '-')} is not supported with --cameras "
                                                  f"yet; leave it out")
    with warned() as caught:
        calibration, cameras, board = recorded_rig(args)
        data = read_pixels(args.data, calibration.robot, cameras, board)
        scores = score_pixels(calibration, args.calibration, data, cameras, board)
    return {"robot": calibration.robot.name, "data": str(args.data), "measurement": "pixels",
            "n_poses": data.n_poses, "n_points": len(data.uv), **scores, "warnings": warning_lines(caught)}


def _evaluated(args, caught: list) -> dict:
    """The scores, result and report; caught: the warnings said on the way (`warned`)."""
    from shlex import quote

    from gecgen.api import load_calibration
    from gecgen.report.verdict import Noise, assess

    with progress_status(not args.json) as status:
        say(status, f"loading the calibration {args.calibration} and its code")
        cal = load_calibration(args.calibration, orientation_length=args.orientation_length)
        say(status, f"scoring {args.data} before and after the calibration")
        score = cal.score(args.data, register={"always": True, "never": False}.get(args.register, args.register))
    registered = score.registrations is not None
    result = {"robot": cal.robot_.name, "error_model": cal.calibration_.model.source, "data": str(args.data),
              "n_poses": score.n_poses, "n_points": score.n_points,
              **({"n_orientations": score.n_orientations} if score.n_orientations else {}),
              "registered": registered}
    if registered:
        first = score.registrations[min(score.registrations)]
        result.update(before_registration="the nominal model's, fitted on DATA", registration=first,
                      registrations={str(k): v for k, v in score.registrations.items()},
                      tracker_frame=f"re-fitted on DATA with the calibration held: {first['angle_deg']:.3f} deg and "
                                    f"{first['distance_mm']:.1f} mm from the calibration's")
    else:
        result.update(before_registration="the calibration's", tracker_frame="the calibration's")
    result.update(before=score.before.to_dict(), after=score.after.to_dict(), extrapolation=score.extrapolation,
                  **({"after_inside": score.after_inside.to_dict()} if score.after_inside else {}),
                  **({"branches": score.branches} if score.branches else {}))
    fitted = cal.report_
    sig, relative = fitted.get("significance") or {}, score.data.relative is not None
    assessment = assess(after=result["after"], before=result["before"], held_out=True, n_poses=score.n_poses,
                        tolerance_mm=args.tolerance_mm, noise=Noise.of_significance(sig), n_train_poses=None,
                        held=(len(sig["held"]), fitted["n_identifiable"]) if "held" in sig and not sig.get(
                            "insignificant_carried") else None, extrapolation=score.extrapolation,
                        inside=result.get("after_inside"), relative=relative,
                        commands=next_commands(cal.robot_.source, "TRAIN.csv", f"--val {quote(args.data)}",
                                               args.calibration, None, relative, ""))
    result["assessment"], result["warnings"] = assessment.to_dict(), warning_lines(caught)
    if args.report:
        from gecgen import report

        result.update(report.write(report.content.evaluate(cal.calibration_, score.cm, score.data, score.y_before,
                                                           score.y, score.extrapolation, args.calibration, assessment,
                                                           result["warnings"]), args.report))
    return result
