"""The exact nonlinear chain with generalized errors, in plain numpy (batched over poses).

This is the independent reference for the generated code (finite differences of these
functions check `J_e`) and the truth model of the simulator. Shapes: q (N, n) the joint
variables, eps (N, 6(m+1)) or (6(m+1),) over the m moving frames; transforms (N, 4, 4); lengths
in m, angles in rad.
"""
from __future__ import annotations

import functools

import numpy as np

from gecgen.model.robot import Elementary, Robot


def _rot(axis: int, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros(angle.shape + (4, 4))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., 3, 3] = 1.0
    R[..., i, i], R[..., i, j], R[..., j, i], R[..., j, j] = c, -s, s, c
    return R


def _trans(vec: np.ndarray) -> np.ndarray:
    T = np.broadcast_to(np.eye(4), vec.shape[:-1] + (4, 4)).copy()
    T[..., :3, 3] = vec
    return T


def elementary(op: Elementary) -> np.ndarray:
    """4x4 matrix of one constant elementary transform."""
    kind, value = op
    if kind == "H":
        return np.array([[float(v) for v in row] for row in value])
    if kind[0] == "T":
        return _trans(np.eye(3)["xyz".index(kind[1])] * float(value))
    return _rot("xyz".index(kind[1]), np.array(float(value)))


def constant(ops: tuple[Elementary, ...]) -> np.ndarray:
    T = np.eye(4)
    for op in ops:
        T = T @ elementary(op)
    return T


@functools.lru_cache(maxsize=1024)
def _fixed(ops: tuple[Elementary, ...]) -> np.ndarray:
    """`constant(ops)`, computed once per process and read-only: the chain is walked again at every
    step of a fit."""
    T = constant(ops)
    T.setflags(write=False)
    return T


def error_transform(e: np.ndarray) -> np.ndarray:
    """E = Trans(ex, ey, ez) RotY(es) RotZ(er) RotX(ep) for e (..., 6)."""
    return _trans(e[..., :3]) @ _rot(1, e[..., 3]) @ _rot(2, e[..., 4]) @ _rot(0, e[..., 5])


def joint_motion(axis, kind: str, q: np.ndarray) -> np.ndarray:
    """M(q): rotation by q about the unit axis (Rodrigues) or translation q * axis."""
    u = np.array([float(a) for a in axis])
    if kind == "P":
        return _trans(q[..., None] * u)
    c, s = np.cos(q)[..., None, None], np.sin(q)[..., None, None]
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    M = np.broadcast_to(np.eye(4), q.shape + (4, 4)).copy()
    M[..., :3, :3] = c * np.eye(3) + s * K + (1 - c) * np.outer(u, u)
    return M


def joint_values(robot: Robot, q: np.ndarray) -> np.ndarray:
    """The value of every frame's joint (N, m) at the readings q (N, n): a coupled joint's is the
    sum of multiplier * q_k plus its offset."""
    return np.column_stack([q[:, terms[0][0]] if joint.coupling is None else
                            sum(float(m) * q[:, k] for k, m in terms) + float(o)
                            for joint, (terms, o) in zip(robot.chain, robot.drives())])


def chain_frames(robot: Robot, q: np.ndarray, eps: np.ndarray | None = None
                 ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """World transforms of frames 0..m before (W_j') and after (W_j) their generalized errors, and
    the tool of each branch (one on a serial chain), each (N, 4, 4): W_j = W_j' E(eps_j), W_j' =
    W_parent(j) Pre_j M_j(q) Post_j, W_0' the base."""
    q = np.atleast_2d(np.asarray(q, float))
    N = q.shape[0]
    eps = np.zeros((N, robot.n_errors)) if eps is None else np.broadcast_to(eps, (N, robot.n_errors))
    pre = [np.broadcast_to(_fixed(robot.base), (N, 4, 4))]
    post = [pre[0] @ error_transform(eps[:, 0:6])]
    v = joint_values(robot, q)
    for i, joint in enumerate(robot.chain):
        A = _fixed(joint.pre) @ joint_motion(joint.axis, joint.kind, v[:, i]) @ _fixed(joint.post)
        pre.append(post[robot.parent(i + 1)] @ A)
        post.append(pre[-1] @ error_transform(eps[:, 6 * (i + 1):6 * (i + 2)]))
    return pre, post, [post[tip] @ _fixed(tool) for tip, tool in robot.tips()]


def frames(robot: Robot, q: np.ndarray, eps: np.ndarray | None = None) -> list[np.ndarray]:
    """World transforms W_0..W_m (after each frame's errors) and the tool of each branch (one on a
    serial chain), each (N, 4, 4)."""
    _, post, tools = chain_frames(robot, q, eps)
    return post + tools


def tool_poses(robot: Robot, q: np.ndarray, eps: np.ndarray | None = None) -> list[np.ndarray]:
    """World pose of each branch's tool frame (one on a serial chain), each (N, 4, 4)."""
    return frames(robot, q, eps)[robot.n_frames + 1:]


def tool_pose(robot: Robot, q: np.ndarray, eps: np.ndarray | None = None) -> np.ndarray:
    """World pose of the tool frame (on a tree, the first branch's), (N, 4, 4)."""
    return tool_poses(robot, q, eps)[0]


def target_positions(robot: Robot, q: np.ndarray, eps: np.ndarray | None = None) -> np.ndarray:
    """World positions of every target, (N, n_targets, 3) in target-file order."""
    return targets_of(robot, tool_poses(robot, q, eps))


def targets_of(robot: Robot, tools: list[np.ndarray]) -> np.ndarray:
    """World positions of every target (N, n_targets, 3) from each branch's tool pose (N, 4, 4)."""
    t = np.array(list(robot.targets.values()))  # (nt, 3)
    if len(tools) == 1:
        return np.einsum("nij,kj->nki", tools[0][:, :3, :3], t) + tools[0][:, None, :3, 3]
    T = np.stack([tools[robot.branch_of(name)] for name in robot.targets], axis=1)  # (N, nt, 4, 4)
    return np.einsum("nkij,kj->nki", T[..., :3, :3], t) + T[..., :3, 3]


def sensor_wrench(robot: Robot, q: np.ndarray, payload_kg: np.ndarray, payload_at: np.ndarray,
                  gravity: np.ndarray, eps: np.ndarray | None = None) -> np.ndarray:
    """What a force/torque sensor in robot.wrench_frame reads for a payload (N, 6): [F; r x F] in the
    sensor frame, r the payload point (tool frame, m) relative to the sensor. On a tree the payload
    hangs from the first branch's tool."""
    F = frames(robot, q, eps)
    tool = F[robot.n_frames + 1]
    S = tool if robot.wrench_frame == "tool" else F[robot.wrench_frame]
    force_world = payload_kg[:, None] * gravity
    force = np.einsum("nji,nj->ni", S[:, :3, :3], force_world)
    point_world = np.einsum("nij,j->ni", tool[:, :3, :3], payload_at) + tool[:, :3, 3]
    r = np.einsum("nji,nj->ni", S[:, :3, :3], point_world - S[:, :3, 3])
    return np.column_stack([force, np.cross(r, force)])
