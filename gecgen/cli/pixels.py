"""`gecgen identify ROBOT PIXELS.csv --cameras CAMERAS.yaml [--board BOARD.yaml]`: a calibration from image
points (`runtime.camera`), written as identify writes one."""
from __future__ import annotations

from gecgen.cli.common import number
from gecgen.model.validation import require


def add_options(p):
    """identify's options for image points."""
    g = p.add_argument_group("with a camera (docs/reference.md, \"Cameras\"): DATA is a pixel file")
    g.add_argument("--cameras", metavar="FILE", help="camera file: each camera's intrinsics and mount (world or tool)")
    g.add_argument("--board", metavar="FILE", help="board file of the chessboard a camera on the tool sees")
    g.add_argument("--noise-px", type=number(0, 100, above=True), metavar="PX",
                   help="the corners' noise per coordinate, px (1 sigma): the coefficients the images determine too "
                        "weakly against it are held at zero and named (default: the fit's own residual)")


def identified(args) -> dict:
    """The calibration from the pixel file args.data and its JSON result."""
    from gecgen.cli.common import robot_and_model
    from gecgen.model.cameras import read_board, read_cameras
    from gecgen.model.pixels import read_pixels
    from gecgen.runtime.calibration import save
    from gecgen.runtime.camera import calibration_of, fit_pixels, refuse_untrustworthy

    require(args.cameras, "--board names the board a carried camera sees: give --cameras too")
    for option in ("ridge", "rank_tol", "noise_mm", "report"):
        value = getattr(args, option, None)
        require(value in (None, "0", False), f"--{option.replace('_', '-')} is not supported with --cameras yet; "
                                             f"leave it out")
    require(args.register in ("auto", "never"), "--register always: with --cameras the cameras' poses are fitted "
                                               "with the robot; leave it out")
    cameras = read_cameras(args.cameras)
    board = read_board(args.board) if args.board else None
    robot, model = robot_and_model(args.robot, args.errors)
    data = read_pixels(args.data, robot, cameras, board)
    require(not model.aux or set(model.aux) <= set(data.aux_names),
            f"{args.data}: the error model uses auxiliary signals {', '.join(model.aux)} the pixel file lacks; "
            f"add the columns or use another error model")
    fit = fit_pixels(robot, model, data, cameras, board, loss=args.loss, noise_px=args.noise_px)
    refuse_untrustworthy(fit, str(args.data))
    calibration = calibration_of(robot, model, fit)
    out = args.output or f"{robot.name}.calib.json"
    save(calibration, out)
    return {"robot": robot.name, "data": str(args.data), "calibration": str(out), "measurement": "pixels",
            **{k: calibration.report[k] for k in ("n_params", "n_identifiable", "eliminated", "before", "train",
                                                  "sigma_px", "outliers", "converged", "iterations", "cameras",
                                                  "held", "scale")},
            **({"board": calibration.report["board"]} if board is not None else {}),
            "next": f"gecgen compensate {out} POSES.csv -o OUT.csv, gecgen export {out} --c DIR"}
