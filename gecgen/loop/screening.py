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

from dataclasses import dataclass, field, replace

import numpy as np
from scipy import linalg, sparse, special

#: family-wise false-alarm rate of one screening round
ALPHA = 1e-3
#: a candidate must lower the cross-validated RMS by at least this fraction
MIN_CV_GAIN = 0.01
FOLDS = 5
#: a candidate's columns must keep this share of their squared norm outside the current model
MIN_INDEPENDENCE = 1e-6
#: candidates tried, most significant first, before a tier is declared empty
TRIES = 8
#: eigenvalues of a unit-diagonal Gram matrix below this (its rounding level) count as zero
SINGULAR_GRAM = 1e-13


def chi2_logsf(x: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """log P(chi-square with dof degrees of freedom > x), elementwise, as scipy.stats.chi2.logsf
    computes it to the last bit: log of the upper tail above the median, log1p of minus the lower
    tail below it (each accurate where it is small). From scipy.special, whose import is a tenth
    of scipy.stats's (about 0.4 s of every diagnose and calibrate)."""
    x, dof = np.broadcast_arrays(np.asarray(x, float), np.asarray(dof, float))
    out = np.zeros(x.shape)  # x <= 0: the whole law lies above
    above = x > 2 * special.gammaincinv(dof / 2, 0.5)  # the median
    below = ~above & (x > 0) | np.isnan(x)
    with np.errstate(divide="ignore"):
        out[above] = np.log(special.chdtrc(dof[above], x[above]))
        out[below] = np.log1p(-special.chdtr(dof[below], x[below]))
    return out


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
class Basis:
    """An orthonormal basis Q = B R^-1 (3R, k) of the current model's columns B (3R, k), kept as B
    and R, the triangular factor of B's QR: Q itself is never formed, which would cost 3R k^2
    multiply-adds per fold and round."""

    B: np.ndarray
    R: np.ndarray

    def project(self, BtY: np.ndarray) -> np.ndarray:
        """Q^T Y (k, ...) from B^T Y."""
        return linalg.solve_triangular(self.R, BtY, trans="T")

    def span(self, z: np.ndarray) -> np.ndarray:
        """Q z (3R,) for z (k,)."""
        return self.B @ linalg.solve_triangular(self.R, z)

    def residual(self, r: np.ndarray) -> np.ndarray:
        """r less its projection on the columns (3R,)."""
        return r - self.span(self.project(self.B.T @ r))


def basis(B: np.ndarray, R_blocks: list[np.ndarray]) -> Basis:
    """The Basis of B (3R, k) from the R factors of blocks of its rows (their QR stacked gives
    B's); when B is (numerically) rank-deficient Q is formed explicitly (R = I)."""
    R = np.linalg.qr(np.vstack(R_blocks), mode="r")
    d = np.abs(np.diag(R))
    if len(d) < B.shape[1] or d.min() <= 1e-10 * d.max():
        Q = np.linalg.qr(B)[0]  # (3R, min(3R, k))
        return Basis(Q, np.eye(Q.shape[1]))
    return Basis(B, R)


@dataclass(slots=True)  # not frozen: there are hundreds of thousands a round, and a frozen one takes 4x to make
class Hit:
    """A (candidate, error) pair that explains part of the residual: the drop in the residual sum
    of squares (m^2) and log of its chi-square p-value. `parts` hold what its fitted effect is made
    of; most hits are never looked at again, so it is formed only when asked for."""

    drop: float
    log_p: float
    candidate: int
    error: int
    # (J_e (3R, ne), F (G, columns), the candidate's columns of F (a, b), v (dof,), group (3R,), Basis,
    # Q^T X of the error (k, its columns), the candidate's among them (dof,)): the products are formed
    # when asked for, most hits never are
    parts: tuple = field(repr=False, compare=False)

    @property
    def fitted(self) -> np.ndarray:
        """The fitted effect projected off the current model (3R,): J_e (F v) - Q (Q^T X v), R x (c + k)."""
        J, F, (a, b), v, group, base, QtX, cols = self.parts
        return J[:, self.error] * (F[:, a:b] @ v)[group] - base.span(QtX[:, cols] @ v)


def _pose_sums(rows_pose: np.ndarray) -> tuple[sparse.csr_matrix, np.ndarray, np.ndarray]:
    """The sum over each pose's rows, which must be adjacent: (S (G, 3R) of ones, the poses (G,),
    the group of each row (3R,)); S with J_e's column as its values sums Q J_e, J_e r per pose."""
    new = np.r_[True, rows_pose[1:] != rows_pose[:-1]]
    poses = rows_pose[new]
    if len(np.unique(poses)) != len(poses):
        raise ValueError("screen needs each pose's rows adjacent (sort the rows by pose)")
    n = len(rows_pose)
    S = sparse.csr_matrix((np.ones(n), np.arange(n), np.r_[np.flatnonzero(new), n]), shape=(len(poses), n))
    return S, poses, np.cumsum(new) - 1


def screen(J: np.ndarray, rows_pose: np.ndarray, resid: np.ndarray, base: Basis, sigma2: float,
           cands: list[Candidate], errors: list[int], ids: list[int] | None = None) -> list[Hit]:
    """Every (candidate, error) pair that explains more than noise would, most significant first;
    a hit's candidate is its index in cands, or ids[index] when ids is given.

    J (3R, ne) is J_e at the current fit for the measured rows; rows_pose (3R,) the pose of each
    row, a pose's rows adjacent; resid (3R,) is orthogonal to the current model's columns, whose
    orthonormal basis Q (3R, k) `base` holds; sigma2 the residual variance per coordinate (m^2).

    A candidate's column is J_e[row] f(pose of row), so every product with it sums first over the
    rows of a pose: B^T X = A^T F with A (poses, k) the per-pose sums of B J_e (then Q^T X =
    R^-T B^T X), and X^T X = F^T diag(sum of J_e^2) F. The products run over poses, not over the
    3 nt rows of each."""
    S, poses, group = _pose_sums(rows_pose)
    F = np.asfortranarray(np.concatenate([c.values for c in cands], axis=1)[poses])  # (G, total columns)
    bounds = np.cumsum([0] + [c.values.shape[1] for c in cands])
    dofs = np.array([c.dof for c in cands])
    free = np.array([c.errors is None for c in cands])
    only: dict[int, list[int]] = {e: [] for e in errors}
    for ci, c in enumerate(cands):
        for e in dict.fromkeys(c.errors or ()):
            if e in only:
                only[e].append(ci)
    # each error's products run over the columns offered to it alone: the candidates offered to every
    # error, then its own (a load acts on one frame's errors; thousands of them would otherwise be
    # multiplied for every error). start: where each offered candidate's columns begin among them
    columns = [np.arange(bounds[ci], bounds[ci + 1]) for ci in range(len(cands))]
    everyone = np.flatnonzero(free)
    shared = np.concatenate([columns[ci] for ci in everyone]) if len(everyone) else np.zeros(0, int)
    start = np.zeros(len(cands), int)
    start[everyone] = np.cumsum(dofs[everyone]) - dofs[everyone]
    found = []  # (drop, dof, candidate, error, v, QtX, the candidate's columns in QtX)
    for e in errors:
        offered = free.copy()
        offered[only[e]] = True
        j = J[:, e]
        if not offered.any() or not np.any(j):
            continue
        start[only[e]] = len(shared) + np.cumsum(dofs[only[e]]) - dofs[only[e]]
        Fe = np.asfortranarray(F[:, np.concatenate([shared, *(columns[ci] for ci in only[e])])])
        S.data = j  # the sums over each pose's rows of J_e times what follows
        BtS = (S @ base.B).T  # (k, G): B^T X = BtS F; R^-T on whichever side is smaller
        QtX = base.project(BtS) @ Fe if BtS.shape[1] < Fe.shape[1] else base.project(BtS @ Fe)
        rX = (S @ resid) @ Fe
        w = S @ j
        Fw = np.multiply(w[:, None], Fe, order="F")
        # candidates of one size at once (thousands of auxiliary signals are thousands of
        # candidates), found in candidate order as one at a time would be
        ours = []
        for dof in np.unique(dofs[offered]):
            group_of = np.flatnonzero(offered & (dofs == dof))
            cols = start[group_of][:, None] + np.arange(dof)  # (n, dof) each candidate's columns in Fe
            XtX = np.einsum("gni,gnj->nij", Fe[:, cols], Fw[:, cols])
            Q = QtX[:, cols]
            G = XtX - np.einsum("kni,knj->nij", Q, Q)  # Gram matrices of the projected columns
            scale = np.sqrt(np.maximum(np.diagonal(XtX, axis1=1, axis2=2), 1e-300))  # (n, dof)
            Gs = G / (scale[:, :, None] * scale[:, None, :])
            # one column (most candidates): its 1 x 1 Gram matrix is its own eigenvalue, and LAPACK's solve
            # divides by it, to the bit; the library's per-matrix calls cost more than the arithmetic
            eigen = Gs[:, :, 0] if dof == 1 else np.linalg.eigvalsh(Gs)
            new = eigen.min(axis=1) >= MIN_INDEPENDENCE  # else inside the current model
            group_of, cols, scale = group_of[new], cols[new], scale[new]
            b = rX[cols] / scale
            beta = b / eigen[new] if dof == 1 else np.linalg.solve(Gs[new], b[:, :, None])[:, :, 0]
            drop = np.einsum("ni,ni->n", b, beta)
            kept = np.flatnonzero(drop > max(9, 3 * dof) * sigma2)  # cheap pre-filter; the real test follows
            ours += zip(drop[kept].tolist(), [int(dof)] * len(kept), group_of[kept].tolist(), [e] * len(kept),
                        beta[kept] / scale[kept], [QtX] * len(kept), cols[kept])
        found += sorted(ours, key=lambda h: h[2])
    if not found:
        return []
    drops, dofs = np.array([h[0] for h in found]), np.array([h[1] for h in found])
    log_p = chi2_logsf(drops / max(sigma2, 1e-300), dofs)
    ids = range(len(cands)) if ids is None else ids
    hits = [Hit(drop, lp, ids[ci], e, (J, F, (bounds[ci], bounds[ci + 1]), v, group, base, QtX, cols))
            for (drop, _, ci, e, v, QtX, cols), lp in zip(found, log_p.tolist())]
    hits.sort(key=significance_order)
    return hits


def significance_order(hit: Hit) -> float:
    """Sort key of hits, most significant first. Hits equal to 10 digits are one column offered twice
    (an auxiliary torque and the model's own gravity_torque of the same joint): they keep the order
    they were found in, candidate order, not whichever the arithmetic's last digits favour."""
    return float(f"{hit.log_p:.10g}")


def folds(n_poses: int, rng: np.random.Generator) -> np.ndarray:
    """Fold number of each pose (P,): folds split poses, never the targets of one pose."""
    return rng.permutation(n_poses) % FOLDS


def _solve_gram(G: np.ndarray, b: np.ndarray) -> np.ndarray:
    """dc of the normal equations G dc = b, columns scaled to a unit diagonal; a singular G (a
    column with nothing left outside the others) gets the minimum-norm solution, as lstsq would."""
    s = np.sqrt(np.maximum(np.diag(G), 1e-300))
    Gs, bs = G / np.outer(s, s), b / s
    try:
        factor = linalg.cho_factor(Gs)
        if np.diag(factor[0]).min() ** 2 > SINGULAR_GRAM:
            return linalg.cho_solve(factor, bs) / s
    except linalg.LinAlgError:
        pass
    # Cholesky also "succeeds" on a Gram matrix singular to rounding: one cut-off for both cases
    lam, V = np.linalg.eigh(Gs)
    keep = lam > SINGULAR_GRAM * lam.max()
    return V[:, keep] @ ((V[:, keep].T @ bs) / lam[keep]) / s


class Folded:
    """The current fit's linear system H dc ~ r (3R rows, k columns) split into FOLDS folds of
    poses, for cross-validating corrections of it (H alone, or with a candidate's columns) and for
    screening a fold's training rows alone.

    H's columns are scaled to unit norm (B). Each fold keeps the R factor of its rows of B, its
    Gram matrix R^T R, B_f^T r_f and r_f^T r_f; the folds partition the rows, so fold f's training
    system is the sum of the others' (a candidate's c columns cost 3R k c, not the 3R (k + c)^2 of
    a least-squares fit per fold) and its R the QR of the others' R stacked (k^3, not 3R k^2)."""

    def __init__(self, H: np.ndarray, r: np.ndarray, rows_pose: np.ndarray, fold: np.ndarray,
                 rows_dof: np.ndarray | None = None):
        # row-major: every screened error multiplies B by a sparse matrix, which wants it so
        self.B = np.ascontiguousarray(H / np.maximum(np.linalg.norm(H, axis=0), 1e-300))
        self.r, self.rows_dof = r, rows_dof
        self.rows = [np.flatnonzero(fold[rows_pose] == f) for f in range(FOLDS)]
        self.R = [np.linalg.qr(self.B[i], mode="r") for i in self.rows]
        self.parts = [(R.T @ R, self.B[i].T @ r[i], float(r[i] @ r[i])) for R, i in zip(self.R, self.rows)]

    def basis(self, f: int | None = None) -> Basis:
        """The Basis of all rows (f None), or of fold f's training rows `self.training(f)`."""
        if f is None:
            return basis(self.B, self.R)
        return basis(self.B[self.training(f)], [R for g, R in enumerate(self.R) if g != f])

    def training(self, f: int) -> np.ndarray:
        """The rows outside fold f (ascending)."""
        return np.setdiff1d(np.arange(len(self.r)), self.rows[f], assume_unique=True)

    def _parts(self, X: np.ndarray | None) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Per fold, the Gram matrix, right-hand side and r^T r of [H X] (X (3R, c), or None)."""
        if X is None:
            return self.parts
        out = []
        for (Gf, bf, rrf), i in zip(self.parts, self.rows):
            Xi = X[i]
            HX = self.B[i].T @ Xi
            out.append((np.block([[Gf, HX], [HX.T, Xi.T @ Xi]]), np.r_[bf, Xi.T @ self.r[i]], rrf))
        return out

    @staticmethod
    def _held_out(parts, f: int) -> float:
        Gf, bf, rrf = parts[f]
        # the sum of the other folds, not the whole less fold f: a column that lives almost only on
        # fold f would keep nothing but rounding from that subtraction
        train = [p for g, p in enumerate(parts) if g != f]
        dc = _solve_gram(sum(p[0] for p in train), sum(p[1] for p in train))
        return max(rrf - 2 * dc @ bf + dc @ Gf @ dc, 0.0)

    def held_out_sq(self, f: int, X: np.ndarray | None = None) -> float:
        """Squared error on fold f's rows of the correction [H X] dc ~ r fitted on the other folds;
        X (3R, c) extra columns, or None."""
        return self._held_out(self._parts(X), f)

    def cv_rms(self, X: np.ndarray | None = None) -> float:
        """k-fold cross-validated RMS point error (m) of the correction [H X] dc ~ r, per three
        degrees of freedom."""
        parts = self._parts(X)
        sq = sum(self._held_out(parts, f) for f in range(FOLDS))
        return float(np.sqrt(sq / (_dof(self.rows_dof, self.r) / 3)))


def _dof(rows_dof: np.ndarray | None, r: np.ndarray, rows=slice(None)) -> float:
    """Degrees of freedom of the rows `rows` of r."""
    return float(len(r[rows]) if rows_dof is None else rows_dof[rows].sum())


def columns(J: np.ndarray, cand: Candidate, error: int, rows_pose: np.ndarray) -> np.ndarray:
    """The new columns (3R, dof) of a candidate on one generalized error."""
    return J[:, error:error + 1] * cand.values[rows_pose]


def selection_cv_rms(fs: Folded, J: np.ndarray, rows_pose: np.ndarray, cands: list[Candidate],
                     shortlist: list[tuple[int, int]]) -> float:
    """k-fold cross-validated RMS point error (m) of the choice itself: in each fold the screening
    runs on the training part alone, its most significant candidate is added, and the held-out
    poses are predicted. The best of thousands of candidates always fits the poses it was picked on
    better than new ones; only an effect that wins on the other folds' poses too is real. The folds
    choose among `shortlist`, the (candidate, error) pairs strongest on all poses: a pair far down
    that list does not win on four fifths of them."""
    # each pair offered to its own error alone: one screening per fold, not one per error
    offered = [replace(cands[ci], errors=(e,)) for ci, e in shortlist]
    errors = sorted({e for _, e in shortlist})
    sq = 0.0
    for f in range(FOLDS):
        train, base = fs.training(f), fs.basis(f)
        resid = base.residual(fs.r[train])
        sigma2 = float(resid @ resid) / max(_dof(fs.rows_dof, fs.r, train) - fs.B.shape[1], 1)
        Jt, pt = J[train], rows_pose[train]  # once per fold: the copies are large at thousands of poses
        hits = [(h.log_p, shortlist[h.candidate][0], h.error)
                for h in (screen(Jt, pt, resid, base, sigma2, offered, errors) if offered else [])]
        best = min(hits, default=None)
        sq += fs.held_out_sq(f, None if best is None else columns(J, cands[best[1]], best[2], rows_pose))
    return float(np.sqrt(sq / (_dof(fs.rows_dof, fs.r) / 3)))


def passing(found: list[Hit], cands: list[Candidate], fs: Folded, J: np.ndarray, rows_pose: np.ndarray,
            n_tests: int, base_cv: float):
    """The candidates, most significant first (at most TRIES), that pass the chi-square test with a
    Bonferroni correction for `n_tests` and lower the cross-validated RMS: [(hit, p, cv), ...]."""
    out = []
    for hit in found[:TRIES]:
        p = float(np.exp(hit.log_p))
        if hit.log_p + np.log(n_tests) > np.log(ALPHA):
            break  # sorted by significance: nothing further can pass either
        cv = fs.cv_rms(columns(J, cands[hit.candidate], hit.error, rows_pose))
        if cv < (1 - MIN_CV_GAIN) * base_cv:
            out.append((hit, p, cv))
    return out
