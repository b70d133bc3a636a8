"""`gecgen simulate`: measurements of a truth robot, as a tracker would record them."""
from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml

from gecgen.cli import pixels
from gecgen.cli.common import MAX_POSES, MAX_SEED, ROBOT_HELP, number, numbers, progress_status, say, whole
from gecgen.model.files import write_atomically
from gecgen.model import load_robot
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import pose_id_column, read_commands, write_measurements
from gecgen.model.table import read_table
from gecgen.model.validation import ModelError, read_yaml, require
from gecgen.simulate import load_truth, one_at_a_time, paper_pps, paper_split, random_design, simulate
from gecgen.simulate.designs import Design, barely_moving, constant_orientation
from gecgen.simulate.fixtures import Fixtures, simulate_fixtures


#: poses of the random design when --poses is not given
POSES = 200
#: how far the joint of --design barely-moving moves when --span is not given (rad, or m)
SPAN = 1e-3
#: the socket and plane options' values when not given (each is refused without --plates or --planes)
FIXTURE_DEFAULTS = {"per_socket": 25, "socket_distance": 0.05, "distance_std": 0.0, "touches": 30,
                    "seating_noise": 1e-5, "encoder_noise": 1e-5}


def add_parser(command):
    p = command("simulate", run)
    p.add_argument("robot", help=ROBOT_HELP)
    p.add_argument("--truth", help="truth file (default: NAME.truth.yaml beside the robot file; without one, the "
                                   "nominal robot: no errors, no noise)")
    p.add_argument("--design", choices=["random", "one-at-a-time", "paper", "tool-grid", "barely-moving"],
                   default="random",
                   help="random poses within the limits, one joint at a time, the seed paper's PPS design, a "
                        "grid the tool visits keeping the orientation it has at --home, as a laser tracker's "
                        "reflector is kept facing the tracker, or random poses in which joint --joint barely "
                        "moves (default %(default)s)")
    p.add_argument("--commands",
                   help="instead of --design: the joints of this CSV (q1..qn a row, the pose ids its pose column's, "
                        "else 0, 1, ...), as a robot commanded to them is measured: an ISO 9283 plan "
                        "(`gecgen iso9283 --plan`) for the run before, its compensated commands for the run after")
    p.add_argument("--home", type=numbers(),
                   help="--design tool-grid: comma-separated joint values (rad or m) whose tool orientation the "
                        "grid keeps, and whose tool origin is its centre; with --cameras the centre of the poses "
                        "(default: the middle of each joint's range)")
    p.add_argument("--spacing", type=number(0, 10, above=True), default=0.1,
                   help="--design tool-grid: distance between grid points, m (default %(default)s)")
    p.add_argument("--grid", type=numbers(1), default=[6, 6, 6],
                   help="--design tool-grid: points along x, y, z of the world (default 6,6,6; 8,8,1 a plane)")
    p.add_argument("--joint", type=whole(1, 1000),
                   help="--design barely-moving: the joint (1-based, as q1..qn) that stays within --span about the "
                        "middle of its range")
    p.add_argument("--span", type=numbers(0), metavar="S",
                   help=f"how far joints move, rad (m for a prismatic joint): with --design barely-moving, that "
                        f"joint (one value, default {SPAN:g}); with --cameras, the poses are drawn in --home +- span "
                        f"(one value, or one per joint; default {pixels.SPAN:g}), keeping every point in every "
                        f"camera's view")
    p.add_argument("--poses", type=whole(1, MAX_POSES),
                   help=f"poses of the random or barely-moving design (default {POSES})")
    p.add_argument("--step", type=number(0, above=True), default=0.05,
                   help="step (m or rad) of the one-at-a-time design (default %(default)s)")
    p.add_argument("--payload-kg", type=numbers(0),
                   help="comma-separated payloads (kg), at the tool origin (default 0; with --design paper 0,70)")
    p.add_argument("--seed", type=whole(0, MAX_SEED), default=0,
                   help="seed of the poses and the noise (default %(default)s); the truth's random errors come from "
                        "the truth file's own seed, so files drawn with two --seed values are of one robot")
    p.add_argument("--truth-seed", type=whole(0, MAX_SEED),
                   help="draw the truth's random errors with this seed instead of the truth file's: another robot "
                        "of the same error budget")
    p.add_argument("-o", "--output", required=True, help="measurement CSV (with --design paper: the training part)")
    p.add_argument("--val-out", help="validation CSV: with --design paper the validation half of set a; with "
                                      "--design random --val-poses new random poses of the same truth")
    p.add_argument("--val-poses", type=whole(1, MAX_POSES),
                   help="poses of --val-out with --design random (default: --poses)")
    p.add_argument("--truth-out", help="write the resolved truth (every random draw made explicit)")
    p.add_argument("--orientation", action="store_true",
                   help="also write each row's measured orientation (quat_w..quat_z; docs/reference.md, \"Pose "
                        "measurements\"), with the truth file's noise.orientation (rad per axis, default 0)")
    g = p.add_argument_group("without a tracker (docs/reference.md, \"Sockets, distances and planes\"): instead of "
                             "--design, a ball seated in the sockets of plates and a probe touching planes")
    g.add_argument("--plates", type=whole(0, 1000), default=0,
                   help="placements of a plate with two sockets, anywhere in reach (default %(default)s)")
    g.add_argument("--per-socket", type=whole(2, MAX_POSES),
                   help=f"configurations per socket (default {FIXTURE_DEFAULTS['per_socket']})")
    g.add_argument("--socket-distance", type=number(0, 10, above=True),
                   help=f"distance between a plate's sockets, m (default {FIXTURE_DEFAULTS['socket_distance']})")
    g.add_argument("--distance-std", type=number(0, 1),
                   help="stated uncertainty of that distance, m (default 0: exact)")
    g.add_argument("--no-distance", action="store_true",
                   help="the plates' distance is not declared in the data: nothing fixes the scale")
    g.add_argument("--planes", type=whole(0, 3), default=0,
                   help="planes touched: a table, then up to two faces of a square on it (default %(default)s)")
    g.add_argument("--touches", type=whole(4, MAX_POSES),
                   help=f"configurations touching each plane (default {FIXTURE_DEFAULTS['touches']})")
    g.add_argument("--plane-relations", action="store_true",
                   help="declare the planes' perpendicularity (the square's faces and the table) in the data")
    g.add_argument("--block-width", type=number(0, 1, above=True),
                   help="a block of this width (m) on the table: its far face a plane parallel to the first face, "
                        "the offset declared")
    g.add_argument("--target", help="the target that sits in the sockets or touches (default: the robot's first)")
    g.add_argument("--seating-noise", type=number(0, 0.01),
                   help=f"m per coordinate of a ball's seat, and along the normal for a touch (default "
                        f"{FIXTURE_DEFAULTS['seating_noise']:g})")
    g.add_argument("--encoder-noise", type=number(0, 0.01),
                   help=f"rad (m for a prismatic joint) per recorded joint reading (default "
                        f"{FIXTURE_DEFAULTS['encoder_noise']:g})")
    pixels.add_simulate_options(p)


def run(args) -> dict:
    robot = load_robot(args.robot)
    truth_path = Path(args.truth) if args.truth else Path(args.robot).with_name(f"{robot.name}.truth.yaml")
    spec = read_yaml(truth_path, "truth") if (args.truth or truth_path.is_file()) else {}
    if not spec:
        warnings.warn(f"no truth file ({truth_path} does not exist, and no --truth): the simulated robot is the "
                      f"nominal one, without errors or noise; give --truth FILE to simulate a robot as built")
    if args.truth_seed is not None:
        require(spec, f"--truth-seed {args.truth_seed}: there is no truth file to draw ({truth_path} does not exist); "
                      f"give --truth FILE")
        spec = {**spec, "seed": args.truth_seed}
    truth = load_truth(spec or {}, robot, str(truth_path) if spec else "<geometric truth>")
    rng = np.random.default_rng(args.seed)
    camera_options = [f"--{k.replace('_', '-')}" for k in ("board", "noise_px", "eye", "look_at", "distance",
                                                           "rig_out", "images", *pixels.IMAGE_DEFAULTS)
                      if getattr(args, k) not in (None, [])]
    if args.cameras:
        require(not (args.plates or args.planes), "--cameras simulates image points; --plates and --planes sockets "
                                                  "and planes: give one of them")
        return pixels.simulated(args, robot, truth, rng)
    require(not camera_options, f"{camera_options[0] if camera_options else ''} goes with --cameras (image points); "
                                f"drop it, or add --cameras FILE")
    if args.plates or args.planes:
        return _fixtures(args, robot, truth, rng)
    given = [f"--{k.replace('_', '-')}" for k in (*FIXTURE_DEFAULTS, "block_width", "target")
             if getattr(args, k) is not None] + (["--plane-relations"] if args.plane_relations else []) + \
        (["--no-distance"] if args.no_distance else [])
    if given:
        raise ModelError(f"{given[0]} goes with --plates or --planes (sockets and planes); drop it, or add one of them")
    require(args.design == "barely-moving" or (args.joint is None and args.span is None),
            "--joint and --span go with --design barely-moving (--span also with --cameras); drop them, or add it")
    payloads = args.payload_kg or [0.0]
    require(args.val_poses is None or (args.design == "random" and args.val_out),
            "--val-poses sets the poses of --val-out with --design random; give both, or neither")
    ids = None
    if args.commands:
        require(args.design == "random" and args.poses is None and not args.val_out and len(payloads) == 1,
                "--commands gives the poses: no --design, --poses or --val-out, and one --payload-kg")
        design, ids = _commanded(args.commands, robot, payloads[0])
    elif args.design == "paper":
        require("isocenter" in robot.points, f"{args.robot}: the paper design needs points: isocenter")
        design = paper_pps(robot, payloads_kg=args.payload_kg or (0.0, 70.0))
    elif args.design == "tool-grid":
        design = _tool_grid(args, robot)
    elif args.design == "barely-moving":
        require(args.joint is not None and args.joint <= robot.n,
                f"--design barely-moving: give --joint K, the joint that barely moves (1 to {robot.n})")
        require(args.span is None or (len(args.span) == 1 and args.span[0] <= 10),
                "--span: one value with --design barely-moving, the span of that joint (rad or m, at most 10)")
        design = barely_moving(robot, args.poses or POSES, rng, args.joint, SPAN if args.span is None else args.span[0],
                               payloads_kg=payloads)
    elif args.design == "one-at-a-time":
        lo, hi = robot.sampling_box()
        count = len(payloads) * sum(int((b - a) / args.step) + 1 for a, b in zip(lo, hi))
        require(count <= MAX_POSES, f"--step {args.step:g}: the one-at-a-time design would have {count:.3g} poses (at "
                                    f"most {MAX_POSES:,}); give a larger step")
        design = one_at_a_time(robot, {j + 1: args.step for j in range(robot.n)}, payloads)
    else:
        design = random_design(robot, args.poses or POSES, rng, payloads)
    data = simulate(robot, truth, design, rng, args.orientation)
    if ids is not None:
        data = replace(data, pose_ids=ids)
    files = {"data": args.output}
    if args.design == "paper":
        train, val = paper_split(design, rng)
        write_measurements(args.output, robot, data.subset(train))
        if args.val_out:
            write_measurements(args.val_out, robot, data.subset(val))
            files["val"] = args.val_out
    else:
        require(args.design == "random" or not args.val_out,
                f"--val-out with --design {args.design}: validation poses come with --design random or paper")
        write_measurements(args.output, robot, data)
        if args.val_out:
            n_val = args.val_poses or args.poses or POSES
            require(n_val >= 1, f"--val-poses {n_val}: give 1 or more")
            val = simulate(robot, truth, random_design(robot, n_val, rng, payloads), rng, args.orientation)
            write_measurements(args.val_out, robot, val)
            files["val"] = args.val_out
    if args.truth_out:
        write_atomically(args.truth_out, yaml.safe_dump(truth.spec, sort_keys=False))
        files["truth"] = args.truth_out
    nominal = target_positions(robot, data.q)[data.pose, data.target]
    err = np.linalg.norm(data.xyz - nominal, axis=1)
    return {"robot": robot.name, "design": "commands" if args.commands else args.design, "poses": data.n_poses,
            "rows": len(data.xyz),
            "uncompensated": {"rms_mm": float(1e3 * np.sqrt(np.mean(err ** 2))), "max_mm": float(1e3 * err.max())},
            "files": files}


def _commanded(path: str, robot, payload_kg: float) -> tuple[Design, np.ndarray | None]:
    """The design of --commands (every target measured at each row's joints, the payload at the tool
    origin) and its pose ids (P,), the file's pose column when it has one (None: 0, 1, ...)."""
    q = read_commands(path, robot).q
    table = read_table(path, "file of joint commands", "q1..qn")
    ids = pose_id_column(table, "pose") if "pose" in table.header else None
    if ids is not None:
        _, first = np.unique(ids, return_index=True)
        again = np.setdiff1d(np.arange(len(ids)), first)
        require(not len(again), f"{path}: row {again[0] + 2 if len(again) else 0}: pose id {ids[again[0]] if len(again) else 0} "
                                f"repeats an earlier row's; one row per pose")
    n = len(q)
    return Design(q, np.full(n, payload_kg), np.zeros(3), tuple(robot.targets), np.array(["commands"] * n)), ids


def _tool_grid(args, robot):
    """The constant-orientation grid of --design tool-grid (`simulate.designs.constant_orientation`)."""
    lo, hi = robot.sampling_box()
    home = args.home if args.home is not None else [(a + b) / 2 for a, b in zip(lo, hi)]
    require(len(home) == robot.n, f"--home: {len(home)} values for {robot.n} joints; give one per joint (rad or m)")
    require(len(args.grid) == 3 and all(float(k).is_integer() for k in args.grid),
            f"--grid {','.join(f'{k:g}' for k in args.grid)}: give three whole numbers, points along x, y, z")
    try:
        return constant_orientation(robot, home, args.spacing, tuple(int(k) for k in args.grid))
    except ValueError as exc:
        raise ModelError(f"--design tool-grid: {exc} (--spacing, --home)") from None


def _fixtures(args, robot, truth, rng) -> dict:
    """Socket and plane data (`simulate.fixtures`); --val-out gets new placements of the same fixtures."""
    require(args.design == "random" and not args.orientation and args.val_poses is None and args.poses is None
            and args.payload_kg is None,
            "--plates and --planes simulate sockets and planes, not a --design, --poses, --payload-kg, --orientation or "
            "--val-poses")
    value = {k: default if getattr(args, k) is None else getattr(args, k) for k, default in FIXTURE_DEFAULTS.items()}
    fixtures = Fixtures(args.target or next(iter(robot.targets)), args.plates, value["per_socket"],
                        value["socket_distance"], value["distance_std"], args.planes, value["touches"],
                        value["seating_noise"], value["encoder_noise"], args.plane_relations, args.block_width,
                        not args.no_distance)
    with progress_status(not args.json) as status:
        say(status, "placing the fixtures and solving the robot's configurations in them")
        data, floor = simulate_fixtures(robot, truth, fixtures, rng)
        if args.val_out:
            say(status, "placing the validation fixtures and solving the configurations in them")
            val, val_floor = simulate_fixtures(robot, truth, fixtures, rng)
    write_measurements(args.output, robot, data, wrench=False)
    out = {"robot": robot.name, "design": "fixtures", "poses": data.n_poses, "rows": len(data.xyz),
           **data.relative.summary(), "noise_floor": floor, "files": {"data": args.output}}
    if args.val_out:
        write_measurements(args.val_out, robot, val, wrench=False)
        out["files"]["val"] = args.val_out
        out["val_noise_floor"] = val_floor
    if args.truth_out:
        write_atomically(args.truth_out, yaml.safe_dump(truth.spec, sort_keys=False))
        out["files"]["truth"] = args.truth_out
    return out
