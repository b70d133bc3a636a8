"""The linear least squares at a fit: H_e over the kept coefficients and the residual, weighted as
the robust fit left them, and J_e, from which the column of any new term on any generalized error
follows (J[:, e] times the term). diagnose screens candidates in it; the ratio check compares fits
with and without loads in it."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.errors import ErrorModel
from gecgen.model.measurements import Measurements
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import Fit, rows_H_and_residual


@dataclass
class Round:
    model: ErrorModel
    cm: CompiledModel
    fit: Fit


def linear_system(rnd: Round, data: Measurements, y: np.ndarray):
    """H over the kept columns and the residual, rows scaled by the robust fit's point weights, so
    a glitch neither passes for an effect nor hides one."""
    H, r = zip(*rows_H_and_residual(rnd.cm, data, y, rnd.fit.c, weights=rnd.fit.weights))
    return np.vstack(H)[:, list(rnd.fit.redundancy.kept)], np.concatenate(r)


def pose_rows(data: Measurements) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row of the linear system: its pose (3R,) and degrees of freedom (3R,; 1, or 1/2 for a
    coordinate of a measured frame's vertex); and the point order rows_H_and_residual yields."""
    order = np.argsort(data.pose, kind="stable")
    return np.repeat(data.pose[order], 3), np.repeat(data.rows.dof[order] / 3, 3), order


def weighted_J(rnd: Round, data: Measurements, order: np.ndarray) -> np.ndarray:
    """J_e at the fitted point, d(position)/d(eps) (3R, ne), its rows in `pose_rows`'s order and
    weighted as `linear_system`'s H and r are: a term t on error e adds the column J[:, e] t."""
    eps = rnd.cm.eps(data.q, data.w, data.aux_columns(rnd.model.aux), rnd.fit.c)
    _, Jall = rnd.cm.J_e(data.q, eps)
    ne = rnd.cm.robot.n_errors
    J = Jall.reshape(data.n_poses, -1, 3, ne)[data.pose[order], data.target[order]].reshape(-1, ne)
    return J * np.repeat(np.sqrt(rnd.fit.weights[order]), 3)[:, None]
