"""Measurement files (CONTRACTS.md section 3): one CSV row per measured target of a pose.

Validated at the boundary: every refusal names the file, the row (1-based, header = row 1),
the column and the fix. Nothing is dropped, clipped or guessed.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gecgen.model.robot import WRENCH, Robot
from gecgen.model.validation import ModelError, require

#: joint readings may exceed the limits by this much (m or rad) before a row is refused
LIMIT_TOLERANCE = 1e-3
#: measured positions farther than this from the robot's reach look like millimetres (m)
MM_SUSPECT = 50.0


@dataclass(frozen=True)
class Measurements:
    """Poses (P of them) and measured target positions (R rows).

    q (P, n) m/rad; w (P, 6) N and N m in the sensor frame; aux (P, len(aux_names));
    pose_ids (P,) the file's pose ids; pose (R,) index into the poses; target (R,) index into
    robot.targets; xyz (R, 3) measured world positions in m.
    """

    q: np.ndarray
    w: np.ndarray
    aux: np.ndarray
    aux_names: tuple[str, ...]
    pose_ids: np.ndarray
    pose: np.ndarray
    target: np.ndarray
    xyz: np.ndarray
    source: str = ""

    @property
    def n_poses(self) -> int:
        return self.q.shape[0]

    def subset(self, poses: np.ndarray) -> "Measurements":
        """The measurements of the given pose indices (rows follow their poses)."""
        poses = np.asarray(poses)
        keep = np.isin(self.pose, poses)
        remap = -np.ones(self.n_poses, int)
        remap[poses] = np.arange(len(poses))
        return Measurements(self.q[poses], self.w[poses], self.aux[poses], self.aux_names, self.pose_ids[poses],
                            remap[self.pose[keep]], self.target[keep], self.xyz[keep], self.source)

    def aux_columns(self, names: tuple[str, ...]) -> np.ndarray:
        """(P, len(names)) values of the named auxiliary signals."""
        missing = [a for a in names if a not in self.aux_names]
        require(not missing, f"{self.source}: the error model uses auxiliary signal '{missing[0] if missing else ''}' "
                             f"but the data has no such column; add it or remove the term")
        return self.aux[:, [self.aux_names.index(a) for a in names]] if names else np.zeros((self.n_poses, 0))


def read_measurements(path: str | Path, robot: Robot, limit_tolerance: float = LIMIT_TOLERANCE) -> Measurements:
    path = Path(path)
    where = str(path)
    require(path.is_file(), f"{where}: no such measurement file")
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        require(header, f"{where}: the file is empty; expected a header row with pose, q1..qn, target, x, y, z")
        header = [h.strip() for h in header]
        rows = list(reader)
    require(len(set(header)) == len(header), f"{where}: row 1: duplicated column names in the header")
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    required = ["pose", *qcols, "target", "x", "y", "z"]
    for col in required:
        require(col in header, f"{where}: row 1: missing column '{col}' (needed: {', '.join(required)})")
    extra_q = [h for h in header if h.startswith("q") and h[1:].isdigit() and h not in qcols]
    require(not extra_q, f"{where}: row 1: column '{extra_q[0] if extra_q else ''}' but robot {robot.name} has "
                         f"{robot.n} joints; remove it or use the right robot file")
    wcols = [c for c in WRENCH if c in header]
    aux_names = tuple(h for h in header if h not in required and h not in WRENCH)
    require(rows, f"{where}: no data rows after the header")
    idx = {h: k for k, h in enumerate(header)}
    numeric = [*qcols, "x", "y", "z", *wcols, *aux_names]

    def value(row, r, col):
        text = row[idx[col]].strip() if idx[col] < len(row) else ""
        try:
            v = float(text)
        except ValueError:
            raise ModelError(f"{where}: row {r}, column '{col}': {text!r} is not a number; "
                             f"fix the value (auxiliary columns must be numeric)") from None
        require(math.isfinite(v), f"{where}: row {r}, column '{col}': {text} is not finite; remove the row or fix it")
        return v

    poses: dict[int, tuple[int, list[float]]] = {}
    pose_of_row, target_of_row, xyz = [], [], []
    seen = set()
    targets = list(robot.targets)
    lo = np.array([j.lower for j in robot.joints]) - limit_tolerance
    hi = np.array([j.upper for j in robot.joints]) + limit_tolerance
    for k, row in enumerate(rows):
        r = k + 2
        require(len(row) == len(header), f"{where}: row {r}: {len(row)} fields, the header has {len(header)}")
        try:
            pid = int(row[idx["pose"]])
        except ValueError:
            raise ModelError(f"{where}: row {r}, column 'pose': {row[idx['pose']]!r} is not an integer pose id") from None
        tname = row[idx["target"]].strip()
        require(tname in targets, f"{where}: row {r}, column 'target': unknown target '{tname}'; "
                                  f"robot {robot.name} has {', '.join(targets)}")
        require((pid, tname) not in seen, f"{where}: row {r}: pose {pid} measures target '{tname}' twice; keep one row")
        seen.add((pid, tname))
        vals = [value(row, r, c) for c in numeric]
        qv = np.array(vals[:robot.n])
        bad = np.nonzero((qv < lo) | (qv > hi))[0]
        if len(bad):
            j = bad[0]
            raise ModelError(f"{where}: row {r}, column 'q{j + 1}': {qv[j]:g} is outside the joint limits "
                             f"[{robot.joints[j].lower:g}, {robot.joints[j].upper:g}] (m or rad); check units or the robot file")
        p = vals[robot.n:robot.n + 3]
        require(max(abs(v) for v in p) < MM_SUSPECT,
                f"{where}: row {r}, columns x y z: {p} look like millimetres; positions are in metres, divide by 1000")
        state = vals[:robot.n] + vals[robot.n + 3:]
        if pid in poses:
            first_row, first = poses[pid]
            diff = [c for c, a, b in zip([*qcols, *wcols, *aux_names], first, state) if a != b]
            require(not diff, f"{where}: row {r}, column '{diff[0] if diff else ''}': pose {pid} disagrees with its "
                              f"row {first_row}; rows of one pose must share joints, wrench and aux")
        else:
            poses[pid] = (r, state)
        pose_of_row.append(pid)
        target_of_row.append(targets.index(tname))
        xyz.append(p)
    ids = np.array(sorted(poses))
    state = np.array([poses[i][1] for i in ids])
    q = state[:, :robot.n]
    w = np.zeros((len(ids), 6))
    for k, c in enumerate(wcols):
        w[:, WRENCH.index(c)] = state[:, robot.n + k]
    aux = state[:, robot.n + len(wcols):]
    index = {pid: k for k, pid in enumerate(ids)}
    return Measurements(q=q, w=w, aux=aux, aux_names=aux_names, pose_ids=ids,
                        pose=np.array([index[p] for p in pose_of_row]), target=np.array(target_of_row),
                        xyz=np.array(xyz), source=where)


def write_measurements(path: str | Path, robot: Robot, data: Measurements, wrench: bool = True):
    """Write in the contract's layout; floats with full precision (repr)."""
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    header = ["pose", *qcols, *(WRENCH if wrench else ()), *data.aux_names, "target", "x", "y", "z"]
    targets = list(robot.targets)
    with Path(path).open("w", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(header)
        for r in range(len(data.pose)):
            k = data.pose[r]
            out.writerow([int(data.pose_ids[k]), *map(repr, data.q[k].tolist()),
                          *(map(repr, data.w[k].tolist()) if wrench else ()), *map(repr, data.aux[k].tolist()),
                          targets[data.target[r]], *map(repr, data.xyz[r].tolist())])


@dataclass(frozen=True)
class Commands:
    """Joint commands to compensate: q (P, n), w (P, 6), aux (P, len(aux_names)), and the file's
    header and rows kept verbatim so the output repeats every other column unchanged."""

    q: np.ndarray
    w: np.ndarray
    aux: np.ndarray
    aux_names: tuple[str, ...]
    header: list[str]
    rows: list[list[str]]


def read_commands(path: str | Path, robot: Robot, aux_names: tuple[str, ...] = ()) -> Commands:
    """A CSV of nominal joint commands q1..qn, optional wrench and the aux columns the model uses."""
    path = Path(path)
    where = str(path)
    require(path.is_file(), f"{where}: no such file of joint commands")
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        header = [h.strip() for h in next(reader, [])]
        rows = list(reader)
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    for col in (*qcols, *aux_names):
        require(col in header, f"{where}: row 1: missing column '{col}'")
    require(rows, f"{where}: no data rows after the header")
    idx = {h: k for k, h in enumerate(header)}
    values = np.zeros((len(rows), len(header)))
    for k, row in enumerate(rows):
        require(len(row) == len(header), f"{where}: row {k + 2}: {len(row)} fields, the header has {len(header)}")
        for col in (*qcols, *[c for c in WRENCH if c in idx], *aux_names):
            try:
                v = float(row[idx[col]])
            except ValueError:
                raise ModelError(f"{where}: row {k + 2}, column '{col}': {row[idx[col]]!r} is not a number") from None
            require(math.isfinite(v), f"{where}: row {k + 2}, column '{col}': not finite")
            values[k, idx[col]] = v
    w = np.zeros((len(rows), 6))
    for j, c in enumerate(WRENCH):
        if c in idx:
            w[:, j] = values[:, idx[c]]
    return Commands(values[:, [idx[c] for c in qcols]], w, values[:, [idx[a] for a in aux_names]], aux_names,
                    header, rows)


def write_commands(path: str | Path, robot: Robot, commands: Commands, q: np.ndarray):
    """The input rows with q1..qn replaced by q (P, n), full precision."""
    idx = {h: k for k, h in enumerate(commands.header)}
    with Path(path).open("w", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(commands.header)
        for row, qi in zip(commands.rows, q):
            row = list(row)
            for j in range(robot.n):
                row[idx[f"q{j + 1}"]] = repr(float(qi[j]))
            out.writerow(row)
