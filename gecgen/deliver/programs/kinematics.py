"""The controller's nominal kinematics: forward kinematics of the flange and a configuration-aware
numerical inverse, on the robot file's nominal model (serial chains).

Shapes: q (N, n) joint readings (m or rad); poses (N, 4, 4) in the robot's world frame, metres.
The flange is frame n of the robot file (after its last joint), turned by the frames file's
`flange` when the controller's flange differs from it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.model.kinematics import constant, frames, joint_motion, joint_values
from gecgen.model.robot import Robot

#: a pose the inverse kinematics reaches within this (m; 1 rad counts as 1 m) is reached
REACHED = 1e-10


@dataclass(frozen=True)
class Arm:
    """The nominal robot as the controller sees it: `flange` (4, 4) after frame n; `links` each joint's
    constant transforms before and after its motion (evaluated once: the solver calls `frames` often)."""

    robot: Robot
    flange: np.ndarray
    stretch: float  # the chain's joint-3 angle (rad) at which the arm is stretched (elbow neither up nor down)
    wrist_miss: float  # how far (m) axes 4, 5 and 6 pass from one common point: 0 for a spherical wrist
    links: tuple

    def frames(self, q) -> list[np.ndarray]:
        """The nominal frames 0..n (each (N, 4, 4)) at readings q (N, n): gecgen.model.kinematics.frames
        of a serial chain without errors."""
        v = joint_values(self.robot, np.atleast_2d(np.asarray(q, float)))
        out = [np.broadcast_to(self.links[0], (len(v), 4, 4))]
        for i, (joint, (pre, post)) in enumerate(zip(self.robot.chain, self.links[1:])):
            out.append(out[-1] @ pre @ joint_motion(joint.axis, joint.kind, v[:, i]) @ post)
        return out

    def axes(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Every joint's axis at readings q (N, n): a point on it (N, m, 3), m, and its unit direction
        (N, m, 3), in the world frame."""
        v = joint_values(self.robot, np.atleast_2d(np.asarray(q, float)))
        at, points, directions = np.broadcast_to(self.links[0], (len(v), 4, 4)), [], []
        for i, (joint, (pre, post)) in enumerate(zip(self.robot.chain, self.links[1:])):
            moving = at @ pre
            points.append(moving[:, :3, 3])
            directions.append(moving[:, :3, :3] @ np.asarray(joint.axis, float))
            at = moving @ joint_motion(joint.axis, joint.kind, v[:, i]) @ post
        return np.stack(points, axis=1), np.stack(directions, axis=1)

    def fk(self, q) -> np.ndarray:
        """Flange poses (N, 4, 4) at readings q (N, n)."""
        return self.frames(q)[-1] @ self.flange

    def ahead(self, q) -> np.ndarray:
        """(N,) how far (m) the wrist centre (the origin of frame 5, a spherical wrist's centre) is in
        front of axis 1: along frame 1's x axis from frame 0's origin."""
        F = self.frames(q)
        return np.einsum("ni,ni->n", F[5][:, :3, 3] - F[0][:, :3, 3], F[1][:, :3, 0])

    def chain(self, q) -> np.ndarray:
        """The chain's joint values (N, m): a coupled joint's through its readings."""
        return joint_values(self.robot, np.atleast_2d(np.asarray(q, float)))

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return (np.array([j.lower for j in self.robot.joints], float),
                np.array([j.upper for j in self.robot.joints], float))


def not_a_six_axis_arm(robot: Robot) -> str | None:
    """Why the controllers' programs here cannot be corrected for `robot` (one clause), or None for a
    serial arm of six revolute joints: their joint targets carry six axes and their configuration
    flags are defined for that arm."""
    prismatic = [j.name for j in robot.joints if j.kind != "R"]
    if robot.branches:
        return f"it branches into {len(robot.branches)} tools"
    if prismatic:
        return f"joint {prismatic[0]} is prismatic"
    if robot.n != 6:
        return f"it has {robot.n} axes"
    if robot.n_frames != 6:
        return f"it has {robot.n_frames - robot.n} passive joint(s) in its chain"
    return None


def arm_of(robot: Robot, flange: np.ndarray) -> Arm:
    """The controller's arm, with the joint-3 angle at which the wrist centre is farthest from the
    shoulder (frame 1's origin): the line between elbow up and elbow down."""
    grid = np.zeros((3601, robot.n))
    grid[:, 2] = np.linspace(-np.pi, np.pi, 3601)
    F = frames(robot, grid)
    reach = np.linalg.norm(F[5][:, :3, 3] - F[1][:, :3, 3], axis=1)
    links = (constant(robot.base),) + tuple((constant(j.pre), constant(j.post)) for j in robot.chain)
    arm = Arm(robot, np.asarray(flange, float), float(joint_values(robot, grid)[np.argmax(reach), 2]), 0.0, links)
    return replace(arm, wrist_miss=_wrist_miss(arm))


def _wrist_miss(arm: Arm) -> float:
    """The largest distance (m) of axes 4, 5 and 6 from their nearest common point over a few postures
    (axis 5 bent, so that 4 and 6 are not one line): the controllers' configuration flags single out one
    posture per pose only when the wrist's axes meet, as on the arms they are defined for."""
    q = np.radians([[0, 0, 0, 0, 40, 0], [30, -20, 15, 60, -70, 20], [-50, 25, -30, -120, 110, 90]])
    points, directions = arm.axes(q)
    p, d = points[:, 3:6], directions[:, 3:6]
    across = np.eye(3) - d[..., :, None] * d[..., None, :]  # (N, 3, 3, 3): each axis's perpendicular projector
    common = np.linalg.solve(across.sum(axis=1), np.einsum("nkij,nkj->ni", across, p)[..., None])[..., 0]
    return float(np.max(np.linalg.norm(np.einsum("nkij,nkj->nki", across, common[:, None] - p), axis=-1)))


def wrapped(angle: np.ndarray) -> np.ndarray:
    """angle (rad) in [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def front(arm: Arm, q) -> np.ndarray:
    """(N,) bool: the wrist centre is in front of axis 1 (along frame 1's x axis)."""
    return arm.ahead(q) >= 0


def elbow_up(arm: Arm, q) -> np.ndarray:
    """(N,) bool: the chain's joint 3 is at or above its stretched angle (the joint's own value, not
    wrapped: a controller compares the angle it reads)."""
    return arm.chain(q)[:, 2] - arm.stretch >= 0


def pose_error(goal: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(N, 6): position difference (m) and the rotation vector (rad) taking T to goal."""
    turn = Rotation.from_matrix(goal[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2)).as_rotvec()
    return np.concatenate([goal[..., :3, 3] - T[..., :3, 3], turn], axis=-1)


def solve(arm: Arm, goal: np.ndarray, seeds: np.ndarray, iterations: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Damped Newton from each seed (K, n) toward one flange goal (4, 4): the joints (K, n) and the
    pose error left (K,) (m, 1 rad as 1 m). Joints are not clipped: limits are checked by the caller."""
    seeds = np.array(seeds, float)
    q = seeds.copy()
    n, h = q.shape[1], 1e-7
    goals = np.broadcast_to(goal, (len(q), 4, 4))
    for _ in range(iterations):
        err = pose_error(goals, arm.fk(q))
        left = np.linalg.norm(err, axis=1)
        todo = left > REACHED
        if not todo.any():
            break
        J = np.stack([(pose_error(goals, arm.fk(q + h * np.eye(n)[j])) - err) / h for j in range(n)], axis=2)
        damping = 1e-6 * np.minimum(left, 1.0)[:, None, None] * np.eye(6)
        JJ = np.einsum("kij,klj->kil", J, J) + damping
        step = -np.einsum("kji,kj->ki", J, np.linalg.solve(JJ, err[..., None])[..., 0])
        # a long step near a singular posture throws the joints turns away from the seed's configuration
        step *= np.minimum(1.0, 0.3 / np.maximum(np.max(np.abs(step), axis=1), 1e-300))[:, None]
        q = np.where(todo[:, None], q + step, q)
    q = seeds + wrapped(q - seeds)  # the same turn of each joint, nearest the seed
    return q, np.linalg.norm(pose_error(goals, arm.fk(q)), axis=1)


@dataclass(frozen=True)
class Seeds:
    """A fixed grid of postures over the joint limits with their flange poses: the starting points of
    the inverse kinematics (the nearest ones of the configuration a target names)."""

    q: np.ndarray
    poses: np.ndarray
    configs: np.ndarray | None  # (K, c) the configuration of each, None for a controller without


def seed_grid(arm: Arm, config: Callable[[np.ndarray], np.ndarray] | None) -> Seeds:
    """Postures spanning the limits: 8 steps on axis 1, 5 on axes 2 and 3, every 45 deg quadrant
    centre on axes 4 and 6 within their limits, and 4 on axis 5."""
    lo, hi = arm.limits()
    axes = []
    for j, count in enumerate((8, 5, 5, None, 4, None)):
        if count is None:  # a wrist axis: the centre of every quadrant it reaches
            centres = np.deg2rad(np.arange(-315.0, 316.0, 90.0))
            inside = centres[(centres > lo[j]) & (centres < hi[j])]
            axes.append(inside if len(inside) else np.array([(lo[j] + hi[j]) / 2]))
        else:
            axes.append(lo[j] + (hi[j] - lo[j]) * (np.arange(count) + 0.5) / count)
    q = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 6)
    return Seeds(q, arm.fk(q), None if config is None else config(q))


def inverse(arm: Arm, goal: np.ndarray, seeds: Seeds, config: Callable[[np.ndarray], np.ndarray] | None,
            wanted=None, near: np.ndarray | None = None, tries: int = 8) -> np.ndarray | None:
    """The joints (n,) inside the limits that put the flange at goal (4, 4) in the configuration
    `wanted` (config(q) maps (K, n) to (K, c)); with `near` (n,), the solution nearest those joints
    (seeded there first). None when no seed reaches the goal in that configuration."""
    lo, hi = arm.limits()
    starts = [] if near is None else [np.asarray(near, float)[None]]
    pool = seeds.q
    poses = seeds.poses
    if config is not None:
        keep = np.all(seeds.configs == np.asarray(wanted), axis=1)
        pool, poses = pool[keep], poses[keep]
    if len(pool):
        # position, and orientation as the chord between rotations (cheap, and monotonic in the angle)
        distance = (np.linalg.norm(poses[:, :3, 3] - goal[:3, 3], axis=1)
                    + np.linalg.norm(poses[:, :3, :3] - goal[:3, :3], axis=(1, 2)))
        starts.append(pool[np.argsort(distance)[:tries]])
    if not starts:
        return None
    q, left = solve(arm, goal, np.concatenate(starts))
    ok = (left <= 1e3 * REACHED) & np.all((q >= lo - 1e-9) & (q <= hi + 1e-9), axis=1)
    if config is not None:
        ok &= np.all(config(q) == np.asarray(wanted), axis=1)
    if not ok.any():
        return None
    q = q[ok]
    if near is None:
        return q[0]
    return q[np.argmin(np.linalg.norm(q - near, axis=1))]
