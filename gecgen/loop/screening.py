"""The statistics of diagnose: how much a candidate effect explains, whether that is more than
chance among everything tried, and whether it predicts poses it was not fitted on.

The linear system is the current fit's, linearised: H (3R, k) over the kept coefficients and the
residual r (3R,), rows scaled by the robust fit's point weights. rows_dof (3R,), where given, is
the degrees of freedom each row carries: 1, or 1/2 for a coordinate of a measured frame's vertex
(`model.pose_targets`), whose twelve coordinates hold six; None means 1 everywhere. A candidate group of terms f for
generalized error e adds the columns J_e[:, e] * f(pose). Its worth is the drop in the residual sum
of squares once the current model's columns are projected out; its significance is that drop
against the residual variance as a chi-square with as many degrees of freedom as it has columns,
so a group of ten load columns is not preferred over one sinusoid for its size alone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

#: family-wise false-alarm rate of one screening round
ALPHA = 1e-3
#: a candidate must lower the cross-validated RMS by at least this fraction
MIN_CV_GAIN = 0.01
FOLDS = 5
#: a candidate's columns must keep this share of their squared norm outside the current model
MIN_INDEPENDENCE = 1e-6
#: candidates tried, most significant first, before a tier is declared empty
TRIES = 8


@dataclass(frozen=True)
class Candidate:
    """A group of new terms, all in the variables `variables`, tested as one: its columns together,
    as many degrees of freedom as terms. `errors` restricts it to those generalized errors (eps
    indices); None offers it to every error."""

    family: str
    variables: tuple[str, ...]
    terms: tuple[str, ...]
    values: np.ndarray  # (P, len(terms)) term values per pose
    errors: tuple[int, ...] | None = None

    @property
    def dof(self) -> int:
        return len(self.terms)


@dataclass(frozen=True)
class Hit:
    """A (candidate, error) pair that explains part of the residual: the drop in the residual sum
    of squares (m^2), log of its chi-square p-value, and the fitted effect projected out of the
    current model (3R,)."""

    drop: float
    log_p: float
    candidate: int
    error: int
    fitted: np.ndarray


def screen(J: np.ndarray, rows_pose: np.ndarray, resid: np.ndarray, Q: np.ndarray, sigma2: float,
           cands: list[Candidate], errors: list[int]) -> list[Hit]:
    """Every (candidate, error) pair that explains more than noise would, most significant first.

    J (3R, ne) is J_e at the current fit for the measured rows; rows_pose (3R,) the pose of each
    row; resid (3R,) is orthogonal to the columns of Q (3R, k); sigma2 the residual variance per
    coordinate (m^2)."""
    results = []
    F = np.concatenate([c.values for c in cands], axis=1)[rows_pose]  # (3R, total columns)
    starts = np.cumsum([0] + [c.values.shape[1] for c in cands])
    for e in errors:
        offered = [ci for ci, c in enumerate(cands) if c.errors is None or e in c.errors]
        if not offered:
            continue
        # column-major: each candidate's columns are then contiguous, and its Gram matrix one small
        # product over contiguous memory (row-major, thousands of poses made it the bottleneck)
        X = np.multiply(J[:, e:e + 1], F, order="F")  # all candidate columns for error e
        if not np.any(X):
            continue
        QtX = Q.T @ X
        rX = resid @ X
        for ci in offered:
            s = slice(starts[ci], starts[ci + 1])
            Xs = X[:, s]
            XtX = Xs.T @ Xs
            G = XtX - QtX[:, s].T @ QtX[:, s]  # Gram matrix of the projected columns
            scale = np.sqrt(np.maximum(np.diag(XtX), 1e-300))
            Gs = G / np.outer(scale, scale)
            if np.linalg.eigvalsh(Gs).min() < MIN_INDEPENDENCE:
                continue  # (nearly) inside the current model: nothing new to add
            b = rX[s] / scale
            beta = np.linalg.solve(Gs, b)
            drop = float(b @ beta)
            dof = cands[ci].dof
            if drop > max(9, 3 * dof) * sigma2:  # cheap pre-filter; the real test follows
                v = beta / scale  # the fitted effect, projected off the model: R x (c + k), not R x k x c
                fitted = Xs @ v - Q @ (QtX[:, s] @ v)
                results.append(Hit(drop, float(stats.chi2.logsf(drop / max(sigma2, 1e-300), dof)), ci, e, fitted))
    results.sort(key=lambda h: h.log_p)
    return results


def folds(n_poses: int, rng: np.random.Generator) -> np.ndarray:
    """Fold number of each pose (P,): folds split poses, never the targets of one pose."""
    return rng.permutation(n_poses) % FOLDS


def _held_out_sq(X: np.ndarray, r: np.ndarray, test: np.ndarray) -> float:
    """Squared error on the `test` rows of the correction X dc ~ r fitted on the other rows."""
    scale = np.maximum(np.linalg.norm(X[~test], axis=0), 1e-300)
    dc = np.linalg.lstsq(X[~test] / scale, r[~test], rcond=None)[0] / scale
    return float(np.sum((r[test] - X[test] @ dc) ** 2))


def _dof(rows_dof: np.ndarray | None, r: np.ndarray, rows=slice(None)) -> float:
    """Degrees of freedom of the rows `rows` of r."""
    return float(len(r[rows]) if rows_dof is None else rows_dof[rows].sum())


def cv_rms(H: np.ndarray, r: np.ndarray, rows_pose: np.ndarray, fold: np.ndarray,
           rows_dof: np.ndarray | None = None) -> float:
    """k-fold cross-validated RMS point error (m) of a linear correction H dc ~ r (3R rows), per
    three degrees of freedom."""
    sq = sum(_held_out_sq(H, r, fold[rows_pose] == f) for f in range(FOLDS))
    return float(np.sqrt(sq / (_dof(rows_dof, r) / 3)))


def columns(J: np.ndarray, cand: Candidate, error: int, rows_pose: np.ndarray) -> np.ndarray:
    """The new columns (3R, dof) of a candidate on one generalized error."""
    return J[:, error:error + 1] * cand.values[rows_pose]


def selection_cv_rms(J: np.ndarray, H: np.ndarray, r: np.ndarray, rows_pose: np.ndarray, fold: np.ndarray,
                     cands: list[Candidate], shortlist: list[tuple[int, int]],
                     rows_dof: np.ndarray | None = None) -> float:
    """k-fold cross-validated RMS point error (m) of the choice itself: in each fold the screening
    runs on the training part alone, its most significant candidate is added, and the held-out
    poses are predicted. The best of thousands of candidates always fits the poses it was picked on
    better than new ones; only an effect that wins on the other folds' poses too is real. The folds
    choose among `shortlist`, the (candidate, error) pairs strongest on all poses: a pair far down
    that list does not win on four fifths of them."""
    by_error: dict[int, list[int]] = {}
    for ci, e in shortlist:
        by_error.setdefault(e, []).append(ci)
    sq = 0.0
    for f in range(FOLDS):
        test = fold[rows_pose] == f
        Ht, rt = H[~test], r[~test]
        Q = np.linalg.qr(Ht / np.maximum(np.linalg.norm(Ht, axis=0), 1e-300))[0]
        resid = rt - Q @ (Q.T @ rt)
        sigma2 = float(resid @ resid) / max(_dof(rows_dof, r, ~test) - H.shape[1], 1)
        Jt, pt = J[~test], rows_pose[~test]  # once per fold: the copies are large at thousands of poses
        hits = [(h.log_p, cis[h.candidate], e) for e, cis in by_error.items()
                for h in screen(Jt, pt, resid, Q, sigma2, [cands[k] for k in cis], [e])]
        best = min(hits, default=None)
        X = H if best is None else np.column_stack([H, columns(J, cands[best[1]], best[2], rows_pose)])
        sq += _held_out_sq(X, r, test)
    return float(np.sqrt(sq / (_dof(rows_dof, r) / 3)))


def passing(found: list[Hit], cands: list[Candidate], J, H, r, rows_pose, fold, n_tests: int, base_cv: float,
            rows_dof: np.ndarray | None = None):
    """The candidates, most significant first (at most TRIES), that pass the chi-square test with a
    Bonferroni correction for `n_tests` and lower the cross-validated RMS: [(hit, p, cv), ...]."""
    out = []
    for hit in found[:TRIES]:
        p = float(np.exp(hit.log_p))
        if hit.log_p + np.log(n_tests) > np.log(ALPHA):
            break  # sorted by significance: nothing further can pass either
        cv = cv_rms(np.column_stack([H, columns(J, cands[hit.candidate], hit.error, rows_pose)]), r, rows_pose, fold,
                    rows_dof)
        if cv < (1 - MIN_CV_GAIN) * base_cv:
            out.append((hit, p, cv))
    return out
