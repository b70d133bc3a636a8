"""ABB RAPID modules (.mod, .modx, .prg): `jointtarget` ([[j1..j6], [external axes]], deg) and
`robtarget` ([[x, y, z] mm, [q1, q2, q3, q4] the orientation quaternion w x y z, [cf1, cf4, cf6, cfx]
the configuration, [external axes]]) declared in the module or written in a move instruction. The
tool and work object of a target: those of the first move instruction using it (`MoveL p10, v100,
fine, tGripper\\WObj:=wobjTable;`), taken from the module's `tooldata` and `wobjdata` or a frames file
(x y z mm and q1..q4); tool0 and wobj0 are the flange and the robot's base.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.deliver.programs.core import Format, Program, Target, line_of, numbers_in, read_text, refuse, \
    write_same_names
from gecgen.deliver.programs.kinematics import Arm, elbow_up, front

DECL = re.compile(r"\b(?:CONST|PERS|VAR)\s+(robtarget|jointtarget|tooldata|wobjdata)\s+(\w+)\s*(\{[^}]*\})?\s*:=\s*",
                  re.I)
MOVE = re.compile(r"\b(MoveJ|MoveL|MoveC|MoveAbsJ|MoveJDO|MoveLDO|MoveJAO|MoveLAO|MoveJGO|MoveLGO|MoveJSync|"
                  r"MoveLSync|MoveCDO|MoveCSync|TriggJ|TriggL|TriggC|EGMMoveL|EGMMoveC|"
                  r"Arc[LC][12]?|Arc[LC]Start|Arc[LC]End)\b([^;]*);", re.I)
#: a target with no value in the module: declared without one, or a routine's parameter (set while it runs)
BARE = re.compile(r"\b(?:(?:CONST|PERS|VAR)\s+(?:robtarget|jointtarget)\s+(\w+)\s*;|(?:robtarget|jointtarget)\s+(\w+)"
                  r"\s*[,)])", re.I)
#: functions whose first argument is a target they offset (the offset target follows its base's correction)
OFFSET = {"offs", "reltool"}
IDENTITY = ("tool0", "wobj0")


def pose(values) -> np.ndarray:
    """x y z (mm) and the quaternion q1..q4 (w x y z) -> 4x4 in m."""
    T = np.eye(4)
    w, x, y, z = values[3:7]
    T[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix()  # scipy orders x y z w
    T[:3, 3] = np.asarray(values[:3], float) / 1000.0
    return T


def numbers(T: np.ndarray, target: Target) -> list[float]:
    """x y z (mm) and q1..q4, the quaternion's sign that of the target's own (q and -q are one turn)."""
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    q = np.array([w, x, y, z])
    if np.dot(q, target.values[3:7]) < 0:
        q = -q
    return [*(1000.0 * T[:3, 3]), *q]


def config(arm: Arm):
    """[cf1, cf4, cf6, cfx] as ABB defines them: the quadrants of axes 1, 4 and 6 (floor(angle / 90 deg)),
    and cfx = 4 (wrist centre behind axis 1) + 2 (behind the lower arm: elbow below the stretched arm)
    + 1 (axis 5 negative)."""
    def of(q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(q)
        quadrant = np.floor(q[:, [0, 3, 5]] / (np.pi / 2) + 1e-12).astype(int)
        cfx = 4 * ~front(arm, q) + 2 * ~elbow_up(arm, q) + (q[:, 4] < 0)
        return np.column_stack([quadrant, cfx])
    return of


def _code(text: str) -> str:
    """text with comments (! to the end of a line, outside strings) and strings blanked, offsets kept."""
    return re.sub(r'"[^"\n]*"|![^\n]*', lambda m: " " * len(m.group()), text)


def _bracket(code: str, at: int) -> int:
    """The end (exclusive) of the bracketed literal that starts at code[at] == '['."""
    depth = 0
    for k in range(at, len(code)):
        depth += {"[": 1, "]": -1}.get(code[k], 0)
        if depth == 0:
            return k + 1
    return len(code)


def _groups(code: str, start: int, end: int) -> list[tuple[int, int]]:
    """The spans of the top-level [...] groups inside the literal code[start:end] (its outer brackets
    included in start..end)."""
    out, depth, begin = [], 0, None
    for k in range(start + 1, end - 1):
        c = code[k]
        if c == "[":
            if depth == 0:
                begin = k
            depth += 1
        elif c == "]":
            depth -= 1
            if depth == 0:
                out.append((begin, k + 1))
    return out


def _split(args: str) -> list[tuple[str, int]]:
    """Top-level comma-separated arguments with their offsets in args."""
    out, depth, begin = [], 0, 0
    for k, c in enumerate(args):
        depth += 1 if c in "([" else -1 if c in ")]" else 0
        if c == "," and depth == 0:
            out.append((args[begin:k], begin))
            begin = k + 1
    out.append((args[begin:], begin))
    return out


def _literal_target(text: str, code: str, path: Path, start: int, kind: str, name: str, tool, wobj) -> Target:
    end = _bracket(code, start)
    groups = _groups(code, start, end)
    line = line_of(text, start)
    if kind == "jointtarget":
        if len(groups) != 2:
            refuse(path, line, f"jointtarget {name} is not [[j1..j6], [external axes]]", "write both groups")
        nums = numbers_in(text, groups[0][0], groups[0][1], "deg")
        return Target(name, path, line, "joint", tuple(nums))
    if len(groups) != 4:
        refuse(path, line, f"robtarget {name} is not [[x, y, z], [q1..q4], [cf1, cf4, cf6, cfx], [external axes]]",
               "write all four groups")
    position = numbers_in(text, groups[0][0], groups[0][1], "mm")
    turn = numbers_in(text, groups[1][0], groups[1][1], "1")
    conf = numbers_in(text, groups[2][0], groups[2][1], "1")
    if len(position) != 3 or len(turn) != 4 or len(conf) != 4:
        refuse(path, line, f"robtarget {name}: a group has the wrong count of numbers", "give x y z, q1..q4 and "
                                                                                        "cf1 cf4 cf6 cfx")
    return Target(name, path, line, "pose", tuple(position + turn), tuple(int(float(n.text)) for n in conf),
                  tool, wobj)


def _frame(text: str, code: str, path: Path, start: int, kind: str, name: str) -> np.ndarray:
    """A tooldata's tframe, or a wobjdata's uframe times oframe (4x4, m); refused when the frame moves
    with something the program does not describe."""
    end = _bracket(code, start)
    line = line_of(text, start)
    top = _split(code[start + 1:end - 1])
    flag = top[0][0].strip().upper()
    if kind == "tooldata":
        if flag != "TRUE":
            refuse(path, line, f"tooldata {name} is a stationary tool (robhold FALSE)",
                   "correct programs of a tool the robot holds")
        (a, b), = [g for g in _groups(code, start, end)][:1]
        pair = _groups(code, a, b)
        values = [n.value for s, e in pair for n in numbers_in(text, s, e, "1")]
        return pose(values)
    if flag != "FALSE" or top[1][0].strip().upper() != "TRUE":
        refuse(path, line, f"wobjdata {name} is held by the robot or moved by a mechanical unit",
               "correct programs whose work object stands still (robhold FALSE, ufprog TRUE)")
    frames = _groups(code, start, end)
    T = np.eye(4)
    for s, e in frames[-2:]:  # uframe, then oframe
        T = T @ pose([n.value for a, b in _groups(code, s, e) for n in numbers_in(text, a, b, "1")])
    return T


def parse(path: Path) -> Program:
    text = read_text(path)
    code = _code(text)
    tools, bases, declared, listed = {}, {}, {}, {}
    for m in DECL.finditer(code):
        kind, name = m.group(1).lower(), m.group(2)
        if code[m.end():m.end() + 1] != "[":
            if kind in ("tooldata", "wobjdata"):  # a frame computed at run time: nobody can say where it is
                refuse(path, line_of(text, m.start()), f"{kind} {name} is not given as a literal",
                       f"write it as [...], or give {name} in a frames file")
            listed[m.end()] = Target(name, path, line_of(text, m.start()), "motion", (),
                                     note="computed from an expression: it follows what it is computed from")
        elif m.group(3):
            listed[m.end()] = Target(f"{name}{m.group(3)}", path, line_of(text, m.start()), "motion", (),
                                     note="an array of targets: not corrected (declare its elements one by one)")
        elif kind == "tooldata":
            tools[name] = _frame(text, code, path, m.end(), kind, name)
        elif kind == "wobjdata":
            bases[name] = _frame(text, code, path, m.end(), kind, name)
        else:
            declared[name] = (kind, m.end())
    bare: dict[str, list[int]] = {}  # name -> the lines declaring it without a value (routines reuse names)
    for m in BARE.finditer(code):
        bare.setdefault(m.group(1) or m.group(2), []).append(line_of(text, m.start()))
    uses, inline = {}, {}
    for m in MOVE.finditer(code):
        args = [(a, m.start(2) + o) for a, o in _split(m.group(2)) if not a.strip().startswith("\\")]
        instruction = m.group(1).lower()
        if instruction.startswith("egm"):
            args = args[1:]  # the EGM identity comes first; the target, speed, zone and tool follow as in MoveL
        circular = instruction.startswith(("movec", "arcc")) or instruction in ("triggc", "egmmovec")
        # trigger and arc-welding instructions put their own data (trigger, seam, weld, weave) before the tool
        tool_arg = args[-1][0] if instruction.startswith(("trigg", "arc")) else \
            args[min(len(args) - 1, 4 if circular else 3)][0]
        tool = re.sub(r"\\.*", "", tool_arg, flags=re.S).strip()
        wobj = re.search(r"\\WObj\s*:=\s*(\w+)", m.group(2), re.I)
        wobj = wobj.group(1) if wobj else "wobj0"
        line = line_of(text, m.start())
        for arg, at in args[:2 if circular else 1]:
            stripped = re.sub(r"\\.*", "", arg, flags=re.S).strip()
            start = at + arg.index(stripped) if stripped else at
            call = re.fullmatch(r"(\w+)\s*\(\s*(\w+)\s*,.*\)", stripped, re.S)
            if stripped.startswith("["):
                kind = "jointtarget" if instruction == "moveabsj" else "robtarget"
                inline[start] = _literal_target(text, code, path, start, kind, f"{m.group(1)} line {line}", tool,
                                                wobj)
            elif stripped in declared:
                uses.setdefault(stripped, (tool, wobj))
            elif call and call.group(1).lower() in OFFSET and call.group(2) in declared:
                uses.setdefault(call.group(2), (tool, wobj))
            elif any(k <= line for k in bare.get(stripped, ())):
                declared_at = max(k for k in bare[stripped] if k <= line)
                inline[start] = Target(f"{stripped} (line {line})", path, line, "motion", (),
                                       note=f"declared without a value (line {declared_at}): set while the module "
                                            f"runs, not corrected")
            elif re.fullmatch(r"\w+\{.*\}", stripped, re.S):
                continue  # an element of an array: the array is listed where it is declared
            else:
                inline[start] = Target(f"{stripped[:30]} (line {line})", path, line, "motion", (),
                                       note="a target computed or declared elsewhere: not this module's to correct")
    targets = inline | listed
    for name, (kind, start) in declared.items():
        tool, wobj = uses.get(name, (None, None))
        if kind == "robtarget" and name not in uses:
            targets[start] = Target(name, path, line_of(text, start), "pose", (), note="used by no move instruction "
                                    "of the module: its tool and work object are unknown")
            continue
        targets[start] = _literal_target(text, code, path, start, kind, name, tool, wobj)
    return Program(path, {path: text}, [targets[k] for k in sorted(targets)], tools, bases)


FORMAT = Format("rapid", (".mod", ".modx", ".prg"), parse, pose, numbers, "deg", config, write_same_names, IDENTITY,
                controller="abb", label="ABB RAPID")
