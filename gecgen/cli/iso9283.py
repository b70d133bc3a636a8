"""`gecgen iso9283 ROBOT -o PLAN.csv [--tool-rpy R,P,Y (deg)] [--cycles 30]`: plans the ISO 9283 pose test;
`gecgen iso9283 ROBOT --plan PLAN.csv --measured DATA.csv [--after DATA2.csv] [--calibration CALIB.json]`: its
characteristics, before and after compensation.

The plan (gecgen/plan/iso9283.py) is the standard's test cube, its five points and the cycles, as
joint commands in visiting order (`cycle, point, q1..qn`, plus `pose`, the row's pose id). Run it on
the robot as it is (the "before" test), or its compensated commands (`gecgen compensate CALIB
PLAN.csv`, the "after" test, `--after`), and measure a target at every row: a measurement file whose
pose ids are the plan's. The commanded pose of a row is where the nominal model puts the target at the plan's
joints, in both tests: what the robot was asked to reach. The measured positions must be in the
robot's world frame, or in the tracker frame of `--calibration` (its registration brings them there).
"""
from __future__ import annotations

import numpy as np

from gecgen.cli.common import MAX_SEED, add_tolerance, progress_status, say, warned, whole
from gecgen.cli.human import warning_lines

#: rad or m: a measured run's readings may differ from the plan's by this much (the compensated
#: commands of the "after" run differ by the corrections, a few mrad); beyond it, it ran another plan
JOINT_MATCH = 0.05


def add_parser(command):
    """Register `iso9283` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("iso9283", run)
    p.add_argument("robot", help="robot file")
    p.add_argument("-o", "--output", help="write the plan here (joint commands in visiting order)")
    p.add_argument("--tool-rpy", default="0,0,0",
                   help="the tool's orientation in the test, roll,pitch,yaw about the world's x,y,z in degrees "
                        "(default %(default)s)")
    p.add_argument("--cycles", type=whole(2, 1000), default=30, help="cycles per point (default %(default)s, the "
                                                                     "standard's)")
    p.add_argument("--seed", type=whole(0, MAX_SEED), default=0, help="seed of the cube search (default %(default)s)")
    p.add_argument("--plan", help="the plan the measured test ran (with --measured)")
    p.add_argument("--measured", help="measurements of the test, pose ids those of the plan's rows")
    p.add_argument("--after", help="measurements of the same test run with the compensated commands (gecgen "
                                   "compensate of the plan): scored against the same commanded poses")
    p.add_argument("--calibration", help="a calibration whose tracker frame the measurements are in")
    p.add_argument("--report", metavar="DIR", help="with --measured: folder for report.md and report.html (the "
                                                   "characteristics per point, before and after)")
    add_tolerance(p)


def run(args) -> dict:
    from gecgen.model import load_robot
    from gecgen.model.validation import require
    from gecgen.report.verdict import iso9283_next_step

    robot = load_robot(args.robot)
    require((args.plan is None) == (args.measured is None), "--plan and --measured go together: the plan the "
                                                             "measured test ran")
    require(args.after is None or args.measured, "--after goes with --plan and --measured (the run before)")
    require(args.calibration is None or args.measured, "--calibration goes with --plan and --measured: the "
                                                       "calibration whose tracker frame the measurements are in")
    require(args.report is None or args.measured, "--report goes with --plan and --measured: it reports a "
                                                  "measured test")
    require(args.tolerance_mm is None or args.measured, "--tolerance-mm goes with --plan and --measured: it judges "
                                                        "a measured test")
    if args.measured:
        require(not args.output, "-o writes a plan; with --measured the characteristics are the result (--json)")
        with warned() as caught, progress_status(not args.json) as status:
            say(status, f"scoring the test measured in {args.measured} against the plan's commanded poses")
            result = _characteristics(robot, args)
            assessment = iso9283_next_step(result, args.tolerance_mm, args.robot)
            result["assessment"], result["warnings"] = assessment.to_dict(), warning_lines(caught)
            if args.report:
                from gecgen import report

                result.update(report.write(report.content.iso9283(result, assessment, result["warnings"]),
                                           args.report))
        return result
    require(args.output, "-o: give the file to write the plan to (or --plan and --measured to evaluate a test)")
    return _plan(robot, args)


def _plan(robot, args) -> dict:
    from scipy.spatial.transform import Rotation

    from gecgen.model.measurements import write_csv
    from gecgen.model.validation import ModelError
    from gecgen.plan.iso9283 import command_table, plan_cube

    try:
        rpy = [float(v) for v in args.tool_rpy.split(",")]
    except ValueError:
        rpy = []
    if len(rpy) != 3 or not np.all(np.isfinite(rpy)):
        raise ModelError(f"--tool-rpy {args.tool_rpy}: give three angles roll,pitch,yaw")
    tool = Rotation.from_euler("xyz", rpy, degrees=True).as_matrix()
    with progress_status(not args.json) as status:
        say(status, "searching for the largest cube the tool origin reaches at its corners in one orientation")
        plan = plan_cube(robot, tool, cycles=args.cycles, rng=np.random.default_rng(args.seed))
    header, rows = command_table(plan)
    write_csv(args.output, ["pose", *header],
              ([k, int(r[0]), int(r[1]), *map(repr, r[2:].tolist())] for k, r in enumerate(rows)))
    return {"robot": robot.name, "output": str(args.output), "side_mm": 1e3 * plan.side_m,
            "centre": plan.centre.tolist(), "plane": plan.plane, "points": plan.points.tolist(),
            "cycles": plan.cycles, "rows": len(rows)}


def _characteristics(robot, args) -> dict:
    from gecgen.model.measurements import pose_id_column
    from gecgen.model.table import at, read_table
    from gecgen.model.validation import ModelError, require
    from gecgen.plan.iso9283 import ORDER

    table = read_table(args.plan, "ISO 9283 plan", "pose, cycle, point, q1..qn")
    for col in ("pose", "cycle", "point", *(f"q{j + 1}" for j in range(robot.n))):
        require(col in table.header, f"{table.where}: row 1: missing column '{col}'; give the plan "
                                     f"`gecgen iso9283 -o` wrote")
    fix = "give the plan `gecgen iso9283 -o` wrote"
    pose = pose_id_column(table, "pose", fix=fix)
    cycle = pose_id_column(table, "cycle", "cycle number", fix)
    point = pose_id_column(table, "point", "point number", fix)
    for col, values, highest in (("cycle", cycle, np.inf), ("point", point, len(ORDER))):
        bad = np.flatnonzero((values < 1) | (values > highest))
        if len(bad):
            raise ModelError(f"{at(table.where, bad[0] + 2, col)}: {values[bad[0]]} is not a {col} of the test "
                             f"(1..{highest if col == 'point' else 'the cycles'}); {fix}")
    twice = np.flatnonzero(np.diff(np.sort(pose)) == 0)
    require(not len(twice), f"{table.where}: pose {np.sort(pose)[twice[0]] if len(twice) else ''} is on two rows; {fix}")
    q = np.column_stack([table.numbers(f"q{j + 1}") for j in range(robot.n)])
    out = {"robot": robot.name, "plan": str(args.plan), "measured": str(args.measured),
           "frame": "the calibration's tracker frame" if args.calibration else "the robot's world frame",
           **_run_characteristics(robot, args.calibration, args.measured, table.where, pose, point, cycle, q)}
    if args.after:
        out["after"] = {"measured": str(args.after),
                        **_run_characteristics(robot, args.calibration, args.after, table.where, pose, point, cycle,
                                               q)}
    return out


def _run_characteristics(robot, calibration: str | None, measured, plan_where: str, pose, point, cycle, q) -> dict:
    """{points: {target: {P1: characteristics, ...}}, distance: {target: P2-P4 characteristics},
    worst: {AP_p, RP_l}} of one measured run of the plan (its rows: pose ids, points, cycles, joints
    q), against the nominal poses at the plan's joints; the measured points in `calibration`'s tracker
    frame when given, else in the robot's world frame. The distance is the standard's P2 to P4, over
    the cycles that measured the target at both."""
    from gecgen.model.kinematics import target_positions, tool_poses
    from gecgen.model.measurements import read_measurements
    from gecgen.model.validation import ModelError, require
    from gecgen.verify.iso9283 import distance_characteristics, pose_characteristics

    data = read_measurements(measured, robot)
    require(data.relative is None, f"{data.source}: the ISO 9283 test compares measured positions; give x y z on "
                                   f"every row (no point or plane rows)")
    unknown = np.setdiff1d(data.pose_ids, pose)
    require(not len(unknown), f"{data.source}: pose {unknown[0] if len(unknown) else ''} is no row of the plan "
                              f"{plan_where}; the test's pose ids are the plan's")
    names = np.array(robot.target_names)
    for t in np.unique(data.target):  # the standard's figures need every cycle of every point
        missing = np.setdiff1d(pose, data.pose_ids[data.pose[data.target == t]])
        require(not len(missing), f"{data.source}: target {names[t]} is measured at {len(pose) - len(missing)} of the "
                                  f"plan's {len(pose)} rows (pose {missing[0] if len(missing) else ''} is missing); "
                                  f"the test needs every cycle of every point: measure the whole plan, or plan fewer "
                                  f"cycles (--cycles)")
    plan_row = {int(p): k for k, p in enumerate(pose)}
    apart = np.abs(data.q - q[[plan_row[int(p)] for p in data.pose_ids]])
    if apart.max(initial=0.0) > JOINT_MATCH:
        k, j = np.unravel_index(int(np.argmax(apart)), apart.shape)
        raise ModelError(f"{data.source}: pose {data.pose_ids[k]}: q{j + 1} is {data.q[k, j]:.6g} but the plan "
                         f"{plan_where} has {q[plan_row[int(data.pose_ids[k])], j]:.6g} ({apart[k, j]:.3g} apart, more "
                         f"than {JOINT_MATCH:g} rad or m): not a run of this plan; give the plan the test ran")
    y = data.xyz
    if calibration:
        from gecgen.api import load_calibration
        from gecgen.fit.identify import to_world

        y = to_world(load_calibration(calibration).calibration_.frames, data)
    row = np.array([plan_row[int(p)] for p in data.pose_ids])[data.pose]  # the plan row of every measured point
    commanded = target_positions(robot, q)[row, data.target]
    R_cmd = tool_poses(robot, q)[0][row, :3, :3]
    out = {}
    for name in sorted(set(robot.target_names[t] for t in data.target)):
        for p in sorted(set(point[row].tolist())):
            at = (point[row] == p) & (np.array(robot.target_names)[data.target] == name)
            require(at.sum() >= 2, f"{data.source}: target {name} is measured {int(at.sum())} time(s) at P{p}; the "
                                   f"test needs it at every cycle of every point")
            R = None if data.orientation is None or np.isnan(data.orientation[at][:, 0, 0]).any() else \
                data.orientation[at]
            c = pose_characteristics((commanded[at][0], R_cmd[at][0] if R is not None else None), (y[at], R))
            out.setdefault(name, {})[f"P{p}"] = {k: (None if np.isnan(v) else float(v)) if isinstance(v, float) else v
                                                 for k, v in vars(c).items()}
    distance = {}
    for name in out:
        ends = []
        for p in (2, 4):
            at = (point[row] == p) & (np.array(robot.target_names)[data.target] == name)
            ends.append(({int(k): i for k, i in zip(cycle[row][at], np.flatnonzero(at))}, commanded[at]))
        both = sorted(set(ends[0][0]) & set(ends[1][0]))
        if len(both) >= 2:
            d = distance_characteristics(ends[0][1][0], ends[1][1][0], y[[ends[0][0][k] for k in both]],
                                         y[[ends[1][0][k] for k in both]])
            distance[name] = {"between": "P2-P4", **vars(d)}
    worst = {k: max(v[k] for t in out.values() for v in t.values()) for k in ("AP_p", "RP_l")}
    return {"points": out, "distance": distance, "worst": worst}
