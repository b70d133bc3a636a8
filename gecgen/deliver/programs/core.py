"""What every controller format shares: a program read as text with the spans of its target numbers,
the correction of each target through the calibration, and the program written back with only
those numbers changed.

A joint target is corrected as `gecgen compensate` corrects a command (the controller's readings).
A Cartesian target is solved by the controller's nominal inverse kinematics in the configuration it
names, compensated, and written back as the nominal forward kinematics of the corrected joints in
the same configuration: the pose the controller must be given to reach the intended one.
Units: the robot's m and rad inside; each format converts its own (mm and deg, or m and rad).
"""
from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.deliver.programs.kinematics import Arm, arm_of, inverse, not_a_six_axis_arm, pose_error, seed_grid
from gecgen.model.files import write_atomically
from gecgen.model.validation import ModelError, read_yaml, require

#: a number in a program: sign, digits, decimals, exponent
NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
#: the decimals a corrected number keeps at least, by unit: 1 um, 1e-4 deg, 1e-6 rad, 1e-7 of a unit quaternion
DECIMALS = {"mm": 3, "m": 6, "deg": 4, "rad": 6, "1": 7}
#: a correction below these (m, rad) changes nothing the controller can act on: the target is kept as written
NOTHING = (1e-7, 1e-8)
#: the outcome of a target the calibration does not move: kept byte for byte, and not a failure
UNCHANGED = "no correction needed"
#: the written pose must bring the controller back to the corrected joints within this (rad): further off,
#: its inverse kinematics took another branch (a configuration flip); rounding moves them far less
ROUND_TRIP = 1e-3
#: a wrist whose axes pass within this (m) of one point is spherical for the configuration flags: those flags
#: tell the eight postures of such an arm apart, not the further ones of an offset wrist (a cobot's)
WRIST_MEETS = 1e-3


@dataclass(frozen=True)
class Number:
    """One number of a target in a file: its character span and text."""

    start: int
    end: int
    text: str
    unit: str  # mm, m, deg, rad, or 1 (a quaternion component)
    pad: bool = False  # the text carries the spaces that align it: a new value is right-aligned in that width

    @property
    def value(self) -> float:
        return float(self.text)


@dataclass(frozen=True)
class Target:
    """A motion target: `numbers` in the controller's order (joints: one per robot joint; poses: the
    format's position and orientation numbers); `config` the configuration a pose names (None: the
    controller takes the solution nearest the previous target); tool and base: the frame names the
    pose is given in (None: the flange, the robot's base)."""

    name: str
    file: Path
    line: int
    kind: str  # "joint", "pose", or "motion" (a motion with no target of its own to correct: see note)
    numbers: tuple[Number, ...]
    config: tuple | None = None
    tool: str | None = None
    base: str | None = None
    note: str | None = None  # why a motion has no target to correct (a relative motion): it is kept and listed

    @property
    def values(self) -> tuple[float, ...]:
        return tuple(n.value for n in self.numbers)


@dataclass
class Program:
    """A robot program as read: every file's text (KUKA: the .src and its .dat), its targets in
    program order, and the tool and base frames it declares itself (flange -> TCP, base -> frame,
    4x4 in m)."""

    path: Path
    texts: dict[Path, str]
    targets: list[Target]
    tools: dict[str, np.ndarray] = field(default_factory=dict)
    bases: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class Format:
    """A controller's program format and conventions.

    pose(values) -> (4, 4) in m from a pose target's numbers; numbers(T, target) -> the numbers of
    pose T (4, 4, m) in the target's order and units; joint_unit "deg" or "rad"; config(arm) -> a
    function mapping joints (K, n) to configurations (K, c) comparable with Target.config, or None;
    identity: frame names that are the flange or the robot base by definition; controller: the
    controller that runs such programs, as a robot file names it (`model.robot.CONTROLLERS`), and
    label how a person names the format."""

    name: str
    suffixes: tuple[str, ...]
    parse: Callable[[Path], Program]
    pose: Callable[[tuple[float, ...]], np.ndarray]
    numbers: Callable[[np.ndarray, Target], list[float]]
    joint_unit: str
    config: Callable[[Arm], Callable[[np.ndarray], np.ndarray]] | None
    write: Callable[[Program, Path, dict[Path, str]], dict[Path, Path]]
    identity: tuple[str, ...] = ()
    controller: str = ""
    label: str = ""


@dataclass(frozen=True)
class Change:
    """One target's outcome: after None when it is kept as written, with the reason."""

    target: Target
    after: tuple[str, ...] | None
    reason: str
    position_mm: float = 0.0
    rotation_deg: float = 0.0
    joints_deg: float = 0.0
    residual_mm: float = 0.0  # the tool error the compensation leaves (m in the model, mm here)


def refuse(path, line: int | None, what: str, fix: str):
    """A bad program: one line naming the file, the line and the fix."""
    raise ModelError(f"{path}{'' if line is None else f':{line}'}: {what}; {fix}")


def line_of(text: str, at: int) -> int:
    return text.count("\n", 0, at) + 1


def numbers_in(text: str, start: int, end: int, unit) -> list[Number]:
    """The numbers between start and end of text; unit a str for all or a list, one per number."""
    found = [Number(start + m.start(), start + m.end(), m.group(), "") for m in NUMBER.finditer(text[start:end])]
    units = [unit] * len(found) if isinstance(unit, str) else list(unit)
    return [Number(n.start, n.end, n.text, u) for n, u in zip(found, units)]


def decimals(text: str) -> int:
    mantissa = re.split("[eE]", text)[0]
    return len(mantissa.split(".")[1]) if "." in mantissa else 0


def formatted(number: Number, value: float) -> str:
    """value in the number's style: its decimals, or more when the unit needs them (DECIMALS), and the
    original text when it already says this value at its own decimals."""
    d = decimals(number.text.strip())
    if float(f"{value:.{d}f}") == number.value and abs(value - number.value) < 0.5 * 10.0 ** -DECIMALS[number.unit]:
        return number.text
    text = f"{value:.{max(d, DECIMALS[number.unit])}f}"
    text = "0" + text[text.index("."):] if text.startswith("-") and float(text) == 0 else text
    return text.rjust(len(number.text)) if number.pad else text


def rotation_angle(A: np.ndarray, B: np.ndarray) -> float:
    """The angle (rad) between the rotations of poses A and B (4, 4)."""
    return float(np.linalg.norm(pose_error(A[None], B[None])[0, 3:]))


def euler_pose(values, sequence: str) -> np.ndarray:
    """x y z (mm) and three Euler angles (deg) of scipy's `sequence` -> 4x4 in m."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler(sequence, values[3:6], degrees=True).as_matrix()
    T[:3, 3] = np.asarray(values[:3], float) / 1000.0
    return T


def near_angles(candidates: list[np.ndarray], old: np.ndarray) -> np.ndarray:
    """Of equivalent Euler triples (deg), the one nearest `old`, each angle shifted by whole turns to lie
    within 180 deg of the old one (the style of the program is kept: 179.9 does not become -180.1)."""
    best = None
    for c in candidates:
        shifted = old + (c - old + 180.0) % 360.0 - 180.0
        if best is None or np.sum(np.abs(shifted - old)) < np.sum(np.abs(best - old)):
            best = shifted
    return best


def euler_numbers(T: np.ndarray, old, sequence: str) -> list[float]:
    """x y z (mm) and the Euler angles of `sequence` (deg), the equivalent triple nearest `old` (6,)."""
    e = Rotation.from_matrix(T[:3, :3]).as_euler(sequence, degrees=True)
    other = np.array([e[0] + 180.0, 180.0 - e[1], e[2] + 180.0])
    return [*(1000.0 * T[:3, 3]), *near_angles([e, other], np.asarray(old[3:6], float))]


# -- frames ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class Frames:
    """The flange (after the robot file's frame n), tools (flange -> TCP) and bases (robot base ->
    user frame), 4x4 in m, by the names programs use."""

    flange: np.ndarray
    tools: dict[str, np.ndarray]
    bases: dict[str, np.ndarray]


def read_frames(path: str | Path | None, fmt: Format) -> Frames:
    """A frames file: `flange`, `tools` and `bases`, each pose six numbers in the controller's own
    convention (KUKA X Y Z A B C, FANUC X Y Z W P R, mm and deg; UR x y z rx ry rz, m and rad; ABB
    seven: x y z mm and the quaternion q1..q4)."""
    if path is None:
        return Frames(np.eye(4), {}, {})
    spec = read_yaml(Path(path), "frames") or {}
    require(isinstance(spec, dict), f"{path}: not a mapping; give keys flange, tools, bases")
    unknown = [k for k in spec if k not in ("flange", "tools", "bases")]
    require(not unknown, f"{path}: unknown key {unknown[0] if unknown else ''}; give flange, tools and bases")

    def pose(value, where):
        ok = isinstance(value, list) and all(isinstance(v, (int, float)) and math.isfinite(v) for v in value)
        wanted = 7 if fmt.name == "rapid" else 6
        require(ok and len(value) == wanted, f"{path}: {where}: give {wanted} numbers in the {fmt.name} "
                                             f"controller's pose convention (as its pendant shows them)")
        return fmt.pose(tuple(float(v) for v in value))

    def named(key):
        group = spec.get(key) or {}
        require(isinstance(group, dict), f"{path}: {key}: give a mapping of frame names to poses")
        return {str(name): pose(v, f"{key}: {name}") for name, v in group.items()}

    flange = pose(spec["flange"], "flange") if "flange" in spec else np.eye(4)
    return Frames(flange, named("tools"), named("bases"))


def frame_of(name: str | None, program: Program, frames: Frames, kind: str, fmt: Format,
             target: Target) -> np.ndarray:
    """The 4x4 of a tool or base a target names: the program's own declaration first, then the frames
    file; refused (one line) when neither describes it."""
    if name is None or name in fmt.identity:
        return np.eye(4)
    found = (program.tools if kind == "tools" else program.bases).get(name)
    if found is None:
        found = (frames.tools if kind == "tools" else frames.bases).get(name)
    if found is None:
        refuse(target.file, target.line, f"target {target.name} is in {kind[:-1]} {name}, which neither the program "
                                         f"nor a frames file describes",
               f"give its pose under {kind}: {name} in a frames file (--frames)")
    return found


# -- correcting --------------------------------------------------------------------------------

@dataclass
class Outcome:
    """The corrected texts by file, each target's change, and what the filter wrote."""

    texts: dict[Path, str]
    changes: list[Change]

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for c in self.changes:
            out[c.reason] = out.get(c.reason, 0) + 1
        return out

    @property
    def corrected(self) -> int:
        return sum(c.after is not None for c in self.changes)

    @property
    def kept(self) -> list[Change]:
        """The targets kept as written that the calibration would have moved, or that have no target
        of their own: each still carries the uncalibrated error."""
        return [c for c in self.changes if c.after is None and c.reason != UNCHANGED]


def _joint_scale(fmt: Format) -> float:
    return 180.0 / math.pi if fmt.joint_unit == "deg" else 1.0


def require_six_axis_arm(robot) -> None:
    """A one-line refusal naming why, unless `robot` is a serial arm of six revolute joints."""
    why = not_a_six_axis_arm(robot)
    require(why is None, f"robot {robot.name}: program filters correct serial arms of six revolute joints (the "
                         f"axes of KUKA, ABB, FANUC and UR programs), and {why}; correct this robot's commands "
                         f"with gecgen compensate")


def correct(fmt: Format, program: Program, cal, frames: Frames, max_iter: int = 50) -> Outcome:
    """Every target of the program corrected through the calibration `cal` (a fitted
    gecgen.api.Calibrator), or kept as written with the reason; the texts with the numbers of the
    corrected targets rewritten and every other character as it was."""
    robot = cal.robot_
    require_six_axis_arm(robot)
    arm = arm_of(robot, frames.flange)
    config = fmt.config(arm) if fmt.config else None
    # the seeds' forward kinematics is most of the work: only for a program with Cartesian targets
    seeds = seed_grid(arm, config) if any(t.kind == "pose" and t.note is None for t in program.targets) else None
    scale = _joint_scale(fmt)
    lo, hi = arm.limits()
    # frames first: a program whose frames nobody describes is refused before any work
    placed = [(t, frame_of(t.tool, program, frames, "tools", fmt, t), frame_of(t.base, program, frames, "bases",
                                                                               fmt, t))
              if t.kind == "pose" else (t, np.eye(4), np.eye(4)) for t in program.targets]
    nominal, reasons, previous = [], [], None
    for t, tool, base in placed:
        if t.note is not None:
            nominal.append(None)
            reasons.append(t.note)
            previous = None  # the robot stands wherever that motion took it
            continue
        if t.kind == "joint":
            require(len(t.numbers) == robot.n, f"{t.file}:{t.line}: target {t.name} has {len(t.numbers)} joint "
                                               f"values; robot {robot.name} has {robot.n}")
            q = np.array(t.values) / scale
            inside = bool(np.all((q >= lo - 1e-9) & (q <= hi + 1e-9)))
            nominal.append(q)
            reasons.append(None if inside else "outside the joint limits")
        else:
            goal = base @ fmt.pose(t.values) @ np.linalg.inv(tool)
            if config is not None and t.config is None:
                nominal.append(None)
                reasons.append("names no configuration: the controller's solution depends on where the robot stands")
                continue
            if config is not None and arm.wrist_miss > WRIST_MEETS:
                nominal.append(None)
                reasons.append(f"the wrist's axes 4, 5 and 6 pass {1e3 * arm.wrist_miss:.0f} mm from one point, so the "
                               f"configuration does not single out the posture the controller will take: teach the "
                               f"target as joints")
                continue
            if config is None and previous is None:
                nominal.append(None)
                reasons.append("no earlier target to solve it near (the controller starts from wherever the robot "
                               "stands)")
                continue
            q = inverse(arm, goal, seeds, config, t.config, near=previous if config is None else None)
            nominal.append(q)
            reasons.append(None if q is not None else "unreachable by the nominal model in its configuration")
        if nominal[-1] is not None:
            previous = nominal[-1]
    solved = [k for k, q in enumerate(nominal) if q is not None and reasons[k] is None]
    q_cmd = np.array([nominal[k] for k in solved]).reshape(-1, robot.n)
    done = cal.compensate(q_cmd, max_iter=max_iter) if len(solved) else None
    corrected = {k: (done.q[i], int(done.status[i]), float(done.residual[i])) for i, k in enumerate(solved)}

    from gecgen.runtime.compiled import STATUS_NAMES

    texts = dict(program.texts)
    edits: dict[Path, list[tuple[Number, str]]] = {}
    changes, previous = [], None
    for k, (t, tool, base) in enumerate(placed):
        if reasons[k] is not None:
            changes.append(Change(t, None, reasons[k]))
            previous = nominal[k] if nominal[k] is not None or t.note is not None else previous  # run as written
            continue
        q0 = nominal[k]
        q, status, residual = corrected[k]
        if status != 0:
            changes.append(Change(t, None, f"compensation {STATUS_NAMES[status]}" if status != 3 else
                                  "corrected joints outside the joint limits", residual_mm=1e3 * residual))
            previous = q0
            continue
        T0, T1 = arm.fk(q0)[0] @ tool, arm.fk(q)[0] @ tool
        move = (float(np.linalg.norm(T1[:3, 3] - T0[:3, 3])), rotation_angle(T0, T1))
        if move[0] < NOTHING[0] and move[1] < NOTHING[1] and np.max(np.abs(q - q0)) < NOTHING[1]:
            changes.append(Change(t, None, UNCHANGED))
            previous = q0
            continue
        if t.kind == "joint":
            after = [formatted(n, v) for n, v in zip(t.numbers, q * scale)]
        else:
            after = [formatted(n, v) for n, v in zip(t.numbers, fmt.numbers(np.linalg.inv(base) @ T1, t))]
            written = base @ fmt.pose(tuple(float(a) for a in after))
            # solved as the controller will: in the named configuration, or nearest the target before
            back = inverse(arm, written @ np.linalg.inv(tool), seeds, config, t.config,
                           near=previous if config is None else None)
            if back is None or np.max(np.abs(back - q)) > ROUND_TRIP:
                changes.append(Change(t, None, "the corrected pose would bring the controller to another "
                                               "configuration", residual_mm=1e3 * residual))
                previous = q0
                continue
        previous = q
        changes.append(Change(t, tuple(after), "corrected", 1e3 * move[0], math.degrees(move[1]),
                              math.degrees(float(np.max(np.abs(q - q0)))), 1e3 * residual))
        edits.setdefault(t.file, []).extend(zip(t.numbers, after))
    for path, spans in edits.items():
        text = texts[path]
        for number, new in sorted(spans, key=lambda s: -s[0].start):
            text = text[:number.start] + new + text[number.end:]
        texts[path] = text
    return Outcome(texts, changes)


def log_text(outcome: Outcome) -> str:
    """The change log as CSV: every target, corrected or kept, with its numbers before and after and
    the correction of its tool point (mm), tool orientation (deg) and largest joint (deg)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(["target", "file", "line", "kind", "status", "before", "after", "position_mm", "rotation_deg",
                "joints_deg", "residual_mm"])
    for c in outcome.changes:
        t = c.target
        # a motion without numbers of its own (its target is set at run time) has no correction to state
        moved = ["", "", "", ""] if t.kind == "motion" else \
            [f"{c.position_mm:.4f}", f"{c.rotation_deg:.5f}", f"{c.joints_deg:.5f}", f"{c.residual_mm:.4g}"]
        w.writerow([t.name, t.file.name, t.line, t.kind, c.reason, " ".join(n.text for n in t.numbers),
                    "" if c.after is None else " ".join(c.after), *moved])
    return out.getvalue()


def write_program(fmt: Format, program: Program, outcome: Outcome, output: Path) -> tuple[dict[Path, Path], Path]:
    """Write the corrected files (each atomically) and the change log beside the output
    (OUTPUT.log.csv): where each input file went, and the log's path."""
    written = fmt.write(program, Path(output), outcome.texts)
    log = Path(output).with_name(Path(output).name + ".log.csv")
    write_atomically(log, log_text(outcome))
    return written, log


def write_same_names(program: Program, output: Path, texts: dict[Path, str]) -> dict[Path, Path]:
    """The writer of one-file formats: the program's text to output, byte for byte as corrected."""
    (source, text), = texts.items()
    write_atomically(output, text.encode("latin-1"))
    return {source: output}


def read_text(path: Path) -> str:
    """A program's text with its line endings and every byte kept (latin-1 maps each byte to one
    character, so writing back with it restores the file exactly)."""
    try:
        return path.read_bytes().decode("latin-1")
    except OSError as exc:
        raise ModelError(f"{path}: {exc.strerror}; give the program's file") from None
