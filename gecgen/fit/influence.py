"""Leave one pose out: the pose the other poses do not predict, and the joint reading that explains it.

A joint-encoder glitch (one pose's reading off by a few hundredths of a radian) moves every target
of that pose along the joint's column of the pose Jacobian. The fit has k coefficients for m
measured coordinates, so it bends towards the pose (its leverage) and the residual left at the pose
can stay below the outlier limit (`fit.robust`) while the coefficients carry the glitch: on
figaroh's 23 UR10 poses a 0.02 rad glitch of one reading leaves a 14 mm residual, under the 15 mm
limit, and raises the RMS from 2.7 to 4.6 mm.

The deleted residual undoes the masking: d_i = (I - L_i)^{-1} r_i is the pose's residual under the
fit to the other poses (exact for the linearised problem; L_i = A_i (A^T A)^{-1} A_i^T the pose's
block of the hat matrix, r_i its residual rows), and r_i^T d_i is what leaving the pose out takes
from the residual sum of squares. Its statistic F_i = (r_i^T d_i / f_i) / s_(i)^2, with f_i the
pose's degrees of freedom and s_(i)^2 the residual variance without it, follows F(f_i, m - k - f_i)
under Gaussian noise.

Misfit (an effect the model lacks) and noise that is not independent per coordinate (a robot's
repeatability moves all targets of a pose together) raise F too, at many poses at once. Measured over
121 fits of simulated robots (industrial6r, panda, fanuc, puma560 and pps; 30 to 150 poses; points
and frames; default and constant models), the largest F reaches 24 and most data sets have a pose
past any significance test, but the largest F was never more than 5.1 times the second largest. A
glitch stands alone: 0.02 rad on q2 of one of figaroh's 23 UR10 poses gives F 29 against 2.3 (12.7
times), 0.05 rad 26 times. So a pose is a suspect when it is significant (F's p-value times the
number of poses below ALPHA) and stands GAP times above the next pose. The price: a smaller glitch,
or one on a joint that moves the targets less, goes unnamed (0.02 rad on the base joint of one UR10
pose: 2.9 times), as it is hard to tell from misfit.
"""
from __future__ import annotations

import numpy as np
from scipy import special  # not scipy.stats: see fit.robust
from scipy.linalg import solve_triangular

#: Bonferroni-corrected p-value below which a pose's deleted residual is significant
ALPHA = 1e-3
#: a suspect pose's F is at least this many times the next pose's (see the module docstring)
GAP = 6.0
#: a joint reading "explains" a deleted residual when its column carries this share of its square
EXPLAINED = 0.9


def deleted_residuals(blocks, row_pose: np.ndarray, Rk: np.ndarray, n_poses: int) -> tuple[np.ndarray, np.ndarray]:
    """Per pose, what leaving it out takes from the residual sum of squares, r_i^T d_i (P,) m^2, and
    the deleted residual rows d (M,) m, for the streamed blocks (A (rows, k) scaled like Rk, r (rows,))
    of the final linear system, whose R factor over the kept columns is Rk (k, k). row_pose (M,)
    gives each row's pose; a block holds whole poses."""
    drop = np.zeros(n_poses)
    d, start = [], 0
    for A, r in blocks:
        U = solve_triangular(Rk, A.T, trans="T").T  # A Rk^-1: each pose's hat block is U_i U_i^T
        poses = row_pose[start:start + len(r)]
        di = np.empty_like(r)
        # poses with the same number of rows are solved together: a batch of small systems
        bounds = np.flatnonzero(np.diff(poses, prepend=-1, append=-1))  # rows of a pose are contiguous
        first, size = bounds[:-1], np.diff(bounds)
        for n in np.unique(size):
            rows = first[size == n][:, None] + np.arange(n)  # (poses, n)
            Ui, ri = U[rows], r[rows]
            I_L = np.eye(n) - Ui @ np.swapaxes(Ui, 1, 2)
            di[rows] = np.linalg.solve(I_L, ri[..., None])[..., 0]
            drop[poses[rows[:, 0]]] = np.einsum("pi,pi->p", ri, di[rows])
        d.append(di)
        start += len(r)
    return drop, np.concatenate(d)


def suspects(drop: np.ndarray, dof: np.ndarray, rss: float, m: float, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The suspect poses (indices, largest F first) and every pose's F (P,), from what leaving each
    out takes from the residual sum of squares rss (drop, m^2), its degrees of freedom (dof, P), and
    the data's m degrees of freedom for k coefficients. At most a twentieth of the poses (and one)
    can be suspects: more is misfit, not glitches."""
    rest = np.maximum(m - k - dof, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        F = np.where(dof > 0, drop / dof / np.maximum((rss - drop) / rest, np.finfo(float).tiny), 0.0)
    p = special.fdtrc(np.maximum(dof, 1), rest, F) * len(F)  # the F law's survival function
    order = np.argsort(-F)
    for j in range(min(max(1, len(F) // 20), len(F) - 1), 0, -1):
        if F[order[j - 1]] >= GAP * F[order[j]] and np.all(p[order[:j]] < ALPHA):
            return order[:j], F
    return order[:0], F


def joint_turn(G: np.ndarray, d: np.ndarray) -> tuple[int, float, float]:
    """The reading whose turn best explains a pose's deleted residual d (rows,): (its index, the
    turn (rad or m), the share of |d|^2 it explains), for the pose's reading columns G (rows, n)."""
    norm = np.maximum(np.einsum("ij,ij->j", G, G), np.finfo(float).tiny)
    along = G.T @ d
    share = along ** 2 / norm / max(float(d @ d), np.finfo(float).tiny)
    j = int(np.argmax(share))
    return j, float(along[j] / norm[j]), float(share[j])
