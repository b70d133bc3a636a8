"""Socket recordings as the common recorders write them: one CSV per socket, a configuration a row.

A lab calibrating with a plate moves the arm by hand until the ball sits in a socket and records the
joint readings, one file per socket: `front/hole_0.csv`, `front/hole_1.csv` (the MUKCa layout,
tests/data/mukca_panda6). Each row holds the robot's joint readings in joint order (m or rad), with
no header or with a header of `q1..qn` or the robot's joint names. The files of one folder are the
sockets of one plate placement; a known socket distance applies to a folder's two sockets.

`read_socket_files` turns them into measurements in the contract's layout: one pose per row, the
ball as `target`, the socket as `point` (`folder/stem`), x y z empty (`model.relative`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import LIMIT_TOLERANCE, Measurements
from gecgen.model.relative import POINT, Distance, Relative
from gecgen.model.robot import Robot
from gecgen.model.table import parse_float
from gecgen.model.validation import ModelError, excerpt, require


#: m: a stated socket distance may differ from the nominal model's by half of it and this much
DISTANCE_SLACK_M = 0.01


def _readings(path: Path, robot: Robot, sep: str, decimal: str) -> tuple[np.ndarray, int]:
    """(rows, n) joint readings of one socket file, and the line number of its first row; a row
    with another count of columns or a cell that is not a number is refused with its file line and
    column."""
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"{path}: cannot read it ({exc.__class__.__name__}); give the socket files, one CSV of "
                         f"joint readings per socket") from None
    while lines and not lines[-1].strip():
        lines.pop()
    require(lines, f"{path}: empty; record at least two configurations per socket")
    cells = [line.split(sep) for line in lines]
    names = [f"q{j + 1}" for j in range(robot.n)]
    aliases = {j.name: f"q{k + 1}" for k, j in enumerate(robot.joints)} | {q: q for q in names}
    headed = all(c.strip() in aliases for c in cells[0])
    order = list(range(robot.n))
    if headed:
        header = [aliases[c.strip()] for c in cells[0]]
        missing = [q for q in names if q not in header]
        require(not missing, f"{path}: line 1: no column {missing[0] if missing else ''} (nor its joint name); name "
                             f"the joints q1..q{robot.n} or as the robot file does")
        order = [header.index(q) for q in names]
    body = cells[1:] if headed else cells
    width = len(cells[0])
    require(width == robot.n or headed, f"{path}: line 1 has {width} columns but {robot.name} has {robot.n} joints; "
                                        f"each row holds the joint readings in joint order")
    bad = [k for k, row in enumerate(body) if len(row) != width]
    require(not bad, f"{path}: line {bad[0] + 1 + headed if bad else 0} has "
                     f"{len(body[bad[0]]) if bad else 0} columns, not {width}; one configuration a row")
    require(body, f"{path}: a header and no rows; record at least two configurations per socket")
    q = np.empty((len(body), robot.n))
    for r, row in enumerate(body):
        for j, k in enumerate(order):
            try:
                q[r, j] = parse_float(row[k].strip(), decimal)
            except ValueError:
                q[r, j] = np.nan
            require(np.isfinite(q[r, j]), f"{path}: line {r + 1 + headed}, column {k + 1} ({names[j]}): "
                                          f"{excerpt(row[k].strip())} is not a finite number; fix or remove the row")
    return q, 1 + headed


def read_socket_files(paths, robot: Robot, target: str | None = None, distance_m: float | None = None,
                      distance_std_m: float = 0.0, sep: str = ",", decimal: str = ".") -> Measurements:
    """Measurements of socket files (paths; see the module docstring), the `target` (default: the
    robot's only target) seated in each; with distance_m, each folder's two sockets that distance
    apart (m, standard uncertainty distance_std_m)."""
    paths = [Path(p) for p in paths]
    targets = list(robot.targets)
    if target is None:
        require(len(targets) == 1, f"{robot.source}: targets {', '.join(targets)}: name the one seated in the "
                                   f"sockets (--target)")
        target = targets[0]
    require(target in targets, f"--target {excerpt(target)}: not a target of {robot.name} ({', '.join(targets)})")
    names = [f"{p.parent.name}/{p.stem}" if p.parent.name else p.stem for p in paths]
    for k, name in enumerate(names):
        if name in names[:k]:
            first = paths[names.index(name)]
            same = first.resolve() == paths[k].resolve()
            raise ModelError(f"socket {name} is given twice; give each socket file once" if same else
                             f"{first} and {paths[k]} both make the socket id {name} (its folder's name and its "
                             f"own); rename one folder or file")
    loaded = [_readings(p, robot, sep, decimal) for p in paths]
    q, first_line = [qk for qk, _ in loaded], [line for _, line in loaded]
    lo = np.array([j.lower for j in robot.joints]) - LIMIT_TOLERANCE
    hi = np.array([j.upper for j in robot.joints]) + LIMIT_TOLERANCE
    for p, qk, line in zip(paths, q, first_line):
        require(len(qk) >= 2, f"{p}: one configuration: a socket seen once says nothing; record more")
        # a ball seated by hand is at joint readings the robot reached: beyond its limits, the file
        # holds something else (a pose or a point per row, or degrees), which must not pass for joints
        out = np.argwhere((qk < lo) | (qk > hi))
        if len(out):
            r, j = out[0]
            joint = robot.joints[j]
            raise ModelError(f"{p}: line {line + r}, column {j + 1} ({joint.name}): {qk[r, j]:g} is outside the joint "
                             f"limits [{joint.lower:g}, {joint.upper:g}] (m or rad): a socket file holds the joint "
                             f"readings of each configuration; is it a file of poses or points, or in degrees? "
                             f"Leave it out or convert it")
    distances = []
    if distance_m is not None:
        folders: dict[Path, list[int]] = {}
        for k, p in enumerate(paths):
            folders.setdefault(p.parent.resolve(), []).append(k)
        for folder, members in folders.items():
            require(len(members) == 2, f"{folder}: {len(members)} socket files; a socket distance joins a "
                                       f"folder's two sockets: give two files per folder, or no distance")
            distances.append(Distance(members[0], members[1], distance_m, distance_std_m))
    N = sum(len(qk) for qk in q)
    group = np.repeat(np.arange(len(paths)), [len(qk) for qk in q])
    relative = Relative(group, tuple(names), (POINT,) * len(paths), tuple(distances))
    twice = relative.seated_twice(np.vstack(q), np.zeros(N))
    if twice is not None:
        start = np.cumsum([0] + [len(qk) for qk in q])
        a, b = ((paths[group[r]], r - start[group[r]] + first_line[group[r]]) for r in twice)
        raise ModelError(f"{a[0]}: line {a[1]} and {b[0]}: line {b[1]} hold the same "
                         f"joint readings, but one configuration cannot seat the ball in two sockets: give each "
                         f"socket its own recording (was one file copied?)")
    for d in distances if target not in robot.estimated else ():  # an estimated target has no nominal place
        # the nominal model misplaces a socket by millimetres, not by a factor: a distance far from its
        # nominal one is in another unit (50 for 50 mm) or joins files of other sockets
        nominal = np.linalg.norm(np.subtract(*(target_positions(robot, q[k])[:, targets.index(target)].mean(axis=0)
                                               for k in (d.a, d.b))))
        require(abs(distance_m - nominal) <= 0.5 * nominal + DISTANCE_SLACK_M,
                f"{paths[d.a].parent}: the socket distance {distance_m:g} m is far from the {nominal:.3g} m at which "
                f"the robot's nominal model puts the folder's two sockets; give the distance in metres (50 mm is "
                f"0.05), and the files of one plate's two sockets")
    return Measurements(q=np.vstack(q), w=np.zeros((N, 6)), aux=np.zeros((N, 0)), aux_names=(),
                        pose_ids=np.arange(N), pose=np.arange(N), target=np.full(N, targets.index(target)),
                        xyz=np.full((N, 3), np.nan), source=", ".join(map(str, paths)), relative=relative)
