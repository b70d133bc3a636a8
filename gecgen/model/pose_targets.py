"""Pose measurements as points: a measured frame is four virtual targets.

A row that measures a target's position p and the orientation R of its frame (parallel to the
tool frame, or turned by `Robot.target_frames`; `Measurements.orientation`) says as much as four
measured points rigidly attached to that frame: the vertices p + r R v_k of a regular tetrahedron around the target. So a robot with
pose data gets four virtual targets per target, t + r v_k in the tool frame (`with_pose_targets`,
a derived robot whose code is generated and compiled by content like any other), each oriented
row becomes its four vertices (`as_points`), and everything downstream - J_e, registration,
robust fitting, redundancy, diagnose - works on points unchanged. The rank analysis then sees
what orientations add: a rotation about the last joint's axis moves the vertices even when the
target sits on that axis.

Why a tetrahedron: its unit vertices v_k sum to zero and sum(v_k v_k^T) = 4/3 I. For a measured
frame off its model by e (position) and a rotation dR of angle theta, the four vertex residuals
are e + r dR v_k, and their squares add up to exactly 4 (|e|^2 + L^2 (2 sin(theta/2))^2) when
r = L sqrt(3/2): no cross term between position and orientation, every axis of rotation counts
the same, and (for small angles) an orientation error of 1 mrad counts as L * 1 mrad of position
error. Each vertex has weight 1/4 (`WEIGHT`), so a measured frame counts |e|^2 + L^2 theta^2 and a
position-only row |e|^2, as before; a measured frame has six degrees of freedom, so each vertex's
three coordinates count for 1.5 (`DOF`) in residual variances. Both errors come back exactly from
the vertices (`Rows.errors`): the position is their centroid, the orientation
(3 / (4 r)) sum(y_k v_k^T).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.model.measurements import Measurements
from gecgen.model.robot import Robot
from gecgen.model.validation import require

#: unit vertices of a regular tetrahedron: they sum to zero, and sum(v v^T) = 4/3 I
VERTICES = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]]) / np.sqrt(3.0)
#: the default length scale L (m): an orientation error of 1 mrad counts as 0.1 mm of position, about
#: the ratio of a laser tracker's position noise to a 6-D probe's orientation noise
LENGTH_M = 0.1
#: weight of each vertex point in the fit, and the degrees of freedom its three coordinates carry
WEIGHT = 0.25
DOF = 1.5


def vertex_radius(length_m: float) -> float:
    """r (m): the distance of the vertices from the target for the length scale L (m)."""
    return float(length_m) * np.sqrt(1.5)


def with_pose_targets(robot: Robot, length_m: float = LENGTH_M) -> Robot:
    """The robot with four virtual targets per target, `<target>__v1..v4` at t + r X v_k in the tool
    frame (r from the length scale L, m; X the measured frame's rotation in the tool frame,
    `Robot.target_frames`, else the identity), after the robot's own targets (whose indices stay)."""
    require(np.isfinite(length_m) and length_m > 0, f"--orientation-length {length_m!r}: give a positive length in "
                                                    f"m (1 rad of orientation error counts as this much position)")
    r = vertex_radius(length_m)
    extra, vertex_of = {}, {}
    for name, t in robot.targets.items():
        turn = Rotation.from_rotvec(robot.target_frames.get(name, (0.0, 0.0, 0.0))).as_matrix()
        for k, v in enumerate(VERTICES):
            virtual = f"{name}__v{k + 1}"
            require(virtual not in robot.targets, f"{robot.source}: targets: {virtual} is the name of a virtual target "
                                                  f"of pose measurements; rename the target")
            extra[virtual] = tuple(float(x) for x in np.asarray(t) + r * turn @ v)
            vertex_of[virtual] = (name, k)
    return replace(robot, targets={**robot.targets, **extra}, vertex_of=vertex_of, pose_length=float(length_m))


def as_points(robot: Robot, data: Measurements) -> Measurements:
    """`data` (read against the robot's own targets) on `robot` from `with_pose_targets`: each
    row with an orientation becomes its four vertex points (measured y + r R v_k, the file row
    kept), position-only rows stay as they are."""
    if data.orientation is None:
        return data
    oriented = ~np.isnan(data.orientation[:, 0, 0])
    count = np.where(oriented, len(VERTICES), 1)
    src = np.repeat(np.arange(len(data.xyz)), count)  # the data row of each new point
    k = np.arange(len(src)) - np.repeat(np.cumsum(count) - count, count)  # vertex number within its row
    vertex = oriented[src]
    names = robot.target_names
    index = np.full((len(names), len(VERTICES)), -1)  # (target, vertex) -> the virtual target
    for v, (origin, kk) in robot.vertex_of.items():
        index[names.index(origin), kk] = names.index(v)
    target = data.target[src].copy()
    target[vertex] = index[target[vertex], k[vertex]]
    xyz = data.xyz[src].copy()
    r = vertex_radius(robot.pose_length)
    xyz[vertex] += r * np.einsum("nij,nj->ni", data.orientation[src][vertex], VERTICES[k[vertex]])
    return replace(data, pose=data.pose[src], target=target, xyz=xyz, row=data.file_rows[src],
                   station=data.station[src], orientation=None,
                   relative=None if data.relative is None else data.relative.take(src))


@dataclass(frozen=True)
class Rows:
    """The measured rows of point data: G rows, each one measured point or the four vertices of one
    measured frame. group (R,) the row of each point; first (G,) its first point; vertex (R,) the
    vertex number of each point (-1: a measured point); weight (R,) and dof (R,) per point (1 and 3,
    or WEIGHT and DOF for a vertex); radius the vertices' distance r (m)."""

    group: np.ndarray
    first: np.ndarray
    vertex: np.ndarray
    weight: np.ndarray
    dof: np.ndarray
    radius: float

    @property
    def row_dof(self) -> np.ndarray:
        """(G,) degrees of freedom of each row: 3 for a point, 6 for a frame."""
        return np.bincount(self.group, self.dof, len(self.first))

    @property
    def oriented(self) -> np.ndarray:
        """(G,) True for a row that measures a frame."""
        return self.vertex[self.first] >= 0

    def signed(self, y: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per row, for measured points y and modelled points p (R, 3): the position error
        measured - modelled (G, 3) m, and the orientation error as a rotation vector in the
        measuring frame (G, 3) rad (NaN for a position-only row)."""
        G = len(self.first)
        d = y - p
        rotation = np.full((G, 3), np.nan)
        if G == len(d):  # one point per row (no frames): nothing to sum
            mean = np.empty((G, 3))
            mean[self.group] = d
            return mean, rotation
        mean = _sums(self.group, self.weight[:, None] * d, G)
        at = self.vertex >= 0
        if at.any():
            v = VERTICES[self.vertex[at]]
            My, Mp = (_sums(self.group[at], np.einsum("ni,nj->nij", x[at], v).reshape(-1, 9), G).reshape(G, 3, 3)
                      for x in (y, p))
            rows = self.oriented
            scale = 3 / (4 * self.radius)
            rotation[rows] = Rotation.from_matrix(scale ** 2 * My[rows] @ np.swapaxes(Mp[rows], 1, 2)).as_rotvec()
        return mean, rotation

    def errors(self, y: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per row, for measured points y and modelled points p (R, 3): the position error (G,) m,
        the orientation error angle (G,) rad (NaN for a position-only row) and the residual length
        sqrt(sum of weight |y - p|^2) (G,) m, which is sqrt(|e|^2 + L^2 (2 sin(theta/2))^2) for a frame."""
        mean, rotation = self.signed(y, p)
        e = np.linalg.norm(mean, axis=1)
        if len(self.first) == len(y):
            return e, rotation[:, 0], e
        d = y - p
        length = np.sqrt(np.bincount(self.group, self.weight * np.einsum("ni,ni->n", d, d), len(self.first)))
        return e, np.linalg.norm(rotation, axis=1), length


def _sums(group: np.ndarray, values: np.ndarray, G: int) -> np.ndarray:
    """(G, k) sums of values (R, k) over the rows of each group (R,); bincount, which is many
    times faster than np.add.at."""
    return np.column_stack([np.bincount(group, values[:, k], G) for k in range(values.shape[1])])


def measured_rows(robot: Robot, data: Measurements) -> Rows:
    """The measured rows of `data` on `robot` (one per pose and target of the robot's own; a robot
    without virtual targets has one row per point)."""
    names = robot.target_names
    origin = np.array([names.index(robot.vertex_of[t][0]) if t in robot.vertex_of else j for j, t in enumerate(names)])
    number = np.array([robot.vertex_of[t][1] if t in robot.vertex_of else -1 for t in names])
    _, first, group = np.unique(data.pose.astype(np.int64) * len(names) + origin[data.target], return_index=True,
                                return_inverse=True)
    vertex = number[data.target]
    dof = np.where(vertex >= 0, DOF, 3.0)
    if data.relative is not None:  # what a point's or plane's fitted unknowns leave of its rows
        dof = np.where(data.relative.rows, data.relative.row_dof(), dof)
    return Rows(group.ravel(), first, vertex, np.where(vertex >= 0, WEIGHT, 1.0), dof,
                vertex_radius(robot.pose_length))
