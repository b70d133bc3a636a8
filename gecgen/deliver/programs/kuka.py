"""KUKA KRL: a program `NAME.src` and its points in `NAME.dat`.

Targets: `DECL E6AXIS|AXIS NAME={A1 ..,A6 ..}` (deg; external axes E1..E6 untouched) and
`DECL E6POS|POS NAME={X ..,Y ..,Z ..,A ..,B ..,C ..,S ..,T ..}` (mm; A B C the Z-Y-X Euler angles in
deg; S and T the configuration) in either file, and aggregates written in a motion
(`PTP {A1 0,...}`, `LIN {X ...}`). The tool and base of a point: its FDAT (`FNAME` for `XNAME`:
TOOL_NO, BASE_NO), else the last `$TOOL=` / `$BASE=` or `BAS(#TOOL, n)` / `BAS(#BASE, n)` before the
motion; tool and base 0 and $NULLFRAME are the flange and the robot's base; a FRAME the .dat
declares is taken from there, any other from a frames file.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from gecgen.deliver.programs.core import Format, Program, Target, euler_numbers, euler_pose, line_of, numbers_in, \
    read_text, refuse
from gecgen.deliver.programs.kinematics import Arm, elbow_up, front
from gecgen.model.files import write_atomically

MOTION = re.compile(r"^[ \t]*(PTP|LIN|CIRC|SPTP|SLIN|SCIRC|PTP_REL|LIN_REL|SPTP_REL|SLIN_REL)\b([^;\n]*)",
                    re.M | re.I)
DECL = re.compile(r"^[ \t]*(?:DECL[ \t]+)?(?:GLOBAL[ \t]+)?(E6POS|POS|E6AXIS|AXIS|FRAME|FDAT)[ \t]+(\w+)[ \t]*=[ \t]*"
                  r"\{([^}\n]*)\}", re.M | re.I)
#: a point declared without a value (`DECL AXIS a, b`): set while the program runs
BARE = re.compile(r"^[ \t]*(?:DECL[ \t]+)?(?:GLOBAL[ \t]+)?(?:E6POS|POS|E6AXIS|AXIS)[ \t]+"
                  r"(\w+(?:[ \t]*,[ \t]*\w+)*)[ \t]*$", re.M | re.I)
AGGREGATE = re.compile(r"\{([^}\n]*)\}")
FIELD = re.compile(r"(\w+)[ \t]+('[^']*'|\"[^\"]*\"|#\w+|[-+.\deE]+)")
TOOL_SET = re.compile(r"^[ \t]*\$(TOOL|BASE)[ \t]*=[ \t]*(?:(?:TOOL|BASE)_DATA\[(\d+)\]|(\$?\w+))", re.M | re.I)
FRAME_SET = re.compile(r"^[ \t]*\$(TOOL|BASE)[ \t]*=[ \t]*\{([^}\n]*)\}", re.M | re.I)
BAS_SET = re.compile(r"^[ \t]*BAS[ \t]*\([ \t]*#(TOOL|BASE)[ \t]*,[ \t]*(\d+)", re.M | re.I)
FDAT_ACT = re.compile(r"^[ \t]*FDAT_ACT[ \t]*=[ \t]*(\w+)", re.M | re.I)
#: a statement that sets a variable or one of its components (`NEXT = $AXIS_ACT_MEAS`, `XP1.X = 100`)
ASSIGN = re.compile(r"^[ \t]*(\w+)(?:\.\w+|\[[^\]\n]*\])*[ \t]*=(?!=)", re.M)
POSE_KEYS, JOINT_KEYS = ("X", "Y", "Z", "A", "B", "C"), ("A1", "A2", "A3", "A4", "A5", "A6")
IDENTITY = ("0", "$NULLFRAME", "NULLFRAME")


def pose(values) -> np.ndarray:
    """X Y Z (mm) A B C (deg, Z-Y-X Euler: Rz(A) Ry(B) Rx(C)) -> 4x4 in m."""
    return euler_pose(values, "ZYX")


def numbers(T: np.ndarray, target: Target) -> list[float]:
    return euler_numbers(T, target.values, "ZYX")


def config(arm: Arm):
    """S and T as KUKA defines them: S bit 0 the wrist centre behind axis 1 (the overhead area), bit 1
    axis 3 at or above the stretched arm, bit 2 A5 negative (a flipped hand); T bit k axis k+1
    negative. Bit 2 is 1 exactly when T's bit 4 is: so every point KUKA controllers wrote into the
    public .dat files checked shows it (S 6 with T 50, S 2 with T 3 or 34; docs/program-filters.md)."""
    def of(q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(q)
        s = (~front(arm, q)).astype(int) + 2 * elbow_up(arm, q) + 4 * (q[:, 4] < 0)
        t = np.sum((q < 0) * (2 ** np.arange(6)), axis=1)
        return np.column_stack([s, t])
    return of


def _fields(text: str, start: int, end: int) -> dict[str, tuple[str, int, int]]:
    """The fields of an aggregate between start and end: KEY -> (value text, start, end)."""
    return {m.group(1).upper(): (m.group(2), start + m.start(2), start + m.end(2))
            for m in FIELD.finditer(text[start:end])}


def _integer(value: str) -> int:
    """S or T: 6, 'B110' or 'H6'."""
    v = value.strip("'\"")
    if v[:1].upper() == "B":
        return int(v[1:], 2)
    if v[:1].upper() == "H":
        return int(v[1:], 16)
    return int(float(v))


def _frame(values: dict, path: Path, line: int) -> np.ndarray:
    try:
        return pose([float(values[k][0]) for k in POSE_KEYS])
    except (KeyError, ValueError):
        refuse(path, line, "a FRAME without all of X Y Z A B C", "write all six")


def _target(text: str, path: Path, kind: str, name: str, start: int, end: int, tool, base) -> Target:
    line = line_of(text, start)
    f = _fields(text, start, end)
    keys = JOINT_KEYS if kind in ("E6AXIS", "AXIS") else POSE_KEYS
    missing = [k for k in keys if k not in f]
    if missing:
        refuse(path, line, f"{kind} {name} lacks {', '.join(missing)}", "give every component of the target")
    try:
        found = [numbers_in(text, f[k][1], f[k][2], "deg" if k in JOINT_KEYS or k in "ABC" else "mm")
                 for k in keys]
    except ValueError:
        found = []
    if any(len(n) != 1 for n in found) or not found:
        refuse(path, line, f"{kind} {name}: a component is not a number", "write plain numbers")
    nums = tuple(n[0] for n in found)
    if kind in ("E6AXIS", "AXIS"):
        return Target(name, path, line, "joint", nums)
    cfg = (_integer(f["S"][0]), _integer(f["T"][0])) if "S" in f and "T" in f else None
    return Target(name, path, line, "pose", nums, cfg, tool, base)


def parse(path: Path) -> Program:
    if path.suffix.lower() != ".src":
        refuse(path, None, "a KRL program is a .src file with its .dat beside it", "give the .src")
    src = read_text(path)
    dat_path = next((p for p in (path.with_suffix(".dat"), path.with_suffix(".DAT")) if p.is_file()), None)
    dat = read_text(dat_path) if dat_path else None
    texts = {path: src} | ({dat_path: dat} if dat_path else {})
    code = {p: re.sub(r";[^\n]*", lambda m: " " * len(m.group()), t) for p, t in texts.items()}
    decls = {}  # NAME -> (file, kind, start, end of the aggregate's inside)
    tools, bases, fdat, bare = {}, {}, {}, {}  # bare: NAME -> (file, line) of a declaration without a value
    frames = {}  # NAME -> (file, line) of a FRAME the program declares
    for p, c in code.items():
        for m in DECL.finditer(c):
            kind, name = m.group(1).upper(), m.group(2).upper()
            if kind == "FDAT":
                f = _fields(c, m.start(3), m.end(3))
                fdat[name] = (f.get("TOOL_NO", ("",))[0], f.get("BASE_NO", ("",))[0])
            elif kind == "FRAME":
                frame = _frame(_fields(c, m.start(3), m.end(3)), p, line_of(c, m.start()))
                tools[name] = bases[name] = frame
                frames[name] = (p, line_of(c, m.start()))
            else:
                decls[name] = (p, kind, m.start(3), m.end(3))
        for m in BARE.finditer(c):
            for name in re.split(r"[ \t]*,[ \t]*", m.group(1).upper()):
                bare.setdefault(name, (p, line_of(c, m.start())))
    # tool and base in effect at each motion, in the order of the program's text
    events = sorted([(m.start(), m.group(1).upper(), m.group(2) or m.group(3).upper()) for m in TOOL_SET.finditer(
        code[path])] + [(m.start(), m.group(1).upper(), m.group(2)) for m in BAS_SET.finditer(code[path])] +
                    [(m.start(), "FDAT", m.group(1).upper()) for m in FDAT_ACT.finditer(code[path])] +
                    [(m.start(), m.group(1).upper(), f"${m.group(1).upper()} line {line_of(src, m.start())}")
                     for m in FRAME_SET.finditer(code[path])])
    for m in FRAME_SET.finditer(code[path]):  # a frame written where it is set: `$TOOL = {FRAME: X ...}`
        name = f"${m.group(1).upper()} line {line_of(src, m.start())}"
        (tools if m.group(1).upper() == "TOOL" else bases)[name] = _frame(_fields(code[path], m.start(2), m.end(2)),
                                                                            path, line_of(src, m.start()))
    # a point the program sets while it runs goes where that value says, not where the .dat's value does
    assigned = {}
    for m in ASSIGN.finditer(code[path]):
        assigned.setdefault(m.group(1).upper(), line_of(src, m.start()))
    targets, first_use = {}, {}
    state = {"TOOL": "$TOOL", "BASE": "$BASE"}
    e = 0
    for m in MOTION.finditer(code[path]):
        while e < len(events) and events[e][0] < m.start():
            _, what, value = events[e]
            if what == "FDAT" and value in fdat:
                state["TOOL"], state["BASE"] = fdat[value]
            elif what != "FDAT":
                state[what] = value
            e += 1
        line = line_of(src, m.start())
        if m.group(1).upper().endswith("_REL"):
            targets[m.start()] = Target(f"{m.group(1).upper()} line {line}", path, line, "motion", (),
                                        note="a relative motion: no target of its own to correct")
            continue
        rest, at = m.group(2), m.start(2)
        count = 2 if m.group(1).upper() in ("CIRC", "SCIRC") else 1
        for token in re.finditer(r"\{[^}\n]*\}|\$?[A-Za-z_][\w.\[\]]*", rest):
            if count == 0:
                break  # what follows the target: approximation, velocity, options
            count -= 1
            if token.group().startswith("{"):
                fields = _fields(rest, token.start() + 1, token.end() - 1)
                kind = "AXIS" if "A1" in fields else "POS"
                missing = [k for k in (JOINT_KEYS if kind == "AXIS" else POSE_KEYS) if k not in fields]
                if missing:  # KRL takes the missing components from the position before it, when it runs
                    targets[at + token.start()] = Target(
                        f"{m.group(1).upper()} line {line}", path, line, "motion", (),
                        note=f"a partial target ({', '.join(missing)} from the position before it while the "
                             f"program runs): not corrected")
                    continue
                targets[at + token.start()] = _target(src, path, kind, f"{m.group(1).upper()} line {line}",
                                                      at + token.start() + 1, at + token.end() - 1, state["TOOL"],
                                                      state["BASE"])
                continue
            name = token.group().upper()
            if name in decls and name in assigned:
                targets[at + token.start()] = Target(
                    f"{token.group()} (line {line})", path, line, "motion", (),
                    note=f"set while the program runs ({path.name}:{assigned[name]}): its declared value is not "
                         f"where the robot goes, not corrected")
            elif name in decls:
                first_use.setdefault(name, (state["TOOL"], state["BASE"]))
            elif name in frames:  # a FRAME names no S and T, and may also be a tool or base of the program
                where, at_line = frames[name]
                targets[at + token.start()] = Target(
                    f"{token.group()} (line {line})", path, line, "motion", (),
                    note=f"a FRAME ({where.name}:{at_line}): it names no configuration (S, T) to solve in, not "
                         f"corrected")
            elif name in bare:
                where, at_line = bare[name]
                targets[at + token.start()] = Target(
                    f"{token.group()} (line {line})", path, line, "motion", (),
                    note=f"declared without a value ({where.name}:{at_line}): set while the program runs, not "
                         f"corrected")
            elif dat_path is None:
                refuse(path, line, f"{m.group(1)} to {token.group()}, and no {path.with_suffix('.dat').name} beside "
                                   f"the program declares it", f"copy {path.with_suffix('.dat').name} beside it")
            else:  # a global point ($config.dat) or a system variable: not this program's to change
                targets[at + token.start()] = Target(f"{token.group()} (line {line})", path, line, "motion", (),
                                                     note="declared outside the program: correct it where it is "
                                                          "declared")
    for name, (p, kind, start, end) in decls.items():
        if name in assigned:
            continue  # its motions are listed above
        fd = fdat.get("F" + name[1:]) if name.startswith("X") else None
        if not fd and name not in first_use and kind in ("E6POS", "POS"):
            targets[(0 if p == path else 1, start)] = Target(
                name, p, line_of(texts[p], start), "motion", (),
                note="used by no motion of the program and without an FDAT: its tool and base are unknown")
            continue
        tool, base = fd if fd else first_use[name] if name in first_use else (None, None)
        targets[(0 if p == path else 1, start)] = _target(texts[p], p, kind, name, start, end, tool, base)
    ordered = sorted(targets.items(), key=lambda kv: kv[0] if isinstance(kv[0], tuple) else (0, kv[0]))
    return Program(path, texts, [t for _, t in ordered], tools, bases)


def write(program: Program, output: Path, texts: dict[Path, str]) -> dict[Path, Path]:
    """The .src to output and its .dat beside it under the same name: KRL pairs them, and the DEF and
    DEFDAT inside, by name."""
    if output.stem.upper() != program.path.stem.upper():
        refuse(output, None, f"KRL pairs a program with its .dat and its DEF {program.path.stem} by name",
               f"write it as {program.path.stem}{program.path.suffix} in another folder")
    written = {}
    for source, text in texts.items():
        target = output if source == program.path else output.with_suffix(source.suffix)
        write_atomically(target, text.encode("latin-1"))
        written[source] = target
    return written


FORMAT = Format("krl", (".src",), parse, pose, numbers, "deg", config, write, IDENTITY,
                controller="kuka", label="KUKA KRL")
