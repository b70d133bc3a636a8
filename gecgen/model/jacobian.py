"""J_e, the derivative of the target positions in the generalized errors, in numpy (batched over poses).

The same structure the generated code prints (`symbolic.chain.jacobian_function`): the error E_j
enters the chain at frame j only, so its effect on a target P is a rigid motion of everything after
frame j. With W_j' the world pose of frame j before its error and o_j its origin after it,

    dP/d(ex, ey, ez)_j = columns of R(W_j')
    dP/d(es, er, ep)_j = a x (P - o_j),  a = R(W_j') y,  R(W_j') Ry(es) z,  R(W_j) x

exact at any error values, and zero for the frames that do not move P (on a tree, the other
branches). Couplings, passive and prismatic joints enter through the chain's poses alone
(`model.kinematics.chain_frames`).
"""
from __future__ import annotations

import numpy as np

from gecgen.model.kinematics import chain_frames, targets_of
from gecgen.model.robot import Robot


def target_jacobian(robot: Robot, q: np.ndarray, eps: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Target positions p (N, nt, 3) in m, and J_e (N, 3 nt, 6 (m + 1)) (m per m, m per rad), row
    3 k + i the coordinate i of target k, column 6 j + e error e (ex ey ez es er ep) of frame j, at
    joints q (N, n) (m or rad) and errors eps (N, 6 (m + 1)) or (6 (m + 1),) (None: the nominal chain)."""
    q = np.atleast_2d(np.asarray(q, float))
    N, ne, nt = q.shape[0], robot.n_errors, len(robot.targets)
    eps = np.zeros((N, ne)) if eps is None else np.broadcast_to(np.asarray(eps, float), (N, ne))
    pre, post, tools = chain_frames(robot, q, eps)
    P = targets_of(robot, tools)
    paths = [set(robot.path(tip)) for tip, _ in robot.tips()]
    # moves[j, k]: frame j moves target k (on a tree, the frames of its own branch and the trunk)
    moves = np.array([[j in paths[robot.branch_of(name)] for name in robot.targets] for j in range(robot.n_frames + 1)])
    Rp, Wq = np.stack(pre, axis=1)[..., :3, :3], np.stack(post, axis=1)  # (N, F, 3, 3), (N, F, 4, 4)
    es = eps.reshape(N, -1, 6)[..., 3]
    er_axis = Rp[..., 0] * np.sin(es)[..., None] + Rp[..., 2] * np.cos(es)[..., None]  # R(W_j') Ry(es) z
    axes = np.stack([Rp[..., 1], er_axis, Wq[..., :3, 0]], axis=2)  # (N, F, 3 rotations, 3)
    d = P[:, None] - Wq[:, :, None, :3, 3]  # (N, F, nt, 3): each target from each frame's origin
    a, b = axes[:, :, None], d[:, :, :, None]  # (N, F, 1, 3, 3), (N, F, nt, 1, 3)
    turns = np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                      a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)  # (N, F, nt, 3 rotations, xyz)
    J = np.empty((N, robot.n_frames + 1, nt, 6, 3))  # [pose, frame, target, error, xyz]
    J[..., :3, :] = Rp.transpose(0, 1, 3, 2)[:, :, None]  # translation e along R(W_j') column e
    J[..., 3:, :] = turns
    J *= moves[None, :, :, None, None]
    return P, J.transpose(0, 2, 4, 1, 3).reshape(N, 3 * nt, ne)
