"""The load signals of `gecgen.model.loads` as straight-line code on the nominal chain.

One forward pass of the nominal chain gives every joint's world axis and every frame's pose; each
signal is then a few dot and cross products:

    wrench_torque(J) = a_J . (m + (p_s - o_J) x f)   (revolute)   a_J . f   (prismatic)

with f, m the wrench rotated from the sensor frame into the world and p_s the sensor frame's
origin; gravity(J, r) is a kept column of `model.loads.joint_columns`, and gravity_torque(J)
the sum of all of joint J's columns times the masses and first moments of the frames it carries.
A frame's wrench (`gravity(F, c, r)`, `gravity_load(F, c)`, `wrench_load(F, c)`) is the same sums
turned into frame F's axes (`model.loads.frame_wrench_columns`, `frame_wrench_load`).
A joint with mimic joints sums over the frames it moves, each times its multiplier.
"""
from __future__ import annotations

import sympy as sp

from gecgen.model.loads import (catalog, frame_wrench_columns, frame_wrench_load, frame_wrench_torque, joint_columns)
from gecgen.model.robot import WRENCH, Robot
from gecgen.symbolic.chain import apply, build_chain
from gecgen.symbolic.exact import sympy_robot
from gecgen.symbolic.parse import joint_symbols, load_symbol
from gecgen.symbolic.program import Builder, Function


def load_values(b: Builder, robot: Robot, q, w, names) -> dict[sp.Symbol, sp.Expr]:
    """load symbol -> its value (an expression in q and w built with b) for the signals `names`
    (canonical spellings the robot supports). Builds nothing when names is empty."""
    robot = sympy_robot(robot)
    if not names:
        return {}
    cat = catalog(robot)
    chain = build_chain(b, robot, q, None)
    axes = [apply(b, F, joint.axis, point=False) for joint, F in zip(robot.chain, chain.joint_frames)]
    origins = [F.p for F in chain.joint_frames]
    carried = [(P.R, P.p) for P in chain.post]
    columns: dict[int, list] = {}
    wrench_columns: dict[int, list] = {}

    def columns_of(J: int) -> list:
        if J not in columns:
            columns[J] = joint_columns(b.let, robot, J, axes, origins, carried, robot.gravity)
        return columns[J]

    def frame_columns_of(f: int) -> list[list]:
        if f not in wrench_columns:
            wrench_columns[f] = frame_wrench_columns(b.let, *carried[f], [carried[k] for k in robot.subtree(f)],
                                                     robot.gravity)
        return wrench_columns[f]

    moving = set(robot.path(robot.sensor_frame()))  # the frames that move the sensor
    sensor = chain.tool if robot.wrench_frame == "tool" else chain.post[robot.wrench_frame]
    force, moment = apply(b, sensor, w[:3], point=False), apply(b, sensor, w[3:], point=False)
    out = {}
    for name in names:
        s = cat.by_name(name)
        if s.kind == "frame_gravity":
            value = frame_columns_of(s.frame)[s.component][s.column]
        elif s.kind == "gravity_load":
            params = [v for k in robot.subtree(s.frame) for v in cat.params[k]]
            value = sum(p * c for p, c in zip(params, frame_columns_of(s.frame)[s.component]) if p)
        elif s.kind == "wrench_load":
            value = frame_wrench_load(b.let, *carried[s.frame], sensor.p, force, moment)[s.component]
        elif s.kind == "wrench_torque":  # frames after the sensor's (or on other branches) do not move it
            value = sum(mult * frame_wrench_torque(b.let, robot.chain[k - 1].kind, axes[k - 1], origins[k - 1],
                                                   sensor.p, force, moment)
                        for k, mult in robot.driven(s.joint - 1) if k in moving)
        elif s.kind == "gravity":
            value = columns_of(s.joint)[s.column]
        else:
            params = [v for row in cat.params[robot.driven(s.joint - 1)[0][0]:] for v in row]
            value = sum(p * c for p, c in zip(params, columns_of(s.joint)) if p)
        out[load_symbol(name)] = b.let(value)
    return out


def loads_function(robot: Robot, names: list[str]) -> Function:
    """The load signals `names` (canonical spellings, those an error model uses), L (NL), at joints q
    and wrench w: only these, since a long chain supports thousands (their number grows with the
    square of the joints)."""
    b, q = Builder(), joint_symbols(robot)
    w = tuple(sp.Symbol(n, real=True) for n in WRENCH)
    values = load_values(b, robot, q, w, names)
    return b.function("loads", f"Load signals L ({robot.name.upper()}_NL, listed above) at joints q and wrench w "
                      "(fx fy fz mx my mz): N m, N along a prismatic joint; gravity columns N m per kg and per kg m.",
                      {"q": q, "w": w}, {"L": [values[load_symbol(n)] for n in names]})
