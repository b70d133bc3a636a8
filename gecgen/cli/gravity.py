"""`gecgen gravity ROBOT TABLE.csv -o OUT.csv [--joints a,b] [--gravity gx,gy,gz] [--json]`.

Appends the static gravity torque of chosen joints (gecgen/model/gravity.py) to any CSV with the
joint columns q1..qn: a measurement file (before identify or diagnose) or a file of joint commands
(before compensate, which needs the same signals as the fit). Every other cell is copied as read.
"""
from __future__ import annotations

import numpy as np

from gecgen.model import load_robot
from gecgen.model.gravity import robot_gravity_torques
from gecgen.model.measurements import write_csv
from gecgen.model.table import read_table
from gecgen.model.validation import ModelError, require


def add_parser(command):
    """Register `gravity` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("gravity", run)
    p.add_argument("robot", help="robot file built from a URDF (its <inertial> masses are used)")
    p.add_argument("table", help="CSV with q1..qn: measurements or joint commands")
    p.add_argument("-o", "--output", required=True, help="the table with tau_<joint> columns appended")
    p.add_argument("--joints", help="comma-separated joint names (default: every joint of the robot)")
    p.add_argument("--gravity", help="gravity in the base link's frame, m/s^2 (default: the robot file's `gravity`, "
                                     "which is 0,0,-9.80665 in its world unless it says otherwise)")


def _gravity(text: str) -> tuple[float, float, float]:
    try:
        g = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ModelError(f"--gravity {text}: expected three numbers gx,gy,gz in m/s^2") from None
    require(len(g) == 3 and all(np.isfinite(g)), f"--gravity {text}: expected three finite numbers gx,gy,gz in m/s^2")
    return g


def run(args) -> dict:
    robot = load_robot(args.robot)
    joints = [j.strip() for j in args.joints.split(",")] if args.joints else list(robot.joint_names)
    # a DH robot file has no masses at all: that, not its couplings, is what it lacks (said below)
    declared = [j.name for j in robot.chain if j.coupling and j.coupling.declared and robot.urdf]
    require(not declared, f"{args.robot}: couplings: gecgen gravity walks the URDF's own joints, not the robot file's "
                          f"couplings of {', '.join(declared)}; use the error terms gravity_torque(J), which follow "
                          f"them")
    mimics = {m.name: m.coupling.terms[0][0] for m in robot.chain if m.coupling and not m.coupling.own}
    for j in joints:
        followed = mimics.get(j)
        require(j not in mimics, f"--joints: '{j}' mimics '{followed}', whose tau_{followed} includes its load times "
                                 f"the multiplier; name '{followed}'")
        require(j in robot.joint_names, f"--joints: '{j}' is not a joint of {robot.name} ({', '.join(robot.joint_names)})")
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    where = str(args.table)
    # every other cell is copied as the file has it: the csv module reads them all
    table = read_table(args.table, "table", ", ".join(qcols), verbatim=True)
    header = table.header
    for col in qcols:
        require(col in header, f"{where}: row 1: missing column '{col}'")
    new = [f"tau_{j}" for j in joints]
    clash = [c for c in new if c in header]
    require(not clash, f"{where}: row 1: column '{clash[0] if clash else ''}' is already there; "
                       f"drop it or write from the table without it")
    q = np.column_stack([table.numbers(c) for c in qcols])
    tau = robot_gravity_torques(robot, q, joints, _gravity(args.gravity) if args.gravity else None)
    write_csv(args.output, header + new,
              (row + [repr(v) for v in t] for row, t in zip(table.rows(), tau.tolist())))
    units = {c: "N" if robot.joints[robot.joint_names.index(j)].kind == "P" else "N m" for c, j in zip(new, joints)}
    return {"robot": robot.name, "output": str(args.output), "rows": len(table), "columns": new,
            "min": {c: float(v) for c, v in zip(new, tau.min(0))}, "max": {c: float(v) for c, v in zip(new, tau.max(0))},
            "unit": units}
