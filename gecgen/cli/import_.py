"""`gecgen import ROBOT WIDE.csv --mapping MAP.yaml -o OUT.csv [--targets m1,m2] [--sep ';'] [--decimal ','] [--json]`,
`gecgen import ROBOT READINGS.csv --images FOLDER --board BOARD.yaml --cameras CAMERAS.yaml -o PIXELS.csv`,
`gecgen import ROBOT SOCKET.csv... --sockets [--socket-distance M [--distance-std M]] [--target T] -o OUT.csv`.

Converts a wide table (several points per row, see gecgen/model/wide.py), or socket recordings (one
file of joint readings per socket, see gecgen/model/socket_files.py), into the contract's
measurement CSV (comma-separated, decimal points). `--sep` and `--decimal` read exports that
separate columns by ';', tabs or '|' and write 1,234 for 1.234, as European spreadsheets and tracker
software do. Joint readings outside the robot's limits are reported (JSON `outside_limits` and a
warning on stderr), never clipped: the values are written as read.
"""
from __future__ import annotations

from gecgen.cli.common import ROBOT_HELP, number

import dataclasses
import sys

import numpy as np

from gecgen.model import load_robot
from gecgen.model.measurements import Measurements, write_measurements
from gecgen.model.robot import Robot
from gecgen.model.socket_files import read_socket_files
from gecgen.model.table import SEPARATORS
from gecgen.model.validation import require
from gecgen.model.wide import import_wide, load_mapping


def add_parser(command):
    """Register `import` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("import", run)
    p.add_argument("robot", help=ROBOT_HELP)
    p.add_argument("table", nargs="+", help="CSV with one row per pose (with --sockets: one CSV per socket)")
    p.add_argument("--mapping", help="column mapping YAML: which columns hold the joints, targets, orientations and "
                                     "wrench (docs/reference.md, \"Files\")")
    p.add_argument("--sockets", action="store_true",
                   help="the tables are socket recordings: one file per socket, a configuration's joint readings a "
                        "row; a folder's files are one plate's sockets (docs/reference.md, \"Sockets, distances and "
                        "planes\")")
    p.add_argument("--socket-distance", type=number(0, 1e3, above=True),
                   help="with --sockets: the distance between a folder's two sockets, m")
    p.add_argument("--distance-std", type=number(0, 1), default=0.0,
                   help="with --socket-distance: its standard uncertainty, m (default 0: exact)")
    p.add_argument("--target", help="with --sockets: the target seated in the sockets (default: the robot's only one)")
    p.add_argument("--targets", help="comma-separated targets to keep (default: every mapped target)")
    p.add_argument("-o", "--output", required=True, help="measurement CSV to write (docs/reference.md, \"Files\")")
    p.add_argument("--sep", default=",", help="the table's column separator: ',' (default), ';', tab or '|'")
    p.add_argument("--decimal", default=".", choices=[".", ","],
                   help="the decimal mark of the table's numbers: '.' (default) or ',' (1,234 is 1.234)")
    g = p.add_argument_group("with a camera (docs/reference.md, \"Cameras\"): TABLE is a readings file, one row per "
                             "image (image, camera, q1..qn)")
    g.add_argument("--images", metavar="FOLDER", help="folder of the board's images; writes a pixel file")
    g.add_argument("--board", metavar="FILE", help="with --images: the board file (chessboard or charuco: inner corners, square)")
    g.add_argument("--cameras", metavar="FILE", help="with --images: the camera file")


def keep_targets(robot: Robot, data: Measurements, option: str) -> Measurements:
    """The rows of the targets named in `option` ("m1,m3"); every pose is kept."""
    names = list(robot.targets)
    keep = [t.strip() for t in option.split(",")]
    for t in keep:
        require(t in names, f"--targets: '{t}' is not a target of {robot.name} ({', '.join(names)})")
    rows = np.isin(data.target, [names.index(t) for t in keep])
    require(rows.any(), f"--targets {option}: the table measures none of these targets")
    return dataclasses.replace(data, pose=data.pose[rows], target=data.target[rows], xyz=data.xyz[rows],
                               orientation=None if data.orientation is None else data.orientation[rows])


def outside_limits(robot: Robot, data: Measurements) -> list[dict]:
    """Every joint reading outside its limits: table row (header = 1), joint, value, limit, excess (m or rad)."""
    lower, upper = [jt.lower for jt in robot.joints], [jt.upper for jt in robot.joints]
    out = []
    for r, j in np.argwhere((data.q < lower) | (data.q > upper)):
        joint, value = robot.joints[j], float(data.q[r, j])
        limit = joint.lower if value < joint.lower else joint.upper
        out.append({"row": int(r) + 2, "joint": joint.name, "value": value, "limit": limit,
                    "excess": abs(value - limit)})
    return out


def separator(option: str, decimal: str) -> str:
    """The character `--sep` names ("tab" or a tab for a tab)."""
    seps = {sep: sep for sep in SEPARATORS} | {"tab": "\t"}
    require(option in seps, f"--sep {option!r}: give ',', ';', tab or '|'")
    require(seps[option] != decimal, f"--sep {option!r} --decimal {decimal!r}: a comma cannot both separate the "
                                     f"columns and mark the decimals; give the table's separator (--sep ';')")
    return seps[option]


def run(args) -> dict:
    sep = separator(args.sep, args.decimal)
    robot = load_robot(args.robot)
    if args.images or args.board or args.cameras:
        return _images(args, robot)
    if args.sockets:
        require(not args.mapping and not args.targets, "--sockets reads socket files: no --mapping or --targets")
        data = read_socket_files(args.table, robot, args.target, args.socket_distance, args.distance_std, sep,
                                 args.decimal)
        write_measurements(args.output, robot, data, wrench=False)
        return {"robot": robot.name, "output": str(args.output), "poses": data.n_poses, "rows": len(data.xyz),
                **data.relative.summary(), "outside_limits": _warn_outside(robot, data)}
    require(args.socket_distance is None and args.target is None,
            "--socket-distance and --target go with --sockets (socket files)")
    require(args.mapping, "--mapping: give the column mapping of the wide table (or --sockets for socket files)")
    require(len(args.table) == 1, f"{len(args.table)} tables: a wide table is imported one at a time "
                                  f"(several files are socket files: --sockets)")
    mapping = load_mapping(args.mapping, robot)
    data = import_wide(args.table[0], robot, mapping, sep, args.decimal)
    if args.targets:
        data = keep_targets(robot, data, args.targets)
    write_measurements(args.output, robot, data, wrench=bool(mapping.wrench))
    outside = _warn_outside(robot, data)
    oriented = {} if data.orientation is None else {"orientations": int(np.sum(~np.isnan(data.orientation[:, 0, 0])))}
    return {"robot": robot.name, "output": str(args.output), "poses": data.n_poses, "rows": len(data.xyz),
            "targets": sorted({list(robot.targets)[t] for t in data.target}, key=list(robot.targets).index),
            **oriented, "outside_limits": outside}


def _warn_outside(robot: Robot, data: Measurements) -> list[dict]:
    """`outside_limits`, and a warning on stderr when there are any."""
    outside = outside_limits(robot, data)
    if outside:
        worst = max(outside, key=lambda o: o["excess"])
        print(f"gecgen import: warning: {len(outside)} joint readings outside the limits of {robot.name}, kept as read "
              f"(largest: {worst['joint']} = {worst['value']:g} beyond {worst['limit']:g} by {worst['excess']:.3g}, "
              f"row {worst['row']})", file=sys.stderr)
    return outside


def _images(args, robot: Robot) -> dict:
    """`import --images`: the board's corners in every image, as a pixel file; the images where the
    board is not found named on stderr and in the JSON (`not_found`)."""
    from gecgen.model.cameras import read_board, read_cameras
    from gecgen.model.images import detect
    from gecgen.model.pixels import write_pixels

    require(args.images and args.board and args.cameras, "--images, --board and --cameras go together: the folder "
                                                          "of images, the board file and the camera file")
    require(not (args.mapping or args.sockets or args.targets), "--images reads a readings file: no --mapping, "
                                                                "--sockets or --targets")
    require(len(args.table) == 1, f"{len(args.table)} tables: give one readings file (a row per image)")
    found = detect(args.table[0], args.images, robot, read_cameras(args.cameras), read_board(args.board))
    write_pixels(args.output, robot, found.pixels)
    if found.not_found:
        print(f"gecgen import: warning: the board was not found in {len(found.not_found)} images, which give no "
              f"rows: {', '.join(found.not_found)}", file=sys.stderr)
    return {"robot": robot.name, "output": str(args.output), "images": found.pixels.n_poses + len(found.not_found),
            "poses": found.pixels.n_poses, "rows": len(found.pixels.uv), "not_found": list(found.not_found)}
