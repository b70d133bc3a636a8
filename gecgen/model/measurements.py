"""Measurement files (CONTRACTS.md section 3): one CSV row per measured target of a pose.

Validated at the boundary: every refusal names the file, the row (1-based, header = row 1),
the column and the fix. Nothing is dropped, clipped or guessed.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from gecgen.model.files import write_atomically
from gecgen.model import relative as rel
from gecgen.model.orientation import PREFIXES, QUATERNION, Convention, file_convention, quaternions, rotations
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.rows import Rows, Vertices, point_rows
from gecgen.model.table import Table, at, numbers, read_table
from gecgen.model.validation import ModelError, excerpt, require

#: joint readings may exceed the limits by this much (m or rad) before a row is refused
LIMIT_TOLERANCE = 1e-3
#: the optional column naming the tracker stationing of each row (an integer id)
STATION = "station"
#: measured positions farther than this from the robot's reach look like millimetres (m)
MM_SUSPECT = 50.0
#: magnitudes no real reading reaches (a wrench in N and N m, an auxiliary signal): beyond them a cell
#: is an export or unit error, and terms that large would swamp every other column of the fit
MAX_WRENCH = 1e7
MAX_AUX = 1e12
#: pose ids are read as floats, which tell neighbouring integers apart only below 2**53
MAX_POSE_ID = 2 ** 53


def pose_id_column(table: Table, col: str, what: str = "pose id",
                   fix: str = "number the poses 0, 1, 2, ...") -> np.ndarray:
    """A column of integer ids (R,) (pose ids; station ids with `what` and `fix`); beyond 2**53
    distinct ids would merge silently."""
    ids = table.numbers(col)
    bad = np.nonzero((ids != np.round(ids)) | (np.abs(ids) >= MAX_POSE_ID))[0]
    require(not len(bad), f"{at(table.where, bad[0] + 2 if len(bad) else 0, col)}: not an integer {what} within "
                          f"+-2**53 ({excerpt(table.cells(col)[bad[0]]) if len(bad) else ''}); {fix}")
    return ids.astype(np.int64)


def pose_subset(pose: np.ndarray, n_poses: int, poses) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For rows whose poses are `pose` (R,) among n_poses: the chosen pose indices (as an array), which
    rows are theirs (R,) and those rows' pose indices among the chosen."""
    poses = np.asarray(poses)
    keep = np.isin(pose, poses)
    remap = -np.ones(n_poses, int)
    remap[poses] = np.arange(len(poses))
    return poses, keep, remap[pose[keep]]


@dataclass(frozen=True)
class Poses:
    """P poses of the robot as a file gives them: q (P, n) joint readings, m/rad; w (P, 6) N and N m
    in the sensor frame; aux (P, len(aux_names)) the auxiliary signals; pose_ids (P,) the file's pose
    ids. What is measured at them (points, image points) is the subclasses'."""

    q: np.ndarray
    w: np.ndarray
    aux: np.ndarray
    aux_names: tuple[str, ...]
    pose_ids: np.ndarray

    @property
    def n_poses(self) -> int:
        return self.q.shape[0]

    def poses_at(self, poses: np.ndarray) -> tuple:
        """The pose fields (q, w, aux, aux_names, pose_ids) of the given pose indices, in field order."""
        return self.q[poses], self.w[poses], self.aux[poses], self.aux_names, self.pose_ids[poses]

    def aux_columns(self, names: tuple[str, ...]) -> np.ndarray:
        """(P, len(names)) values of the named auxiliary signals."""
        missing = [a for a in names if a not in self.aux_names]
        require(not missing, f"{self.source}: the error model uses auxiliary signal {excerpt(missing[0]) if missing else ''} "
                             f"but the data has no such column; add it or remove the term")
        return self.aux[:, [self.aux_names.index(a) for a in names]] if names else np.zeros((self.n_poses, 0))


@dataclass(frozen=True)
class Measurements(Poses):
    """Poses (P of them, `Poses`) and measured target positions (R rows).

    pose (R,) index into the poses; target (R,) index into
    robot.targets; xyz (R, 3) measured world positions in m; row (R,) the line of each point in
    its file (header = 1), None when the points were never read from a file (then they are
    numbered as `write_measurements` would write them); station (R,) the integer id of the tracker
    stationing each point was measured from (zeros when the file has no `station` column);
    orientation (R, 3, 3) the measured orientation of each row's target frame (parallel to the tool
    frame) in the measuring frame, NaN for a row that measures the position only; None when no
    row has one (docs/reference.md, "Pose measurements"); relative the rows that say only which
    point or plane their target sits at (`model.relative`; their xyz NaN), None when no row does;
    vertices which points are the vertices of a measured frame once pose data are points
    (`model.pose_targets.as_points`), None for point data.
    """

    pose: np.ndarray
    target: np.ndarray
    xyz: np.ndarray
    source: str = ""
    row: np.ndarray | None = None
    station: np.ndarray | None = None
    orientation: np.ndarray | None = None
    relative: rel.Relative | None = None
    vertices: Vertices | None = None

    def __post_init__(self):
        if self.station is None:  # one stationing: every point in the same tracker frame
            object.__setattr__(self, "station", np.zeros(len(self.xyz), np.int64))

    @property
    def file_rows(self) -> np.ndarray:
        """(R,) the file line of each measured point (header = 1)."""
        return self.row if self.row is not None else np.arange(len(self.xyz)) + 2

    @cached_property
    def rows(self) -> Rows:
        """The measured rows (`model.rows.Rows`): one per pose and measured frame or point."""
        relative_dof = None if self.relative is None else self.relative.row_dof()
        return point_rows(self.pose, self.target, self.vertices, relative_dof)

    def subset(self, poses: np.ndarray) -> "Measurements":
        """The measurements of the given pose indices (rows follow their poses)."""
        poses, keep, pose = pose_subset(self.pose, self.n_poses, poses)
        return Measurements(*self.poses_at(poses), pose, self.target[keep], self.xyz[keep], self.source,
                            self.file_rows[keep], self.station[keep],
                            None if self.orientation is None else self.orientation[keep],
                            None if self.relative is None else self.relative.take(keep),
                            None if self.vertices is None else self.vertices.take(keep))

    def rows_of(self, keep: np.ndarray) -> "Measurements":
        """The measured rows where `keep` (R,) holds, every pose kept (a branch's points of a tree)."""
        return Measurements(self.q, self.w, self.aux, self.aux_names, self.pose_ids, self.pose[keep],
                            self.target[keep], self.xyz[keep], self.source, self.file_rows[keep], self.station[keep],
                            None if self.orientation is None else self.orientation[keep],
                            None if self.relative is None else self.relative.take(keep),
                            None if self.vertices is None else self.vertices.take(keep))



def within_limits(q: np.ndarray, robot: Robot, where: str, limit_tolerance: float = LIMIT_TOLERANCE):
    """Refuse the first joint value of q (rows, n; row r is file row r + 2) outside the robot's
    limits by more than limit_tolerance (m or rad): a file in degrees read as radians, mostly."""
    lo = np.array([j.lower for j in robot.joints]) - limit_tolerance
    hi = np.array([j.upper for j in robot.joints]) + limit_tolerance
    out = np.argwhere((q < lo) | (q > hi))
    if len(out):
        r, j = out[0]
        raise ModelError(f"{at(where, r + 2, f'q{j + 1}')}: {q[r, j]:g} is outside the joint limits "
                         f"[{robot.joints[j].lower:g}, {robot.joints[j].upper:g}] (m or rad); check units (degrees "
                         f"read as radians?) or the robot file")


def read_measurements(path, robot: Robot, limit_tolerance: float = LIMIT_TOLERANCE) -> Measurements:
    """The measurements of a CSV file (its path), or of a pandas DataFrame with the file's columns
    (messages name it `DataFrame`, its rows numbered as in the CSV `to_csv(index=False)` writes)."""
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    required = ["pose", *qcols, "target", "x", "y", "z"]
    table = read_table(path, "measurement file", ", ".join(required), text=("target", *rel.COLUMNS))
    where = table.where
    header = table.header
    require(not ("u" in header and "v" in header and "target" not in header),
            f"{where}: row 1: columns u and v: a pixel file (image points), which identify, diagnose, calibrate, "
            f"redundancy, evaluate, check, accuracy and export --data read with the camera file (--cameras); this "
            f"step takes tracker measurements (pose, q1..qn, target, x, y, z)")
    for col in required:
        require(col in header, f"{where}: row 1: missing column '{col}' (needed: {', '.join(required)})"
                               f"{named_joints(header, robot, IMPORT) if col in qcols else ''}")
    no_other_joints(header, robot, where, "use the right robot file")
    wcols = [c for c in WRENCH if c in header]
    convention = file_convention(header, where)
    # station names the tracker frame of a row and orientation columns its measured frame, not
    # signals the robot's errors may depend on
    aux_names = tuple(h for h in header if h not in required and h not in WRENCH and h != STATION
                      and h not in rel.COLUMNS and not h.startswith(PREFIXES))

    def column(col: str) -> np.ndarray:
        if col in required:
            return table.numbers(col)
        if col in WRENCH:
            return table.numbers(col, limit=MAX_WRENCH)
        return table.numbers(col, "fix it or remove the column (auxiliary columns must be numeric)", MAX_AUX)

    ids = pose_id_column(table, "pose")
    targets = list(robot.targets)
    tindex = {t: k for k, t in enumerate(targets)}
    names = table.cells("target")
    target = np.fromiter((tindex.get(t.strip(), -1) for t in names), np.int64, len(names))
    unknown = np.nonzero(target < 0)[0]
    require(not len(unknown), f"{at(where, unknown[0] + 2 if len(unknown) else 0, 'target')}: unknown target "
                              f"{excerpt(names[unknown[0]].strip()) if len(unknown) else ''}; robot {robot.name} has "
                              f"{', '.join(targets)}")
    key = ids * len(targets) + target
    _, first = np.unique(key, return_index=True)
    dup = np.ones(len(table), bool)
    dup[first] = False
    dup = np.nonzero(dup)[0]
    require(not len(dup), f"{where}: row {dup[0] + 2 if len(dup) else 0}: pose {ids[dup[0]] if len(dup) else 0} "
                          f"measures target '{names[dup[0]].strip() if len(dup) else ''}' twice; keep one row")
    state_cols = [*qcols, *wcols, *aux_names]
    state = np.column_stack([column(c) for c in state_cols])
    relative = rel.read_relative(table)
    twice = None if relative is None else relative.seated_twice(state[:, :robot.n], target)
    if twice is not None:
        a, b = twice
        raise ModelError(f"{where}: rows {a + 2} and {b + 2}: the same joint readings seat target "
                         f"{excerpt(names[a].strip())} at point {excerpt(relative.names[relative.group[a]])} and at "
                         f"point {excerpt(relative.names[relative.group[b]])}, which one configuration cannot do: "
                         f"give each point its own recording (was one copied?)")
    xyz = _positions(table, column, relative)
    within_limits(state[:, :robot.n], robot, where, limit_tolerance)
    mm = np.nonzero(np.abs(xyz).max(axis=1) >= MM_SUSPECT)[0]
    require(not len(mm), f"{where}: row {mm[0] + 2 if len(mm) else 0}, columns x y z: "
                         f"{xyz[mm[0]].tolist() if len(mm) else ''} are over {MM_SUSPECT:g} m from the robot: "
                         f"positions are in metres; divide millimetres by 1000, centimetres by 100")
    pose_ids, first, pose = np.unique(ids, return_index=True, return_inverse=True)
    differs = np.argwhere(state != state[first[pose]])
    if len(differs):
        r, k = differs[0]
        raise ModelError(f"{at(where, r + 2, state_cols[k])}: pose {ids[r]} disagrees with its row "
                         f"{first[pose[r]] + 2}; rows of one pose must share joints, wrench and aux")
    station = np.zeros(len(xyz), np.int64)
    if STATION in header:
        station = pose_id_column(table, STATION, "station id",
                                 "give every row of one tracker stationing the same integer")
    ps = state[first]
    w = np.zeros((len(pose_ids), 6))
    for k, c in enumerate(wcols):
        w[:, WRENCH.index(c)] = ps[:, robot.n + k]
    orientation = None if convention is None else _orientations(table, convention)
    if orientation is not None and relative is not None:
        both = np.nonzero(relative.rows & ~np.isnan(orientation[:, 0, 0]))[0]
        require(not len(both), f"{where}: row {both[0] + 2 if len(both) else 0}: a point or plane row with an "
                               f"orientation; a socket or plane fixes the position only: leave the orientation empty")
    return Measurements(q=ps[:, :robot.n], w=w, aux=ps[:, robot.n + len(wcols):], aux_names=aux_names,
                        pose_ids=pose_ids, pose=pose, target=target, xyz=xyz, source=where,
                        row=np.arange(len(xyz)) + 2, station=station, orientation=orientation, relative=relative)


def _positions(table: Table, column, relative: rel.Relative | None) -> np.ndarray:
    """(R, 3) the x y z of every row (m), NaN on a relative row, whose cells must be empty."""
    if relative is None or not relative.rows.any():
        return np.column_stack([column(c) for c in ("x", "y", "z")])
    xyz = np.empty((len(table), 3))
    for k, c in enumerate(("x", "y", "z")):
        cells = np.char.strip(table.cells(c).astype(str))
        given = np.nonzero(relative.rows & (cells != ""))[0]
        require(not len(given), f"{at(table.where, given[0] + 2 if len(given) else 0, c)}: a point or plane row gives "
                                f"a position; leave x y z empty on it, or remove its point or plane id")
        # "0" on the relative rows so that a bad cell elsewhere is named by its own row
        xyz[:, k] = numbers(np.where(relative.rows, "0", cells), c, table.where, decimal=table.decimal)
    xyz[relative.rows] = np.nan
    return xyz


def _orientations(table: Table, convention: Convention) -> np.ndarray | None:
    """(R, 3, 3) measured orientations of a file's rows, NaN where a row leaves every orientation
    cell empty (it measures the position only); None when no row has one. A row with some cells
    empty, a cell that is not a finite number or values that are no rotation is refused."""
    where, names = table.where, convention.columns()
    fix = "fix the orientation, or leave all its columns empty for a position-only row"
    span = f"columns {names[0]}..{names[-1]}"
    try:  # the usual file: every row has its orientation, read as numbers by the fast reader
        values = np.column_stack([table.numbers(c, fix) for c in names])
    except ModelError:
        values = None  # an empty cell (a position-only row) or a bad one: the cells below say which
    if values is not None:
        return rotations(values, convention, lambda r: f"{where}: row {r + 2}, {span}")
    cells = np.column_stack([table.cells(c) for c in names])  # some cell is empty, or bad: find which
    empty = np.char.strip(cells.astype(str)) == ""
    partial = np.nonzero(empty.any(axis=1) & ~empty.all(axis=1))[0]
    if len(partial):
        r = partial[0]
        raise ModelError(f"{at(where, r + 2, names[int(np.argmax(empty[r]))])}: empty, but the row gives other "
                         f"orientation columns; give all of {', '.join(names)}, or none for a position-only row")
    rows = np.nonzero(~empty[:, 0])[0]
    if not len(rows):
        return None
    filled = np.where(empty, "0", cells)  # so that messages count rows as the file does
    values = np.column_stack([numbers(filled[:, k], c, where, fix, decimal=table.decimal) for k, c in enumerate(names)])
    R = np.full((len(table), 3, 3), np.nan)
    R[rows] = rotations(values[rows], convention, lambda i: f"{where}: row {rows[i] + 2}, {span}")
    return R


def write_measurements(path: str | Path, robot: Robot, data: Measurements, wrench: bool = True):
    """Write in the contract's layout; floats with full precision (repr); the station column only
    when some point is not from station 0 (a file without it is station 0); orientations, when
    the data has any, as unit quaternions `quat_w..quat_z` (empty for position-only rows)."""
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    stations = bool(np.any(data.station != 0))
    quat = [[]] * len(data.xyz)
    if data.orientation is not None:
        has = ~np.isnan(data.orientation[:, 0, 0])
        quat = [[""] * 4] * len(data.xyz)
        for r, qr in zip(np.nonzero(has)[0], quaternions(data.orientation[has])):
            quat[r] = list(map(repr, qr.tolist()))
    relative = data.relative
    header = ["pose", *qcols, *(WRENCH if wrench else ()), *data.aux_names, *([STATION] if stations else ()),
              "target", "x", "y", "z", *(QUATERNION if data.orientation is not None else ()),
              *(rel.COLUMNS if relative is not None else ())]
    targets = list(robot.targets)

    def position(r: int) -> list[str]:
        return [""] * 3 if relative is not None and relative.group[r] >= 0 else list(map(repr, data.xyz[r].tolist()))

    write_csv(path, header, ([int(data.pose_ids[k]), *map(repr, data.q[k].tolist()),
                              *(map(repr, data.w[k].tolist()) if wrench else ()), *map(repr, data.aux[k].tolist()),
                              *([int(data.station[r])] if stations else ()),
                              targets[data.target[r]], *position(r), *quat[r],
                              *(rel.columns(relative, r) if relative is not None else ())]
                             for r, k in enumerate(data.pose)))


def write_csv(path: str | Path, header: list[str], rows) -> Path:
    """A CSV of header and rows (iterables of cells), written atomically; returns the path."""
    text = io.StringIO()
    out = csv.writer(text, lineterminator="\n")
    out.writerow(header)
    out.writerows(rows)
    return write_atomically(path, text.getvalue())


@dataclass(frozen=True)
class Commands:
    """Joint commands to compensate: q (P, n), w (P, 6), aux (P, len(aux_names)), and the file's
    header and rows kept verbatim so the output repeats every other column unchanged; row p is
    line p + 2 of `source`."""

    q: np.ndarray
    w: np.ndarray
    aux: np.ndarray
    aux_names: tuple[str, ...]
    header: list[str]
    rows: list[list[str]]
    source: str = ""


#: how a measurement file that names its joints is converted
IMPORT = "rename the columns, or convert the file with gecgen import --mapping"


def named_joints(header: list[str], robot: Robot, how: str = "rename the columns") -> str:
    """What to say beside a missing joint column when the header names the robot's joints instead of
    q1..qn (a controller's or a tracker software's export): how gecgen numbers them, and `how` to convert."""
    if not any(j.name in header for j in robot.joints):
        return ""
    return (f"; the file names joints ({robot.joints[0].name}, ...): gecgen reads q1..q{robot.n} in the robot file's "
            f"order (q1 = {robot.joints[0].name}); {how}")


def no_other_joints(header: list[str], robot: Robot, where: str, fix: str):
    """Refuse a joint column the robot does not have (q7 for a six-joint robot): the file is another
    robot's, and reading only q1..qn of it would give that robot's poses to this one."""
    qcols = {f"q{i + 1}" for i in range(robot.n)}
    extra = [h for h in header if h.startswith("q") and h[1:].isdigit() and h not in qcols]
    require(not extra, f"{where}: row 1: column {excerpt(extra[0]) if extra else ''} but robot {robot.name} has "
                       f"{robot.n} joints; remove it or {fix}")


def read_commands(path, robot: Robot, aux_names: tuple[str, ...] = ()) -> Commands:
    """A CSV (path or pandas DataFrame) of nominal joint commands q1..qn, optional wrench and the aux
    columns the model uses."""
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    # the output repeats every cell as the file has it: the csv module reads them all
    table = read_table(path, "file of joint commands", ", ".join(qcols), verbatim=True)
    where = table.where
    header = table.header
    for col in qcols:
        require(col in header, f"{where}: row 1: missing column '{col}'{named_joints(header, robot)}")
    no_other_joints(header, robot, where, "use the calibration or robot file of the robot these commands are for")
    for col in aux_names:
        require(col in header, f"{where}: row 1: missing column {excerpt(col)}, an auxiliary signal the error model uses; "
                               f"add it" + (" (gecgen gravity writes tau_<joint> columns)" if col.startswith("tau_") else ""))

    w = np.zeros((len(table), 6))
    for j, c in enumerate(WRENCH):
        if c in header:
            w[:, j] = table.numbers(c, limit=MAX_WRENCH)
    aux = np.column_stack([table.numbers(a, limit=MAX_AUX) for a in aux_names]) if aux_names else np.zeros((len(table), 0))
    q = np.column_stack([table.numbers(c) for c in qcols])
    within_limits(q, robot, where)
    return Commands(q, w, aux, aux_names, header, table.rows(), where)


def write_commands(path: str | Path, robot: Robot, commands: Commands, q: np.ndarray, columns: dict | None = None):
    """The input rows with q1..qn replaced by q (P, n), full precision; `columns` (name -> P cells)
    replace the input's columns of those names or are added after the others."""
    header = list(commands.header) + [name for name in columns or {} if name not in commands.header]
    idx = {h: k for k, h in enumerate(header)}
    rows = []
    for p, (row, qi) in enumerate(zip(commands.rows, q)):
        row = list(row) + [""] * (len(header) - len(row))
        for j in range(robot.n):
            row[idx[f"q{j + 1}"]] = repr(float(qi[j]))
        for name, cells in (columns or {}).items():
            row[idx[name]] = cells[p]
        rows.append(row)
    write_csv(path, header, rows)


def hold_out(data: Measurements, fraction: float, seed: int = 0) -> tuple[Measurements, Measurements]:
    """(training, held-out) parts of `data`, split by pose at random (seeded): round(fraction x
    poses) poses held out, at least one on each side."""
    require(0 < fraction < 1, f"--holdout {fraction:g}: give the share of poses to hold out, between 0 and 1 (e.g. 0.2)")
    require(data.n_poses >= 2, f"{data.source}: {data.n_poses} pose: nothing to hold out; measure more poses")
    n = min(max(1, round(fraction * data.n_poses)), data.n_poses - 1)
    held = np.random.default_rng(seed).permutation(data.n_poses)
    return data.subset(np.sort(held[n:])), data.subset(np.sort(held[:n]))
