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
    on_path = [paths[robot.branch_of(name)] for name in robot.targets]  # the frames that move each target
    J = np.zeros((N, nt, 3, robot.n_frames + 1, 6))
    for j in range(robot.n_frames + 1):
        moves = np.array([j in path for path in on_path])
        if not moves.any():
            continue
        Rp, Rq = pre[j][:, :3, :3], post[j][:, :3, :3]
        es = eps[:, 6 * j + 3]
        er_axis = Rp[:, :, 0] * np.sin(es)[:, None] + Rp[:, :, 2] * np.cos(es)[:, None]  # R(W_j') Ry(es) z
        d = P - post[j][:, None, :3, 3]  # (N, nt, 3)
        block = J[:, :, :, j, :]  # (N, nt, 3, 6), a view
        block[:, :, :, :3] = Rp[:, None]
        for e, axis in enumerate((Rp[:, :, 1], er_axis, Rq[:, :, 0]), start=3):
            block[:, :, :, e] = np.cross(axis[:, None], d)
        block[:, ~moves] = 0.0
    return P, J.reshape(N, 3 * nt, ne)
