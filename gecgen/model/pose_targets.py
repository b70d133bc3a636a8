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

from dataclasses import replace

import numpy as np

from gecgen.model.measurements import Measurements
from gecgen.model.robot import LENGTH_M, Robot
from gecgen.model.rows import VERTICES, Vertices, vertex_radius
from gecgen.model.validation import require


def with_pose_targets(robot: Robot, length_m: float = LENGTH_M) -> Robot:
    """The robot with four virtual targets per target, `<target>__v1..v4` at t + r X v_k in the tool
    frame (r from the length scale L, m; X the measured frame's rotation in the tool frame,
    `Robot.target_frames`, else the identity), after the robot's own targets (whose indices stay)."""
    require(np.isfinite(length_m) and length_m > 0, f"--orientation-length {length_m!r}: give a positive length in "
                                                    f"m (1 rad of orientation error counts as this much position)")
    from scipy.spatial.transform import Rotation  # here: the option's help needs this module, not scipy

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
                   relative=None if data.relative is None else data.relative.take(src),
                   vertices=Vertices(data.target[src], np.where(vertex, k, -1), r))
