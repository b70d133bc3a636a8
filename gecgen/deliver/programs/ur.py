"""Universal Robots script (.script, .urscript): `movej`, `movel`, `movep`, `movec` (its via pose
and its target), `optimovej` and `optimovel` to a joint list `[q1, ..., q6]` (rad) or a pose
`p[x, y, z, rx, ry, rz]` (m, rotation vector in rad) in the robot's base frame, written in the call
(also through `get_inverse_kin(pose, ...)`) or assigned to a variable the call names. The TCP is the
last `set_tcp(p[...])` before the target, else the installation's (`tools: installation` of a frames file).
The controller has no configuration flags: a pose is reached nearest the joints of the target before.
A move to anything else (a variable set again, element by element or at run time; a function's
parameter; an expression) is listed and kept as written, and the pose after it has no target before
it to be solved near.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.deliver.programs.core import Format, Program, Target, line_of, numbers_in, read_text, refuse, \
    write_same_names

MOVE = re.compile(r"\b(movej|movel|movep|movec|optimovej|optimovel)\s*\(")
#: a literal joint list or pose: p[ six numbers ] or [ six numbers ]
LITERAL = re.compile(r"(p?)\[\s*([^\[\]]*)\]")
ASSIGN = re.compile(r"^[ \t]*(?:global[ \t]+|local[ \t]+)?([A-Za-z_]\w*)[ \t]*=[ \t]*(p?)\[([^\[\]\n]*)\]", re.M)
SET_TCP = re.compile(r"\bset_tcp\s*\(\s*p\[([^\[\]]*)\]\s*\)")
SIX = re.compile(r"^\s*[-+.\d][-+.\deE]*(\s*,\s*[-+.\d][-+.\deE]*){5}\s*$")
NAME = re.compile(r"[A-Za-z_]\w*")
#: any assignment to a name or to one of its elements (`q = ...`, `q[0] = ...`), not a comparison
ANY_ASSIGN = re.compile(r"^[ \t]*(?:\$[\d.]+[ \t]+)?(?:global[ \t]+|local[ \t]+)?([A-Za-z_]\w*)[ \t]*(?:\[[^\]\n]*\])?"
                        r"[ \t]*=(?!=)", re.M)
#: a function's or thread's parameters: names bound at each call, never a fixed target
PARAMETERS = re.compile(r"\b(?:def|thread)[ \t]+\w+[ \t]*\(([^)]*)\)")
#: the calls a target expression may pass through on its way to a move (UR's own inverse kinematics)
PASS = {"get_inverse_kin"}


def pose(values) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(values[3:6]).as_matrix()
    T[:3, 3] = values[:3]
    return T


def numbers(T: np.ndarray, target: Target) -> list[float]:
    """x y z (m) and the rotation vector (rad), turned to the same side as the target's own (a rotation
    vector of angle a and one of 2 pi - a about the opposite axis are the same turn)."""
    v = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    old = np.array(target.values[3:6])
    angle = np.linalg.norm(v)
    if angle > 1e-9 and np.dot(v, old) < 0:
        v = -v / angle * (2 * np.pi - angle)
    return [*T[:3, 3], *v]


def _argument_end(text: str, at: int) -> int:
    """The end of the call's first argument starting at `at` (a comma or the closing parenthesis at depth 0)."""
    depth = 0
    for k in range(at, len(text)):
        c = text[k]
        if c in "([":
            depth += 1
        elif c in ")]":
            if depth == 0:
                return k
            depth -= 1
        elif c == "," and depth == 0:
            return k
    return len(text)


def _code(text: str) -> str:
    """text with comments (from # to the end of a line) and strings blanked, offsets kept."""
    return re.sub(r'#[^\n]*|"[^"\n]*"', lambda m: " " * len(m.group()), text)


def parse(path: Path) -> Program:
    text = read_text(path)
    code = _code(text)
    tcps = [(m.start(), f"set_tcp line {line_of(text, m.start())}", pose([float(v) for v in m.group(1).split(",")]))
            for m in SET_TCP.finditer(code) if SIX.match(m.group(1))]

    def tool_at(at: int) -> str:
        before = [name for start, name, _ in tcps if start < at]
        return before[-1] if before else "installation"

    # a variable is a target only when the program gives it one literal value and never sets it again
    # (a driver's `q = [0, 0, 0, 0, 0, 0]` later filled from registers is not one), and no function
    # takes a parameter of that name
    times = {}
    for m in ANY_ASSIGN.finditer(code):
        times[m.group(1)] = times.get(m.group(1), 0) + 1
    parameters = {n for m in PARAMETERS.finditer(code) for n in NAME.findall(m.group(1))}
    assigned = {m.group(1): m for m in ASSIGN.finditer(code)
                if SIX.match(m.group(3)) and times.get(m.group(1)) == 1 and m.group(1) not in parameters}
    found: dict[int, Target] = {}
    used: dict[str, int] = {}
    for m in MOVE.finditer(code):
        start = m.end()
        # movec passes through a via pose to its target: both are targets
        for _ in range(2 if m.group(1) == "movec" else 1):
            end = _argument_end(code, start)
            arg = code[start:end].strip()
            called = re.fullmatch(r"(\w+)\s*\(.*\)", arg, re.S)
            first = start + code[start:end].index("(") + 1 if called and called.group(1) in PASS else start
            inner_end = _argument_end(code, first)
            inner = code[first:inner_end].strip()
            literal = LITERAL.fullmatch(inner)
            if literal and SIX.match(literal.group(2)):
                at = first + code[first:inner_end].index(inner)
                found[at] = _target(text, path, at, LITERAL.match(code, at), f"{m.group(1)} line {line_of(text, at)}",
                                    tool_at(at))
            elif NAME.fullmatch(inner) and inner in assigned:
                used.setdefault(inner, start)
            else:
                line = line_of(text, start)
                name = f"{m.group(1)} to {arg.splitlines()[0][:30].rstrip()} (line {line})"
                found[start] = Target(name, path, line, "motion", (), note="a target computed at run time (not a "
                                      "joint list or pose p[...] written in the program): not corrected")
            start = end + 1
    for a in ASSIGN.finditer(code):
        if a.group(1) in used and SIX.match(a.group(3)):
            # the controller moves with the TCP set when the move runs, not when the variable was assigned
            found[a.start(2)] = _target(text, path, a.start(2), LITERAL.match(code, a.start(2)), a.group(1),
                                        tool_at(used[a.group(1)]))
    tools = {name: T for _, name, T in tcps}
    return Program(path, {path: text}, [found[k] for k in sorted(found)], tools=tools)


def _target(text: str, path: Path, at: int, literal: re.Match, name: str, tool: str) -> Target:
    is_pose = literal.group(1) == "p"
    units = ["m"] * 3 + ["rad"] * 3 if is_pose else "rad"
    numbers_found = numbers_in(text, literal.start(2), literal.end(2), units)
    return Target(name, path, line_of(text, at), "pose" if is_pose else "joint", tuple(numbers_found),
                  tool=tool if is_pose else None)


FORMAT = Format("ur", (".script", ".urscript"), parse, pose, numbers, "rad", None, write_same_names,
                controller="ur", label="UR script")
