"""`gecgen import`: a wide table (several points per row) into the contract's measurement CSV."""
from __future__ import annotations

import numpy as np

from gecgen.model import load_robot
from gecgen.model.measurements import write_measurements
from gecgen.model.validation import require
from gecgen.model.wide import import_wide, load_mapping


def add_parser(command):
    p = command("import", run, "convert a wide table (points side by side) into a measurement CSV")
    p.add_argument("robot")
    p.add_argument("table", help="CSV with one row per pose")
    p.add_argument("--mapping", required=True, help="column mapping YAML (see gecgen/model/wide.py)")
    p.add_argument("--targets", help="comma-separated targets to keep (default: every mapped target)")
    p.add_argument("-o", "--output", required=True)


def run(args) -> dict:
    robot = load_robot(args.robot)
    data = import_wide(args.table, robot, load_mapping(args.mapping, robot))
    if args.targets:
        names = list(robot.targets)
        keep = [t.strip() for t in args.targets.split(",")]
        for t in keep:
            require(t in names, f"--targets: '{t}' is not a target of {robot.name} ({', '.join(names)})")
        rows = np.isin(data.target, [names.index(t) for t in keep])
        data = type(data)(data.q, data.w, data.aux, data.aux_names, data.pose_ids, data.pose[rows], data.target[rows],
                          data.xyz[rows], data.source)
    write_measurements(args.output, robot, data, wrench=bool(np.any(data.w)))
    lo = np.array([j.lower for j in robot.joints])
    hi = np.array([j.upper for j in robot.joints])
    outside = [{"row": int(r) + 2, "joint": robot.joint_names[j], "value": float(data.q[r, j])}
               for r, j in np.argwhere((data.q < lo) | (data.q > hi))]
    return {"robot": robot.name, "output": args.output, "poses": data.n_poses, "rows": len(data.xyz),
            "outside_limits": outside}
