"""Pixel measurement files: one CSV row per point a camera saw in the image of one pose.

Columns: `pose`, `q1..qn` (and the optional wrench and auxiliary columns of a measurement file),
`camera` (a name from the camera file), `point` (a robot target for a camera fixed in the world, a
board corner `rRcC` for a camera on the tool) and `u`, `v` (px, OpenCV's image coordinates: origin
at the top-left pixel's centre, u to the right, v down). Validated like a measurement file: every
refusal names the file, the row and the column.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.cameras import Board, Camera
from gecgen.model.measurements import (MAX_AUX, MAX_WRENCH, Poses, named_joints, no_other_joints, pose_id_column,
                                       pose_subset, within_limits, write_csv)
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.table import at, read_table
from gecgen.model.validation import excerpt, require

#: the columns that make a measurement file a pixel file
PIXEL_COLUMNS = ("camera", "point", "u", "v")


@dataclass(frozen=True)
class Pixels(Poses):
    """P poses (`Poses`) and R image points: pose (R,) index into the poses; camera (R,) index into
    `cameras`; point (R,) index into `points` (robot targets, or board corners in `Board.names`
    order); uv (R, 2) px; row (R,) file lines (header = 1); mount "world" (cameras fixed, points on
    the robot) or "tool" (one camera on the tool, points on a board in the world)."""

    pose: np.ndarray
    camera: np.ndarray
    point: np.ndarray
    uv: np.ndarray
    row: np.ndarray
    cameras: tuple[str, ...]
    points: tuple[str, ...]
    mount: str
    source: str = ""

    #: image points are never relative rows (sockets, planes): what `fit.weak` asks measurements
    relative = None

    def subset(self, poses: np.ndarray) -> "Pixels":
        """The image points of the given pose indices."""
        poses, keep, pose = pose_subset(self.pose, self.n_poses, poses)
        return Pixels(*self.poses_at(poses), pose, self.camera[keep], self.point[keep], self.uv[keep], self.row[keep],
                      self.cameras, self.points, self.mount, self.source)


def is_pixel_file(header: list[str]) -> bool:
    """Whether a measurement file's header makes it a pixel file (it has u and v)."""
    return "u" in header and "v" in header


def read_pixels(path, robot: Robot, cameras: dict[str, Camera], board: Board | None = None) -> Pixels:
    """The image points of a pixel file (a path or a pandas DataFrame) for these cameras; a camera on
    the tool needs the board its points name."""
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    required = ["pose", *qcols, *PIXEL_COLUMNS]
    table = read_table(path, "pixel measurement file", ", ".join(required), text=("camera", "point"))
    where, header = table.where, table.header
    require(is_pixel_file(header) or not {"target", "x", "y", "z"} <= set(header),
            f"{where}: row 1: columns target, x, y, z: tracker measurements, not image points; read them without "
            f"--cameras (and --board)")
    for col in required:
        require(col in header, f"{where}: row 1: missing column '{col}' (a pixel file needs: {', '.join(required)})"
                               f"{named_joints(header, robot) if col in qcols else ''}")
    for col in ("target", "x", "y", "z"):
        require(col not in header, f"{where}: row 1: column '{col}' in a pixel file; give tracker points and "
                                   f"image points in separate files")
    no_other_joints(header, robot, where, "use the right robot file")
    mounts = {c.mount for c in cameras.values()}
    mount = "tool" if "tool" in mounts else "world"
    if mount == "tool":
        require(not robot.branches, f"{robot.source}: a tree of branches; a camera on the tool is supported on "
                                    f"serial chains only: see the tree's targets with fixed cameras (mount: world)")
        require(board is not None, f"{where}: the camera is on the tool and sees a board: give the board file "
                                   f"(--board BOARD.yaml)")
        points = tuple(board.names)
    else:
        require(board is None, f"{where}: the cameras are fixed (mount: world) and see the robot's targets: a board "
                               f"goes with a camera on the tool; leave out --board")
        points = tuple(robot.targets)
    names = tuple(cameras)
    cam = _index(table, "camera", names, f"the camera file has {', '.join(names)}")
    pt = _index(table, "point", points, f"robot {robot.name} has targets {', '.join(points)}" if mount == "world"
                else f"the board's corners are r0c0..r{board.rows - 1}c{board.columns - 1}")
    ids = pose_id_column(table, "pose")
    uv = np.column_stack([table.numbers(c, "give the pixel coordinate", 1e6) for c in ("u", "v")])
    for k, c in enumerate(names):
        cm = cameras[c]
        out = np.nonzero((cam == k) & ((uv[:, 0] < -0.5) | (uv[:, 0] > cm.width - 0.5) | (uv[:, 1] < -0.5)
                                       | (uv[:, 1] > cm.height - 0.5)))[0]
        require(not len(out), f"{where}: row {out[0] + 2 if len(out) else 0}, columns u v: "
                              f"{uv[out[0]].tolist() if len(out) else ''} outside camera {c}'s {cm.width} x "
                              f"{cm.height} image; intrinsics of another resolution, or the wrong camera? give the "
                              f"camera file this camera's intrinsics at the images' size (or scale fx fy cx cy by it)")
    key = (ids * len(names) + cam) * len(points) + pt
    _, first = np.unique(key, return_index=True)
    dup = np.setdiff1d(np.arange(len(table)), first)
    require(not len(dup), f"{where}: row {dup[0] + 2 if len(dup) else 0}: pose {ids[dup[0]] if len(dup) else 0} "
                          f"sees point {points[pt[dup[0]]] if len(dup) else ''} twice in one camera; keep one row")
    wcols = [c for c in WRENCH if c in header]
    aux_names = tuple(h for h in header if h not in required and h not in WRENCH)
    state_cols = [*qcols, *wcols, *aux_names]
    state = np.column_stack([table.numbers(c) if c in qcols else
                             table.numbers(c, limit=MAX_WRENCH) if c in WRENCH else
                             table.numbers(c, "fix it or remove the column (auxiliary columns must be numeric)",
                                           MAX_AUX) for c in state_cols])
    within_limits(state[:, :robot.n], robot, where)
    pose_ids, first, pose = np.unique(ids, return_index=True, return_inverse=True)
    differs = np.argwhere(state != state[first[pose]])
    if len(differs):
        r, k = differs[0]
        require(False, f"{at(where, r + 2, state_cols[k])}: pose {ids[r]} disagrees with its row "
                       f"{first[pose[r]] + 2}; rows of one pose must share joints, wrench and aux")
    ps = state[first]
    w = np.zeros((len(pose_ids), 6))
    for k, c in enumerate(wcols):
        w[:, WRENCH.index(c)] = ps[:, robot.n + k]
    return Pixels(ps[:, :robot.n], w, ps[:, robot.n + len(wcols):], aux_names, pose_ids, pose, cam, pt, uv,
                  np.arange(len(table)) + 2, names, points, mount, where)


def _index(table, col: str, names: tuple[str, ...], fix: str) -> np.ndarray:
    cells = [c.strip() for c in table.cells(col)]
    lookup = {n: k for k, n in enumerate(names)}
    idx = np.fromiter((lookup.get(c, -1) for c in cells), np.int64, len(cells))
    bad = np.nonzero(idx < 0)[0]
    require(not len(bad), f"{at(table.where, bad[0] + 2 if len(bad) else 0, col)}: unknown {col} "
                          f"{excerpt(cells[bad[0]]) if len(bad) else ''}; {fix}")
    return idx


def write_pixels(path, robot: Robot, data: Pixels):
    """Write in the pixel file's layout, floats with full precision (repr)."""
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    header = ["pose", *qcols, *WRENCH, *data.aux_names, *PIXEL_COLUMNS]
    return write_csv(path, header, ([int(data.pose_ids[k]), *map(repr, data.q[k].tolist()),
                                     *map(repr, data.w[k].tolist()), *map(repr, data.aux[k].tolist()),
                                     data.cameras[data.camera[r]], data.points[data.point[r]],
                                     *map(repr, data.uv[r].tolist())] for r, k in enumerate(data.pose)))
