"""FANUC TP programs in their ASCII form (.ls): the positions `P[n]` of the /POS section, group 1 (other
groups, extended axes, untouched). A joint position gives J1..J6 (deg, the controller's readings: a
robot file's `couplings` say how they drive the arm); a Cartesian one X Y Z (mm) and W P R (deg,
fixed angles about x, y, z: R = Rz(R) Ry(P) Rx(W)) in its user frame `UF` with its tool `UT`, and
`CONFIG : 'F U T, t1, t4, t6'` (flip, elbow up, front, and the turns of J1, J4, J6). Frame 0 is the
world (the robot's base) and tool 0 the faceplate; others come from a frames file (X Y Z W P R).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from gecgen.deliver.programs.core import Format, Number, Program, Target, euler_numbers, euler_pose, line_of, \
    read_text, refuse, write_same_names
from gecgen.deliver.programs.kinematics import Arm, elbow_up, front

POINT = re.compile(r"^P\[(\d+)(?:\s*:\s*\"[^\"]*\")?\]\s*\{(.*?)\};", re.M | re.S)
GROUP = re.compile(r"GP(\d+)\s*:")
FRAMES = re.compile(r"UF\s*:\s*(\d+)\s*,\s*UT\s*:\s*(\d+)")
CONFIG = re.compile(r"CONFIG\s*:\s*'\s*([NF])\s*([UD])\s*([TB])\s*,\s*(-?\d+)\s*,\s*(-?\d+)\s*,\s*(-?\d+)\s*'")
FIELD = re.compile(r"\b(X|Y|Z|W|P|R|J[1-6])\s*=(\s*[-+]?(?:\d+\.?\d*|\.\d+))\s*(mm|deg)")
#: a motion line; the line number before the colon is optional (editors and compilers write " : J P[1] ...")
MOTION = re.compile(r"^[ \t]*\d*[ \t]*:[ \t]*([JLCA])[ \t]+(P|PR)\[[ \t]*(R\[[ \t]*\w+[ \t]*\]|\w+)", re.M)
IDENTITY = ("0",)


def pose(values) -> np.ndarray:
    """X Y Z (mm) W P R (deg, fixed x-y-z) -> 4x4 in m."""
    return euler_pose(values, "xyz")


def numbers(T: np.ndarray, target: Target) -> list[float]:
    return euler_numbers(T, target.values, "xyz")


def turns(q: np.ndarray) -> np.ndarray:
    """FANUC's turn number of an angle (rad): 0 in (-180, 180] deg, 1 in (180, 540], -1 in (-540, -180]."""
    return np.ceil((np.degrees(q) - 180.0) / 360.0 - 1e-12).astype(int)


def config(arm: Arm):
    """(flip, up, front, t1, t4, t6) as numbers: flip 1 when J5 > 0 ('F'), up 1 when the elbow is at or
    above the stretched arm ('U'), front 1 when the wrist centre is in front of J1 ('T'). The letters
    FANUC gives recorded postures (tests/data/programs/tp/crx10ia), J5 = 0 included."""
    def of(q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(q)
        return np.column_stack([(q[:, 4] > 0).astype(int), elbow_up(arm, q), front(arm, q),
                                turns(q[:, 0]), turns(q[:, 3]), turns(q[:, 5])])
    return of


def _config(match: re.Match) -> tuple:
    flip, up, front_, *t = match.groups()
    return (int(flip == "F"), int(up == "U"), int(front_ == "T"), *map(int, t))


def parse(path: Path) -> Program:
    text = read_text(path)
    if not text.lstrip().startswith("/PROG"):
        refuse(path, 1, "not a TP program in ASCII form (it starts with /PROG)",
               "give the .ls the controller or its editor exports")
    section = text.find("/POS")
    targets = []
    for m in POINT.finditer(text, max(section, 0)):
        name, line = f"P[{m.group(1)}]", line_of(text, m.start())
        groups = list(GROUP.finditer(text, m.start(2), m.end(2)))
        first = next((g for g in groups if g.group(1) == "1"), None)
        if first is None:
            refuse(path, line, f"{name} has no group 1 (GP1)", "give the robot's position in GP1")
        end = next((g.start() for g in groups if g.start() > first.start()), m.end(2))
        block = text[first.end():end]
        at = first.end()
        frames = FRAMES.search(block)
        if frames is None:
            refuse(path, line, f"{name} names no user frame and tool (UF : n, UT : n)", "write them as the controller "
                                                                                       "does")
        fields = {f.group(1): Number(at + f.start(2), at + f.end(2), f.group(2), f.group(3), pad=True)
                  for f in FIELD.finditer(block)}
        joints, cartesian = [f"J{k}" for k in range(1, 7)], ["X", "Y", "Z", "W", "P", "R"]
        if all(k in fields for k in joints):
            targets.append(Target(name, path, line, "joint", tuple(fields[k] for k in joints)))
        elif all(k in fields for k in cartesian):
            config = CONFIG.search(block)
            if config is None:
                refuse(path, line, f"{name} has no CONFIG", "write it as CONFIG : 'N U T, 0, 0, 0'")
            targets.append(Target(name, path, line, "pose", tuple(fields[k] for k in cartesian), _config(config),
                                  frames.group(2), frames.group(1)))
        else:
            missing = [k for k in cartesian if k not in fields] if any(k in fields for k in cartesian) else \
                [k for k in joints if k not in fields]
            refuse(path, line, f"{name} lacks {', '.join(missing)} in GP1", "give all six, each with its unit")
    defined = {t.name for t in targets}
    for m in MOTION.finditer(text, 0, section if section >= 0 else len(text)):
        line = line_of(text, m.start())
        if m.group(3).upper().startswith("R["):  # indirect: the register picks the position while it runs
            targets.append(Target(f"{m.group(2)}[{m.group(3)}] (line {line})", path, line, "motion", (),
                                  note=f"the position is chosen by {m.group(3)} while the program runs: " + (
                                      "correct the position registers on the controller" if m.group(2) == "PR"
                                      else "the /POS positions it may pick are corrected where they are defined")))
        elif m.group(2) == "PR":
            targets.append(Target(f"PR[{m.group(3)}] (line {line})", path, line, "motion", (),
                                  note="a position register: correct it on the controller"))
        elif f"P[{m.group(3)}]" not in defined:
            refuse(path, line, f"motion to P[{m.group(3)}], which the /POS section does not define",
                   "export the program with its positions")
    return Program(path, {path: text}, targets)


FORMAT = Format("tp", (".ls",), parse, pose, numbers, "deg", config, write_same_names, IDENTITY,
                controller="fanuc", label="FANUC TP")
