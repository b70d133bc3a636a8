"""`gecgen redundancy ROBOT [DATA]`: which coefficients are eliminated and what they merge into."""
from __future__ import annotations

from gecgen.cli.common import ROBOT_HELP, add_orientation_length, number, robot_and_model
from gecgen.model import load_robot


def add_parser(command):
    """Register `redundancy` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("redundancy", run)
    p.add_argument("robot", help=ROBOT_HELP)
    p.add_argument("data", nargs="?", help="measurement CSV: also report what it leaves unexcited")
    p.add_argument("--errors", help="error-model file (default: robots/NAME.errors.yaml)")
    add_orientation_length(p)
    p.add_argument("--cameras", metavar="FILE", help="DATA is a pixel file of these cameras (docs/reference.md, "
                                                     "\"Cameras\"): also what pixels cannot give")
    p.add_argument("--board", metavar="FILE", help="with --cameras: the board a camera on the tool sees")
    p.add_argument("--noise-px", type=number(0, 100, above=True), metavar="PX",
                   help="with --cameras: the corners' noise per coordinate, px (1 sigma): what the images determine "
                        "too weakly against it is named (default: the nominal model's linearised residual)")


def run(args) -> dict:
    if args.cameras or args.board or args.noise_px is not None:
        return _pixels(args)
    from gecgen.fit.inputs import checked, on_points, placed
    from gecgen.fit.identify import redundancy

    data = None
    if args.data:
        from gecgen.model.measurements import read_measurements

        data = read_measurements(args.data, load_robot(args.robot))
    robot, model = robot_and_model(args.robot, args.errors, data.aux_names if data else ())
    if data:
        robot = placed(robot, data)[0]
        robot, data = on_points(robot, args.orientation_length, data)
    result = redundancy(checked(model, robot, data), data).to_dict()
    return {"robot": robot.name, "error_model": model.source, "data": args.data, **result}


def _pixels(args) -> dict:
    from gecgen.model.cameras import read_board, read_cameras
    from gecgen.model.pixels import read_pixels
    from gecgen.model.validation import require
    from gecgen.fit.camera import pixel_redundancy

    require(args.cameras and args.data, "--cameras needs DATA, a pixel file, and --board and --noise-px go with "
                                        "--cameras")
    cameras = read_cameras(args.cameras)
    board = read_board(args.board) if args.board else None
    robot, model = robot_and_model(args.robot, args.errors)
    data = read_pixels(args.data, robot, cameras, board)
    return {"robot": robot.name, "error_model": model.source, "data": args.data,
            **pixel_redundancy(robot, model, data, cameras, board, args.noise_px)}
