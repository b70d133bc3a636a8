"""Identification: iterated least squares on H_e (the seed paper's Eq. 8, done carefully).

Gauss-Newton on the nonlinear chain: at the current coefficients c the generated code gives the
modelled targets and H_e (J_e at eps(c) times the basis terms); the step solves the column-scaled
least-squares problem by Householder QR, damped (Levenberg-Marquardt) only when a full step
would raise the residual, as it can when the data barely excites some coefficient. Rows are streamed through the QR in blocks of poses, so
memory stays bounded by the block size whatever the number of poses (the R factor of [H | r] is
all that is kept). Redundant and unexcited coefficients (and, with a rank tolerance, weakly
determined ones) are found first (`redundancy`) and held at zero.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy import special
from scipy.linalg import solve_triangular

from gecgen.model.measurements import Measurements
from gecgen.model.robot import WRENCH
from gecgen.model.validation import ModelError
from gecgen.fit import influence, relative, robust, weak
from gecgen.runtime.compiled import CompiledModel, cache_dir, write_atomically
from gecgen.fit.redundancy import (RANK_TOL, Eliminated, Redundancy, generic_design, structural, unexcited,
                                      unmeasured_frames)
from gecgen.fit.registration import IDENTITY, Registration, register
from gecgen.runtime.threads import one_blas_thread

BLOCK_POSES = 2000
#: condition number of the column-scaled kept H_e above which the fit is reported ill-posed
ILL_CONDITIONED = 1e6
#: ... and above which it is singular in double precision: the coefficients are not determined
SINGULAR = 1e12
#: relative decrease of the residual sum of squares per step below which the fit is stationary
RSS_TOL = 1e-6  # 5e-7 of the RMS: far below anything a tracker resolves


#: beyond these a generalized error is absurd (no real robot is that far from its model)
ABSURD_TRANSLATION_M = 0.5
ABSURD_ROTATION_RAD = 0.5
#: more outliers than this share of the points suggests a missing effect rather than glitches
OUTLIER_SHARE = 0.05


@dataclass(frozen=True)
class Outlier:
    """A measured row the robust fit flagged: its file line (header = 1), pose id, target,
    position residual (mm), the weight it kept in the fit (1 = full) and, for a measured frame,
    its orientation residual (mrad)."""

    row: int
    pose: int
    target: str
    residual_mm: float
    weight: float
    rotation_mrad: float | None = None

    def to_dict(self) -> dict:
        out = {"row": self.row, "pose": self.pose, "target": self.target, "residual_mm": self.residual_mm,
               "weight": self.weight}
        return out if self.rotation_mrad is None else {**out, "rotation_mrad": self.rotation_mrad}


@dataclass(frozen=True)
class Suspect:
    """A pose the other poses do not predict (`fit.influence`): the file line of its first row
    (header = 1), its pose id, its residual under the fit to the other poses (mm per point: a
    measured frame's orientation counted through the length scale), its F statistic and the next
    largest pose's, and the reading whose change best explains it ("q2"), that change in `unit`
    (rad or m) and the share of the residual it explains."""

    row: int
    pose: int
    deleted_mm: float
    F: float
    next_F: float
    reading: str
    change: float
    explained: float
    unit: str

    def to_dict(self) -> dict:
        return {"row": self.row, "pose": self.pose, "deleted_mm": self.deleted_mm, "F": self.F,
                "next_F": self.next_F, "reading": self.reading, "change": self.change, "unit": self.unit,
                "explained": self.explained}

    def __str__(self) -> str:
        why = (f"{self.reading} off by {self.change:.3g} {self.unit} explains {100 * self.explained:.0f} % of it: "
               f"a joint reading glitch?" if self.explained >= influence.EXPLAINED
               else "no single joint reading explains it: a mis-measured pose?")
        return (f"pose {self.pose} (line {self.row}) does not fit the others: without it the fit misses it by "
                f"{self.deleted_mm:.3g} mm (F {self.F:.3g}, the next pose {self.next_F:.3g}); {why} Check the pose, "
                f"or drop it and run again")


@dataclass(frozen=True)
class Analysis:
    """The data analysis a fit's first round begins from (`_data_analysis`): the redundancy red and
    A0, [H | r] over its kept columns up to an orthogonal factor, of the compiled model with cache
    key `key` for the measured points y (R, 3) in the robot world (m) at rank tolerance rank_tol,
    before any coefficient is held."""

    red: Redundancy
    A0: np.ndarray
    key: str
    y: np.ndarray
    rank_tol: float

    def serves(self, cm: CompiledModel, y: np.ndarray, rank_tol: float) -> bool:
        """Whether a fit of the same data by cm at y and rank_tol would find the same. Relative rows
        (NaN in y) are analysed again."""
        return cm.key == self.key and rank_tol == self.rank_tol and np.array_equal(y, self.y)


@dataclass(frozen=True)
class Fit:
    """Result of `identify`. c (nc,) all coefficients (eliminated ones 0); std (nc,) with NaN for
    eliminated; cov (k, k) over `redundancy.kept`; sigma_m the residual standard deviation per
    degree of freedom (m; a measured frame's orientation counted through the length scale, see
    `model.pose_targets`), down-weighted rows counted by their weight; metrics in mm (and mrad)
    over all measured rows (`train_inliers` without the outliers). weights (R,) the final weight
    of each point in the least squares (a frame's vertices 1/4 of their row's); measured_dof the
    degrees of freedom of the data, each row counted by its robust weight (3 per point, 6 per
    frame); outlier_limit_m the residual length beyond which a point is an outlier (inf for l2;
    a frame's limit is sqrt(2) times as long, for its six degrees of freedom); ranges the span of
    each input over the data ({"q1": [lo, hi], ..., "fx": ..., aux: ...}). A fit with `failures`
    must not be used: each says why. suspects: the poses the other poses do not predict, each
    named in `warnings` (and in `failures`, when the fit has any). analysis: the data analysis its
    first round began from, which a refit of the same data begins from too (`Analysis`). held: the
    weakly determined coefficients held at zero (`fit.weak`), each named in `warnings`."""

    c: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    redundancy: Redundancy
    registration: Registration
    sigma_m: float
    condition_number: float
    observability_index: float
    iterations: int
    converged: bool
    before: dict
    train: dict
    warnings: tuple[str, ...]
    failures: tuple[str, ...] = ()
    loss: str = "l2"
    outlier_limit_m: float = np.inf
    weights: np.ndarray | None = None
    outliers: tuple[Outlier, ...] = ()
    train_inliers: dict | None = None
    ranges: dict | None = None
    registrations: dict[int, Registration] | None = None  # per station id; `registration` is the first's
    measured_dof: float | None = None
    suspects: tuple[Suspect, ...] = ()
    analysis: Analysis | None = field(default=None, repr=False, compare=False)
    #: the coefficients held at zero because the data and the noise leave their direction weakly
    #: determined (`fit.weak`), each with why; each is also in `redundancy.eliminated` ("held")
    held: tuple[weak.Held, ...] = ()

    @property
    def trustworthy(self) -> bool:
        return not self.failures

    def to_world(self, data: Measurements) -> np.ndarray:
        """Measured points of `data` (R, 3) in the robot world, each through its station's frame."""
        return to_world(self.registrations, data)


def _poses_inputs(cm: CompiledModel, data: Measurements):
    return data.q, data.w, data.aux_columns(cm.model.aux)


def _blocks(data: Measurements, block: int):
    """Row indices grouped by blocks of consecutive poses; one block for data with relative rows,
    whose points and planes gather rows of any poses."""
    if data.relative is not None:
        block = max(data.n_poses, 1)
    order = np.argsort(data.pose, kind="stable")
    bounds = np.searchsorted(data.pose[order], np.arange(0, data.n_poses + block, block))
    for b in range(len(bounds) - 1):
        if bounds[b] < bounds[b + 1]:
            yield b * block, min((b + 1) * block, data.n_poses), order[bounds[b]:bounds[b + 1]]


def rows_H_and_residual(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray, block: int = BLOCK_POSES,
                        weights: np.ndarray | None = None, known_sigma_m: float | None = None,
                        projected: bool = True):
    """Yield (H rows (3r, nc), residual y - p (3r,)) per block of poses, at coefficients c; with
    point weights (R,), each point's three rows are scaled by the square root of its weight.
    Relative rows (`fit.relative`) have y NaN: their y is filled and, when `projected`, their
    columns projected (else their residual is 0: the columns as absolute data would have them);
    with known_sigma_m (m) the rows of the known distances and plane relations follow the last
    block's."""
    q, w, aux = _poses_inputs(cm, data)
    nt = cm.dims.nt
    for start, stop, rows in _blocks(data, block):
        p, H = cm.model_targets(q[start:stop], w[start:stop], aux[start:stop], c, with_H=True)
        local = data.pose[rows] - start
        Hr = H.reshape(stop - start, nt, 3, -1)[local, data.target[rows]]
        pr = p[local, data.target[rows]]
        r = y[rows] - pr
        extra = None
        if data.relative is not None:  # one block holds every row (_blocks)
            rel = data.relative.take(rows)
            wr = np.ones(len(rows)) if weights is None else weights[rows]
            if not projected:
                r = np.where(rel.rows[:, None], 0.0, r)
            else:
                r = relative.fill(rel, y[rows], pr, wr) - pr
                if known_sigma_m is not None and rel.n_known:
                    extra = relative.known_rows(rel, Hr, pr, wr, known_sigma_m)
                Hr = relative.project(rel, Hr, pr, wr)
        if weights is not None:
            root = np.sqrt(weights[rows])[:, None]
            Hr *= root[:, :, None]  # a copy already (the rows' selection): scaled in place
            r = r * root
        yield Hr.reshape(-1, H.shape[-1]), r.ravel()
        if extra is not None:
            yield extra


def qr_accumulate(blocks, columns: np.ndarray | None = None, scale: np.ndarray | None = None):
    """R factor of [H | r] over streamed blocks, (k+1, k+1), and the number of rows m."""
    R, m = None, 0
    for H, r in blocks:
        # [R; A | r] filled in place rather than stacked in steps: these blocks are megabytes, and each
        # copy of them shows
        k0 = 0 if R is None else len(R)
        k = H.shape[1] if columns is None else len(columns)
        M = np.empty((k0 + len(r), k + 1))
        if R is not None:
            M[:k0] = R
        M[k0:, :k] = H if columns is None else H[:, columns]
        if scale is not None:
            M[k0:, :k] /= scale
        M[k0:, k] = r
        R = np.linalg.qr(M, mode="r")
        m += len(r)
    k1 = R.shape[1]
    if R.shape[0] < k1:  # fewer rows than unknowns so far: pad so the shape is always square
        R = np.vstack([R, np.zeros((k1 - R.shape[0], k1))])
    return R, m


def damped_step(Rk: np.ndarray, z: np.ndarray, lam: float, ridge: float = 0.0, x: np.ndarray | None = None) -> np.ndarray:
    """Step dx in scaled coordinates minimising |Rk dx - z|^2 + ridge |x + dx|^2 + lam |dx|^2
    (Levenberg-Marquardt damping lam, ridge prior on the coefficients x; both 0: Gauss-Newton)."""
    if lam == 0 and ridge == 0:
        return solve_triangular(Rk, z)
    k = len(z)
    A = np.vstack([Rk, np.sqrt(ridge) * np.eye(k), np.sqrt(lam) * np.eye(k)])
    b = np.concatenate([z, -np.sqrt(ridge) * (x if x is not None else np.zeros(k)), np.zeros(k)])
    R2 = np.linalg.qr(np.column_stack([A, b]), mode="r")
    return solve_triangular(R2[:k, :k], R2[:k, k])


#: candidate ridges and rank tolerances for `choose` (roughly half-decade steps; 0 and RANK_TOL: off)
RIDGE_GRID = (0.0, 1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0)
RANK_TOL_GRID = (RANK_TOL, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3)


def cross_validated_rms(cm: CompiledModel, data: Measurements, folds: int = 5, seed: int = 0, **options) -> float:
    """k-fold cross-validated RMS point error (mm) of `identify(..., **options)`: per three degrees
    of freedom, so a measured frame counts as two points (its residual length, `row_errors`).
    Folds split poses, never the targets of one pose, so a held-out pose is wholly unseen."""
    fold = np.random.default_rng(seed).permutation(data.n_poses) % folds
    sq, n = 0.0, 0
    for f in range(folds):
        train, test = data.subset(np.nonzero(fold != f)[0]), data.subset(np.nonzero(fold == f)[0])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = identify(cm, train, **options)
        sq_f, n_f = squared_error(cm, test, fit.to_world(test), fit.c)
        sq, n = sq + sq_f, n + n_f
    return 1e3 * np.sqrt(sq / n)


def choose(cm: CompiledModel, data: Measurements, grids: dict[str, tuple], folds: int = 5, seed: int = 0,
           **fixed) -> tuple[dict, list[dict]]:
    """The combination of `identify` options from `grids` (name -> values, every combination tried)
    with the lowest k-fold cross-validated RMS on the training data, and the table
    [{option: value, ..., cv_rms_mm}] it was chosen from. `fixed` options apply to every fit."""
    names = list(grids)
    table = []
    for values in itertools.product(*(grids[name] for name in names)):
        options = dict(zip(names, values))
        table.append({**options, "cv_rms_mm": cross_validated_rms(cm, data, folds, seed, **options, **fixed)})
    best = min(table, key=lambda row: row["cv_rms_mm"])
    return {name: best[name] for name in names}, table


def position_errors(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray | None) -> np.ndarray:
    """|measured - modelled| per measured point (R,), m; c=None is the nominal model."""
    q, w, aux = _poses_inputs(cm, data)
    p = cm.model_targets(q, w, aux, np.zeros(cm.dims.nc) if c is None else c)[data.pose, data.target]
    return np.linalg.norm(filled(data, y, p) - p, axis=1)


def filled(data: Measurements, y: np.ndarray, p: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Measured points y (R, 3) with the relative rows' filled in from the modelled points p (R, 3)
    (`fit.relative.fill`, point weights (R,)); y itself for data without relative rows."""
    return y if data.relative is None else relative.fill(data.relative, y, p, weights)


def row_errors(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray | None,
               weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per measured row (`model.rows.Rows`; one per point unless the data measures
    frames): position error (G,) m, orientation error (G,) rad (NaN for a position-only row) and
    residual length (G,) m, at coefficients c (None: the nominal model) with measured points y (a
    relative row's from its fitted point or plane, with point weights (R,), `filled`)."""
    q, w, aux = _poses_inputs(cm, data)
    p = cm.model_targets(q, w, aux, np.zeros(cm.dims.nc) if c is None else c)[data.pose, data.target]
    return data.rows.errors(filled(data, y, p, weights), p)


def squared_error(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray | None) -> tuple[float, float]:
    """(sum of the measured rows' squared residual lengths (m^2), the number of points they count
    for): a measured frame counts as two points, its six degrees of freedom, so that the square
    root of their ratio is an RMS point error for position data and the fit's weighted residual
    per three degrees of freedom for pose data."""
    rows = data.rows
    e = row_errors(cm, data, y, c)[2]
    return float(e @ e), float(rows.row_dof.sum()) / 3


def summary(errors_m: np.ndarray, rotation_rad: np.ndarray | None = None) -> dict:
    """{rms_mm, max_mm} of position errors given in m; with orientation errors (rad, NaN for rows
    without one) of any row, also {rot_rms_mrad, rot_max_mrad} over the rows that have one."""
    out = {"rms_mm": float(1e3 * np.sqrt(np.mean(errors_m ** 2))), "max_mm": float(1e3 * errors_m.max())}
    if rotation_rad is not None and not np.all(np.isnan(rotation_rad)):
        rot = rotation_rad[~np.isnan(rotation_rad)]
        out.update(rot_rms_mrad=float(1e3 * np.sqrt(np.mean(rot ** 2))), rot_max_mrad=float(1e3 * rot.max()))
    return out


def fixture_measures(cm: CompiledModel, data: Measurements, c: np.ndarray | None) -> dict:
    """What the relative rows of `data` say of the model at coefficients c (None: nominal):
    `fit.relative.measures` (consistency, flatness, distance errors, mm)."""
    return relative.measures(data.relative, _relative_targets(cm, data, c))


def stray_placements(cm: CompiledModel, data: Measurements, c: np.ndarray) -> list[str]:
    """`fit.relative.stray_placements` of the relative rows of `data` at coefficients c: a warning
    for each placement recorded badly, on training or held-out data alike."""
    return relative.stray_placements(data.relative, _relative_targets(cm, data, c)) if data.relative else []


def _relative_targets(cm: CompiledModel, data: Measurements, c: np.ndarray | None) -> np.ndarray:
    """The modelled target of every row of `data` (R, 3) m at coefficients c (None: nominal)."""
    q, w, aux = _poses_inputs(cm, data)
    return cm.model_targets(q, w, aux, np.zeros(cm.dims.nc) if c is None else c)[data.pose, data.target]


def structural_matrix(cm: CompiledModel, targets: np.ndarray, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The data-free design for the measured targets: the R factor of H_e at generic poses (rows of
    the measured targets only), and the lever arm of each generalized error (ne,): the RMS motion of
    the measured points per unit error (m per m, m per rad) over those poses."""
    nc, ntm = cm.dims.nc, len(targets)
    n_poses = max(40, int(np.ceil(3 * nc / (3 * ntm))))
    q, w, aux = generic_design(cm.robot, cm.dims.naux, n_poses, np.random.default_rng(seed))
    _, H = cm.model_targets(q, w, aux, np.zeros(nc), with_H=True)
    rows = (3 * targets[:, None] + np.arange(3)).ravel()
    A = H[:, rows, :].reshape(-1, nc)
    J = cm.J_e(q, np.zeros(cm.dims.ne))[1][:, rows, :]
    lever = np.sqrt(np.sum(J ** 2, axis=1).mean(axis=0) / ntm)
    return np.linalg.qr(A, mode="r"), lever


def structural_analysis(cm: CompiledModel, targets: np.ndarray) -> Redundancy:
    """Structural analysis for the measured targets. It uses no data, so like the compiled code it
    is cached by content (the model's key, the analysis code, numpy's version, the targets): a
    warm run skips an H_e evaluation at generic poses, its QR, the rank test and the merges."""
    h = hashlib.sha256(json.dumps([cm.key, np.__version__, targets.tolist()]).encode())
    fit = Path(__file__).resolve().parent
    for source in (fit / "identify.py", fit / "redundancy.py", fit.parent / "model" / "kinematics.py"):
        h.update(source.read_bytes())
    path = cache_dir() / f"{cm.robot.name}-structural-{h.hexdigest()[:24]}.json"
    try:
        red = Redundancy.from_json(path.read_text())
        # a cached entry must at least partition this model's coefficients, or it is recomputed
        if red.names == tuple(cm.model.coefficient_names(cm.robot)) and \
                sorted([*red.kept, *(e.index for e in red.eliminated)]) == list(range(cm.dims.nc)):
            return red
    except (OSError, ValueError, KeyError, TypeError):
        pass  # no entry, or a truncated or foreign one: recomputed and replaced below
    red = structural(*structural_matrix(cm, targets), cm.robot, cm.model, len(targets),
                     unmeasured_frames(cm.robot, targets))
    write_atomically(path, red.to_json())
    return red


def _data_analysis(cm: CompiledModel, data: Measurements, y: np.ndarray, rank_tol: float = RANK_TOL,
                   weights: np.ndarray | None = None, at: np.ndarray | None = None) -> tuple[Redundancy, np.ndarray, int]:
    """Redundancy for the targets the data measures (`rank_tol`: see `redundancy.unexcited`) at
    coefficients `at` (default 0); A0 (s+1, k+1), [H | r] there with rows scaled by the point weights (R,) over the
    identifiable columns up to an orthogonal factor (s the structurally kept count); the number
    of measured coordinates."""
    targets = np.unique(data.target)
    struct = structural_analysis(cm, targets)
    c = np.zeros(cm.dims.nc) if at is None else at
    columns = np.array(struct.kept, int)
    # the distances' weight against the rows changes no rank: a typical noise stands for the fit's
    blocks = rows_H_and_residual(cm, data, y, c, weights=weights, known_sigma_m=TYPICAL_NOISE_M)
    if data.relative is not None:  # one block (_blocks), read again by _relative_analysis
        blocks = list(blocks)
    R0, m = qr_accumulate(blocks, columns)
    if data.relative is None:
        red = unexcited(struct, R0[:, :-1], cm.robot, cm.model, len(targets), rank_tol)
    else:
        red = _relative_analysis(cm, data, y, c, weights, struct, blocks, R0, rank_tol)
    return red, R0[:, [*np.searchsorted(struct.kept, red.kept), -1]], m


def _relative_analysis(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray, weights: np.ndarray | None,
                       struct: Redundancy, blocks: list, R0: np.ndarray, rank_tol: float) -> Redundancy:
    """`unexcited` for data with relative rows (their blocks and R factor R0 at coefficients c over
    the structurally kept columns): first what the same rows would excite as absolute measurements,
    then, of that, the directions relative rows cannot see (`fit.relative.unseen`) taken out, so
    that a coefficient is eliminated for each, named as invisible to relative data."""
    n_targets, columns = len(np.unique(data.target)), np.array(struct.kept, int)
    unprojected = list(rows_H_and_residual(cm, data, y, c, weights=weights, projected=False))  # one block (_blocks)
    R_abs, _ = qr_accumulate(unprojected, columns)
    absolute = unexcited(struct, R_abs[:, :-1], cm.robot, cm.model, n_targets, rank_tol)
    excited = np.searchsorted(struct.kept, absolute.kept)
    lengths = blocks[-1][0][relative.scale_rows(data.relative)][:, columns] if data.relative.n_known else \
        np.zeros((0, len(columns)))
    # what a motion of the whole set does, taken out: at c = 0 a socket's rows scatter by the model's
    # whole error, and a turn of the set would seem to move them apart
    q, w, aux = _poses_inputs(cm, data)
    p = cm.model_targets(q, w, aux, c)[data.pose, data.target]
    wts = np.ones(len(p)) if weights is None else weights
    order = np.argsort(data.pose, kind="stable")  # the row order of the block (_blocks)
    moves = relative.rigid(data.relative, p)
    G = (relative.project(data.relative, moves, p, wts) * np.sqrt(wts)[:, None, None])[order].reshape(-1, 7)
    H = blocks[0][0][:, columns]
    R_rows = np.linalg.qr(H - G @ np.linalg.lstsq(G, H, rcond=None)[0], mode="r")
    A = R_abs[:, excited]
    V = relative.unseen(R_rows[:, excited], A, lengths[:, excited])
    R = R0[:, :-1].copy()
    R[:, excited] = relative.blind(R[:, excited], V, A.T @ A)
    R[:, excited[relative.spanning(V, np.linalg.norm(A, axis=0))]] = 0.0  # one coefficient dropped per direction
    red = unexcited(struct, R, cm.robot, cm.model, n_targets, rank_tol)
    scaled = (moves * np.sqrt(wts)[:, None, None])[order].reshape(-1, 7)
    return _unseen_by_relative(cm, data, red, absolute, unprojected[0][0][:, columns], scaled,
                               np.searchsorted(struct.kept, [e.index for e in red.eliminated]))


#: m: a tracker's or a socket's noise, for what does not depend on it
TYPICAL_NOISE_M = 5e-5


def _unseen_by_relative(cm: CompiledModel, data: Measurements, red: Redundancy, absolute: Redundancy,
                        H: np.ndarray, moves: np.ndarray, at: np.ndarray) -> Redundancy:
    """`red` (the analysis of data with relative rows) with the coefficients the same rows would
    excite as absolute measurements (`absolute`, their columns unprojected) eliminated for being
    invisible to relative data, and why. Without a known distance or offset, the one of them that
    carries the scale is named as such (SCALE_HELD; `Fit.held` lists it): H (rows, s) the
    unprojected rows over the structurally kept columns, moves (rows, 7) what a motion and a scaling of the whole set do to
    them (`fit.relative.rigid`), at the column of each of red's eliminated coefficients in H."""
    seen = set(absolute.kept)
    names = [e.split(".")[0] for e in cm.robot.error_names()]
    scale = ("" if data.relative.distances or any(x.kind == "offset" for x in data.relative.relations) else
             "; a known distance between two points, or offset between two planes, fixes the scale")

    def why(j: int) -> str:
        frame = names[cm.model.coefficients[j].error]
        return ("relative data cannot see it: it moves every point and plane of the fixtures alike (the base "
                "placement)" if frame == "0" else
                "relative data cannot see it: at the measured poses it moves the points and planes only together, "
                "as a rigid motion or a scaling of the whole set does" + scale)

    unseen = [i for i, e in enumerate(red.eliminated) if e.reason in ("unexcited", "weak") and e.index in seen]
    carrier = None
    if scale and unseen:
        # beyond what a rigid motion of the set does (taken out of every column), the unseen coefficient
        # whose column is most nearly the scaling carries the scale; one that is a rigid motion keeps
        # only rounding, and counts for nothing
        Q = np.linalg.qr(moves[:, :6])[0]
        X = np.column_stack([H[:, at[unseen]], moves[:, 6]])
        before = np.linalg.norm(X, axis=0)
        X = X - Q @ (Q.T @ X)
        after = np.linalg.norm(X, axis=0)
        cos = np.abs(X[:, -1] @ X[:, :-1]) / np.maximum(after[:-1] * after[-1], 1e-300)
        cos[after[:-1] <= 1e-6 * before[:-1]] = 0.0
        carrier = unseen[int(np.argmax(cos))]
    return replace(red, eliminated=tuple(
        replace(e, reason="relative", detail=SCALE_HELD) if i == carrier else
        replace(e, reason="relative", detail=why(e.index)) if i in unseen else e
        for i, e in enumerate(red.eliminated)))


#: why the coefficient that carries the scale is held, for relative data without a known distance
SCALE_HELD = ("the scale is not determined: no known distance between sockets or points, nor offset between planes, "
              "fixes it, and this error acts as a scaling of the whole set; held at zero (declare a known distance "
              "to determine it)")


def redundancy(cm: CompiledModel, data: Measurements | None = None, registration_mode: str = "auto") -> Redundancy:
    """Structural analysis for the targets the data measures (all robot targets without data)."""
    if data is None:
        return structural_analysis(cm, np.arange(cm.dims.nt))
    return _data_analysis(cm, data, to_world(fit_frames(cm, data, None, mode=registration_mode), data), RANK_TOL,
                          data.rows.weight)[0]


def fit_frames(cm: CompiledModel, data: Measurements, c: np.ndarray | None, loss: str = "cauchy",
               mode: str = "always") -> dict[int, Registration]:
    """The tracker frame of each station of `data` ({station id: Registration}) with the model held
    at coefficients c (nc,), None for the nominal model: the robust rigid transform taking the
    modelled points onto the station's measured ones (`registration.register`: mode and loss; a
    measured frame's vertices weigh 1/4 each, so a frame counts as much as a point). Relative rows
    have no measured position: a station with no other rows keeps the identity (nothing fixes it)."""
    prior = data.rows.weight
    absolute = np.ones(len(data.xyz), bool) if data.relative is None else ~data.relative.rows
    if c is None:
        p = cm.nominal_targets(data.q)[data.pose, data.target]
    else:
        p = cm.model_targets(data.q, data.w, data.aux_columns(cm.model.aux), c)[data.pose, data.target]
    frames = {}
    for s in np.unique(data.station):
        rows = (data.station == s) & absolute
        if not rows.any():
            frames[int(s)] = IDENTITY
            continue
        try:
            frames[int(s)] = register(p[rows], data.xyz[rows], mode, loss, prior[rows])
        except ModelError as exc:
            raise ModelError(f"{data.source}: station {s}: {exc}") from None
    return frames


def to_world(frames: dict[int, Registration], data: Measurements, fix: str = "use --register") -> np.ndarray:
    """Measured points of `data` (R, 3) in the robot world (m), each through the frame of its
    station; a station `frames` lacks is refused (`fix` says what to do)."""
    unknown = sorted(set(np.unique(data.station).tolist()) - set(frames))
    if unknown:
        raise ModelError(f"{data.source}: station {unknown[0]} has no known tracker frame (known: stations "
                         f"{', '.join(map(str, sorted(frames)))}); {fix} to fit its frame on this data")
    y = data.xyz.copy()
    for s, frame in frames.items():
        rows = data.station == s
        y[rows] = frame.to_world(data.xyz[rows])
    return y


def _fit_failures(cm: CompiledModel, data: Measurements, c: np.ndarray, std: np.ndarray, kept: np.ndarray,
                  converged: bool, why_not: str) -> list[str]:
    """Reasons the fit is not to be trusted: no convergence, a coefficient without a finite
    uncertainty, generalized errors no real robot has (over ABSURD_TRANSLATION_M or
    ABSURD_ROTATION_RAD at a measured pose: the data cannot hold the coefficient)."""
    out = [] if converged else [why_not]
    names = cm.model.coefficient_names(cm.robot)
    bad = [j for j in kept if not np.isfinite(std[j]) or not np.isfinite(c[j])]
    if bad:
        out.append(f"coefficient {names[bad[0]]} has no finite uncertainty ({len(bad)} such); the data cannot "
                   f"determine it: check the redundancy analysis, measure poses that move it or drop its term")
        return out
    absurd = absurd_error(cm, data.q, data.w, data.aux_columns(cm.model.aux), c)
    if absurd:
        # the cause is the data when that error's coefficients are not determined (|value| within two
        # std of zero: noise put them there); only determined values speak against the robot file
        error = cm.robot.error_names().index(absurd.split()[2])
        own = [j for j in kept if cm.model.coefficients[j].error == error]
        determined = any(abs(c[j]) > 2 * std[j] for j in own)
        out.append(f"{absurd} at a measured pose: no real robot is that far from its model; " +
                   ("its coefficients are determined by the data, so the robot file (or its targets) does not "
                    "describe this robot" if determined else
                    "the data do not determine its coefficients (|value| within two std of zero): measure poses "
                    "that move it, or reduce the model"))
    return out


def absurd_error(cm: CompiledModel, q: np.ndarray, w: np.ndarray, aux: np.ndarray, c: np.ndarray) -> str | None:
    """The largest generalized error at poses q (P, n), w, aux beyond ABSURD_TRANSLATION_M or
    ABSURD_ROTATION_RAD ("generalized error 3.ey reaches 2.1 m (limit 0.5 m)"), or None. Blocks of
    BLOCK_POSES poses, so the memory does not grow with the data; w and aux may be shared by all poses."""
    q = np.atleast_2d(q)
    w, aux = (None if a is None else np.broadcast_to(a, (len(q), np.shape(a)[-1])) for a in (w, aux))
    eps = np.zeros(cm.robot.n_errors)
    for start in range(0, len(q), BLOCK_POSES):
        part = slice(start, start + BLOCK_POSES)
        block = np.abs(cm.eps(q[part], *(None if a is None else a[part] for a in (w, aux)), c))
        eps = np.maximum(eps, np.where(np.isfinite(block), block, np.inf).max(axis=0))
    limit = np.tile([ABSURD_TRANSLATION_M] * 3 + [ABSURD_ROTATION_RAD] * 3, cm.robot.n_frames + 1)
    if not np.any(eps > limit):
        return None
    e = int(np.argmax(eps / limit))
    unit = "m" if e % 6 < 3 else "rad"
    return f"generalized error {cm.robot.error_names()[e]} reaches {eps[e]:.3g} {unit} (limit {limit[e]:g} {unit})"


def _ranges(cm: CompiledModel, data: Measurements) -> dict[str, list[float]]:
    """The span of every input the model was fitted over: joints, wrench, aux signals it uses."""
    names = [f"q{i + 1}" for i in range(cm.robot.n)] + list(WRENCH) + list(cm.model.aux)
    values = np.column_stack([data.q, data.w, data.aux_columns(cm.model.aux)])
    return {n: [float(v.min()), float(v.max())] for n, v in zip(names, values.T)}


#: alternations of station frames and coefficients at most (see `identify`)
STATION_ROUNDS = 50
#: the station frames have settled when no measured point moves more than this between rounds (m)
STATION_TOL_M = 1e-6  # a micrometre: a fiftieth of a good tracker's noise


@one_blas_thread
def identify(cm: CompiledModel, data: Measurements, registration_mode: str = "auto", max_iter: int = 30,
             step_tol_m: float = 1e-12, progress=None, ridge: float = 0.0, rank_tol: float = RANK_TOL,
             loss: str = "cauchy", hold: dict[int, str] | None = None,
             analysis: Analysis | None = None, noise_m: float | None = None, hold_weak: bool = True) -> Fit:
    """Fit the error model of `cm` to `data`.

    Stops when a Gauss-Newton step changes the modelled points by less than step_tol_m (rms) or
    lowers the objective by a negligible share; `progress(iteration, rms_mm)` is called after each
    step when given. `loss` (see `fit.robust`): with `cauchy` (default) or `huber` every step
    is a reweighted least-squares step, the registration too is robust, and the points beyond the
    outlier limit are down-weighted and listed in `Fit.outliers`; `l2` is plain least squares.
    `ridge` > 0 adds ridge * |x|^2 to the least squares, x the coefficients scaled by their
    columns' norms (each coefficient penalised by its effect on the data): a prior that keeps
    weakly excited coefficients from growing where the data cannot hold them. `rank_tol` above
    the exact RANK_TOL holds the weakly excited coefficients at zero instead (see
    `redundancy.unexcited`). Choose either with `choose`. The result is never silently wrong:
    `Fit.failures` says why it must not be used (non-convergence, undetermined or absurd values).
    `hold` ({coefficient index: why}) holds those coefficients at zero, listed as eliminated for
    being insignificant (`fit.significance`), or, where why is a `weak.Held`, as weakly determined
    (a refit keeps what its fit held, `Fit.held`); `analysis`, the `Fit.analysis` of an earlier fit
    of the same compiled model and data, spares the first round's analysis where it would repeat it.
    hold_weak (default): when the fit cannot be trusted (it does not converge, or carries an absurd
    or undetermined value), it is redone with the coefficients whose direction the data determine too
    weakly against the noise to hold a plausible value held at zero (`fit.weak`; noise_m the
    instrument's noise per coordinate, m, when known, else estimated), each listed in `Fit.held`
    with why; that fit is returned when it holds some and fails for fewer reasons. Not when the
    failure names a pose the others do not predict (`Fit.suspects`): a glitch is fixed in the data.

    Stations (`data.station`): each is registered onto the nominal model on its own. With more
    than one, what the nominal model leaves of each frame differs between stations, and frame 0's
    errors can absorb only one of them; so the frames and the coefficients are then fitted in turn
    (each other station's frame onto the calibrated model's points, `fit_frames`, then the
    coefficients anew) until no measured point moves by more than STATION_TOL_M between two
    rounds' frames. The first (lowest id) station keeps its nominal registration: it anchors frame
    0's errors as with one station. `Fit.before` stays that of the nominal registrations.
    """
    robust.check_loss(loss)
    options = (registration_mode, max_iter, step_tol_m, progress, ridge, rank_tol, loss, hold or {}, analysis)
    fit = _identify(cm, data, *options, noise_m, False)
    if fit.failures and hold_weak and not fit.suspects:
        # a fit the data do not let converge, or that carries what they cannot hold, is redone with the
        # weakly determined directions held. A pose the others do not predict explains a failure better
        # than weak directions: that stands
        held = _identify(cm, data, *options, noise_m, True)
        if held.held and len(held.failures) < len(fit.failures):
            fit = replace(held, warnings=(f"the fit of every identifiable coefficient cannot be trusted "
                                          f"({'; '.join(fit.failures)}): refitted with the weakly determined "
                                          f"ones held", *held.warnings))
            if fit.failures:
                fit = replace(fit, failures=(*fit.failures, _unhelped(held, "as above")))
        else:
            fit = replace(fit, failures=(*fit.failures, _unhelped(held, f"({'; '.join(held.failures)})")))
    if hold_weak and not fit.failures and noise_m is not None:
        fit = _plausible(cm, data, options, fit, noise_m)
    for note in [*fit.failures, *fit.warnings]:
        warnings.warn(note, stacklevel=3)  # past one_blas_thread, at the caller
    return fit


def _unhelped(held: Fit, how: str) -> str:
    """Why holding the weakly determined directions does not rescue a fit that cannot be trusted:
    `held` is the same data's fit with them held, failing `how` (its reasons, in words)."""
    if not held.held:
        return ("no direction of the model is weakly determined against the noise, so holding none changes the "
                "fit: the failure is not what the data leave undetermined")
    names = ", ".join(h.param for h in held.held[:6]) + (", ..." if len(held.held) > 6 else "")
    return (f"no subspace the data determine lets the fit stand: with the {len(held.held)} weakly determined "
            f"coefficients held ({names}) the fit still fails {how}")


#: holding weak directions may raise the residual sum of squares by at most this chi-square quantile
#: of the noise (one degree of freedom per coefficient held)
HOLD_P = 0.99


#: a fit that carries an implausible value holds the directions determined to within this many times
#: a plausible size, in turn, as long as the noise explains what that costs
WIDEN = (1, 2, 4, 8, 16)


def _plausible(cm: CompiledModel, data: Measurements, options: tuple, fit: Fit, noise_m: float) -> Fit:
    """A fit that stands, or the same data fitted with more weakly determined directions held when
    it gives a generalized error beyond a plausible size (`weak.largest`). Real data fit well with
    every coefficient the data separate (the significance gate then judges them), so a direction is
    held only when the fit carries a value no robot has and holding it costs no more residual than
    the stated instrument noise noise_m (m per coordinate) explains (`_costs_only_noise`; a residual
    estimate holds what the model misses too, and would let a few poses hold anything); directions
    determined to within WIDEN times a plausible size are held in turn until every value is
    plausible. Returns the fit with the fewest held directions that lowers the largest value most."""
    size, where = weak.largest(cm, data, fit.c)
    if size <= 1.0:
        return fit
    best, best_size = fit, size
    for widen in WIDEN[1:] if fit.held else WIDEN:
        held = _identify(cm, data, *options, noise_m * widen, True)
        if held.failures or not _costs_only_noise(fit, held, noise_m):
            break
        after, _ = weak.largest(cm, data, held.c)
        if held.held and after < best_size:
            best, best_size = held, after
        if best_size <= 1.0:
            break
    if best is fit:
        return fit
    return replace(best, warnings=(
        f"the fit gives {where} {size:.3g} times a plausible size ({1e3 * weak.PLAUSIBLE_M:g} mm, "
        f"{1e3 * weak.PLAUSIBLE_RAD:g} mrad) along directions the data determine only weakly: refitted with those "
        f"held ({best_size:.3g} times at most), the residual {fit.train['rms_mm']:.4g} -> "
        f"{best.train['rms_mm']:.4g} mm rms, within the noise", *best.warnings))


def _costs_only_noise(full: Fit, held: Fit, noise_m: float) -> bool:
    """Whether the held fit's larger residual is what the noise alone makes of the coefficients it
    holds (their true values near zero): the rise in the weighted residual sum of squares within the
    HOLD_P chi-square quantile, in units of the instrument noise noise_m (m per coordinate)."""
    k_full, k_held = len(full.redundancy.kept), len(held.redundancy.kept)
    rss = [f.sigma_m ** 2 * max(f.measured_dof - k, 1.0) for f, k in ((full, k_full), (held, k_held))]
    return (rss[1] - rss[0]) / noise_m ** 2 <= noise_rise_limit(k_full - k_held)


def noise_rise_limit(k: int) -> float:
    """The HOLD_P quantile of the chi-square law with k (at least 1) degrees of freedom: how far, in units
    of the noise variance, holding k coefficients whose true values are near zero may raise the weighted
    residual sum of squares (scipy.special's inverse, not scipy.stats's: the same function without the
    import of scipy.stats, which loads scipy.optimize)."""
    return float(special.chdtri(max(k, 1), 1 - HOLD_P))


def _identify(cm: CompiledModel, data: Measurements, registration_mode: str, max_iter: int, step_tol_m: float,
              progress, ridge: float, rank_tol: float, loss: str, hold: dict[int, str], analysis: Analysis | None,
              noise_m: float | None, hold_weak: bool) -> Fit:
    """`identify`, with the weakly determined directions held (`_fit`'s hold_weak) or not; its notes
    not yet warned."""
    frames = fit_frames(cm, data, None, loss, registration_mode)
    weakly = {"noise_m": noise_m, "hold_weak": hold_weak}
    fit = _fit(cm, data, frames, max_iter, step_tol_m, progress, ridge, rank_tol, loss, hold, analysis=analysis,
               **weakly)
    begun = fit.analysis
    if data.relative is not None:
        # at c = 0 the rows of a socket scatter by the model's whole error, which lets a rigid motion
        # of the set look visible; at the fit they scatter by the noise: analysed again there
        again = _fit(cm, data, frames, max_iter, step_tol_m, progress, ridge, rank_tol, loss, hold, fit.c, **weakly)
        fit = replace(again, before=fit.before)
    if len(frames) > 1 and registration_mode != "never":
        first = min(frames)
        for _ in range(STATION_ROUNDS):
            # the first station keeps its frame: frame 0's errors stay relative to it as with one
            # station, rather than trading places with all the frames at once
            new = {**fit_frames(cm, data, fit.c, loss), first: frames[first]}
            gone = np.linalg.norm(to_world(new, data) - to_world(frames, data), axis=1)
            moved = float(np.max(gone, initial=0.0, where=~np.isnan(gone)))  # relative rows have no frame
            frames = new
            fit = replace(_fit(cm, data, frames, max_iter, step_tol_m, progress, ridge, rank_tol, loss, hold,
                               fit.c if data.relative is not None else None, **weakly), before=fit.before)
            if moved <= STATION_TOL_M:
                break
        else:
            fit = replace(fit, failures=(*fit.failures, f"the {len(frames)} station frames did not settle in "
                                         f"{STATION_ROUNDS} rounds (last move {1e3 * moved:.3g} mm): on this data "
                                         f"they are hard to tell from the robot's errors; measure more poses, "
                                         f"spread wider, from each station"))
    return replace(fit, analysis=begun)


def _fit(cm: CompiledModel, data: Measurements, frames: dict[int, Registration], max_iter: int, step_tol_m: float,
         progress, ridge: float, rank_tol: float, loss: str, hold: dict[int, str], at: np.ndarray | None = None,
         analysis: Analysis | None = None, noise_m: float | None = None, hold_weak: bool = True) -> Fit:
    """`identify` with the station frames held: Gauss-Newton on the coefficients, robustly weighted,
    from c = 0, the redundancy analysed at coefficients `at` (default 0; at 0, `analysis` where it serves).
    The robust unit is the measured row (`model.rows.Rows`): a point, or a frame whose
    residual length is scaled to three degrees of freedom and counts twice (`fit.robust`).
    With hold_weak, the coefficients whose direction the data determine weakly against the noise
    (noise_m, m per coordinate; None: the linearised fit's residual) are held at zero first
    (`fit.weak`)."""
    notes = []
    y = to_world(frames, data)
    nc = cm.dims.nc
    c = np.zeros(nc)
    rows = data.rows
    row_dof = rows.row_dof
    if at is not None or analysis is None or not analysis.serves(cm, y, rank_tol):
        analysis = Analysis(*_data_analysis(cm, data, y, rank_tol, rows.weight, at)[:2], cm.key, y, rank_tol)
    red, A0 = analysis.red, analysis.A0
    kept_held = ()  # a refit's weakly determined directions, held again as such (`identify`'s hold)
    if hold:
        stay = [i for i, j in enumerate(red.kept) if j not in hold]
        names = cm.model.coefficient_names(cm.robot)
        kept_held = tuple(hold[j] for j in red.kept if isinstance(hold.get(j), weak.Held))
        red = replace(red, kept=tuple(int(red.kept[i]) for i in stay),
                      eliminated=(*red.eliminated, *(
                          Eliminated(names[j], j, "held", hold[j].reason) if isinstance(hold[j], weak.Held)
                          else Eliminated(names[j], j, "insignificant", hold[j]) for j in red.kept if j in hold)))
        A0 = A0[:, [*stay, -1]]
    known = _known_rows(cm, data)
    m = float(row_dof.sum()) + known.n  # a known distance or plane relation is one more equation
    kept = np.array(red.kept, int)
    k = len(kept)
    if m <= k:
        raise ModelError(f"{data.source}: {m:.0f} measured coordinates for {k} identifiable coefficients; "
                         f"measure more poses or reduce the error model")
    scale = np.linalg.norm(A0[:, :k], axis=0)
    # a relative row whose point or plane has no other row says nothing (row_dof 0): it counts for nothing
    norm = np.sqrt(3 / np.where(row_dof > 0, row_dof, np.inf))
    count = row_dof / 3
    pos, rot, length = row_errors(cm, data, y, c)
    e = length * norm
    before = summary(pos, rot) | ({} if data.relative is None else fixture_measures(cm, data, None))
    limit = robust.outlier_limit(e, loss)
    wr = robust.weights(e, limit, loss)
    if loss == "l2" and data.relative is None:
        # [H_kept / scale | r] at c = 0 is A0 scaled up to an orthogonal factor: its R factor comes
        # from this small matrix rather than from a second pass over the data
        R = np.linalg.qr(np.column_stack([A0[:, :k] / scale, A0[:, k]]), mode="r")
        stale = False  # True once c (or the weights) moved on from those R was factored at
    else:
        stale = True
    # the analysis holds what relative data without a known distance leave of the scale
    held = tuple(weak.Held(e.param, e.index, None, None, e.detail)
                 for e in red.eliminated if e.detail == SCALE_HELD) + kept_held
    if hold_weak and k:
        if stale:  # the first round's R, robustly weighted: a gross outlier would pass for noise
            w = rows.weight * wr[rows.group]
            if data.relative is not None:
                known = known.at(robust.scale(row_errors(cm, data, y, c, w)[2] * norm))
            R, _ = qr_accumulate(rows_H_and_residual(cm, data, y, c, weights=w, known_sigma_m=known.sigma_m),
                                 kept, scale)
            stale = False  # the first round's R: the same c and weights
        first = float(row_dof @ wr) + known.n
        red, stay, more = _hold_weak(cm, data, red, R, scale, first, noise_m)
        if more:
            held += more
            kept, k, scale = kept[stay], len(stay), scale[stay]
            R = np.linalg.qr(R[:, [*stay, -1]], mode="r")  # the same rows' R factor over the columns left
    notes.extend(weak.said(held))
    converged, it, lam, why_not = False, 0, 0.0, f"Gauss-Newton did not converge in {max_iter} iterations"
    for it in range(1, max_iter + 1):
        w = rows.weight * wr[rows.group]
        if data.relative is not None:  # the points and planes as these weights fit them
            e = row_errors(cm, data, y, c, w)[2] * norm
            known = known.at(robust.scale(e))
        if stale:
            R, _ = qr_accumulate(rows_H_and_residual(cm, data, y, c, weights=w, known_sigma_m=known.sigma_m),
                                 kept, scale)
            stale = False
        Rk, z, x = R[:k, :k], R[:k, k], c[kept] * scale
        objective = robust.objective(e, limit, loss, count) + ridge * float(x @ x) + known.squares(c, w)
        full_step = damped_step(Rk, z, 0.0, ridge, x)
        predicted = np.linalg.norm(Rk @ full_step)
        if predicted / np.sqrt(m) < step_tol_m or predicted ** 2 <= RSS_TOL * objective:
            converged = True  # the step would change nothing a tracker resolves
            break
        for _ in range(16):
            trial = c.copy()
            trial[kept] += (full_step if lam == 0 else damped_step(Rk, z, lam, ridge, x)) / scale
            errors_trial = row_errors(cm, data, y, trial, w)
            e_trial = errors_trial[2] * norm
            trial_objective = (robust.objective(e_trial, limit, loss, count)
                               + ridge * float(np.sum((trial[kept] * scale) ** 2)) + known.squares(trial, w))
            if trial_objective < objective:
                break
            lam = 1e-6 if lam == 0 else 10 * lam
        else:
            why_not = ("the fit stalled: no step lowers the residual (strong nonlinearity or a poorly excited "
                       "model); measure poses that move the weak coefficients or reduce the model")
            break
        c, (pos, rot, _), e, lam, stale = trial, errors_trial, e_trial, (lam / 10 if lam > 1e-9 else 0.0), True
        new_limit = robust.outlier_limit(e, loss)
        settled = loss == "l2" or abs(new_limit - limit) <= 0.01 * limit
        limit, wr = new_limit, robust.weights(e, new_limit, loss)
        if progress:
            progress(it, 1e3 * np.sqrt(np.mean(e ** 2)))
        if settled and objective - trial_objective <= RSS_TOL * objective:  # stationary: further steps change nothing
            converged = True
            break
    w = rows.weight * wr[rows.group]
    if stale:
        R, _ = qr_accumulate(rows_H_and_residual(cm, data, y, c, weights=w, known_sigma_m=known.sigma_m),
                             kept, scale)
    Rk, rss = R[:k, :k], R[k, k] ** 2
    m_eff = float(row_dof @ wr) + known.n  # down-weighted rows count for their weight
    sigma = float(np.sqrt(rss / max(m_eff - k, 1)))
    sv = np.linalg.svd(Rk, compute_uv=False) if k else np.ones(1)  # k = 0: every coefficient held at zero
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    obs = float(np.exp(np.mean(np.log(np.maximum(sv, 1e-300)))) / np.sqrt(m)) if k else 0.0
    std = np.full(nc, np.nan)
    with np.errstate(all="ignore"):  # a singular system gives inf/NaN here, which is reported below
        try:
            if ridge > 0:
                inverse = np.linalg.inv(Rk.T @ Rk + ridge * np.eye(k))
            else:  # from R itself: (R^T R)^-1 would square its condition number, and at 1e9 lose every digit
                Rinv = solve_triangular(Rk, np.eye(k))
                inverse = Rinv @ Rinv.T
            cov = sigma ** 2 * inverse / np.outer(scale, scale)
        except np.linalg.LinAlgError:
            cov = np.full((k, k), np.inf)
        std[kept] = np.sqrt(np.abs(np.diag(cov)))
    failures = _fit_failures(cm, data, c, std, kept, converged, why_not)
    if ridge > 0:  # the hat matrix of ridge regression: A (A^T A + ridge I)^-1 A^T
        Rk = np.linalg.qr(np.vstack([Rk, np.sqrt(ridge) * np.eye(k)]), mode="r")
    suspects = _suspects(cm, data, y, c, w, kept, scale, Rk, rss, m_eff, rows.dof)
    notes.extend(map(str, suspects))
    if failures:
        failures.extend(map(str, suspects))
    if cond > SINGULAR:
        failures.append(f"H_e is numerically singular on this data (condition number {cond:.3g} of the scaled "
                        f"kept columns): some coefficients are not determined; see the redundancy analysis")
    if cond > ILL_CONDITIONED:
        notes.append(f"ill-conditioned: condition number {cond:.3g} of the scaled H_e; some coefficients are "
                     f"barely excited (see std), measure poses that move them or drop their terms")
    if m - k < k:
        notes.append(f"few measurements: {m:.0f} coordinates for {k} coefficients; uncertainties are large")
    flagged = np.nonzero(e > limit)[0]
    names = cm.robot.target_names
    outliers = []
    for g in flagged[np.argsort(-e[flagged])]:
        r = rows.first[g]
        target = names[data.target[r]]
        outliers.append(Outlier(int(data.file_rows[r]), int(data.pose_ids[data.pose[r]]),
                                cm.robot.vertex_of.get(target, (target,))[0], 1e3 * float(pos[g]), float(wr[g]),
                                None if np.isnan(rot[g]) else 1e3 * float(rot[g])))
    if len(flagged) > OUTLIER_SHARE * len(e):
        what = "rows" if rows.oriented.any() else "points"
        notes.append(f"{len(flagged)} of {len(e)} {what} are outliers: more than glitches usually make; the model "
                     f"may lack an effect (run diagnose) or the data mixes set-ups")
    inliers = e <= limit
    train_inliers = summary(pos[inliers], rot[inliers]) if inliers.any() else summary(pos, rot)
    train = summary(pos, rot) | ({} if data.relative is None else fixture_measures(cm, data, c))
    if data.relative is not None:
        notes.extend(stray_placements(cm, data, c))
    if train["rms_mm"] > before["rms_mm"]:
        failures.append(f"the fit leaves more position error than the nominal model ({train['rms_mm']:.4g} mm rms "
                        f"against {before['rms_mm']:.4g} mm): the data is not what the model describes (an "
                        f"orientation unit or convention, the wrong robot file or targets)")
    if train.get("rot_rms_mrad", 0.0) > 1e3 * ABSURD_ROTATION_RAD:
        failures.append(f"the fit leaves {train['rot_rms_mrad']:.4g} mrad rms of orientation error (limit "
                        f"{1e3 * ABSURD_ROTATION_RAD:g}): no instrument is that far off; check the orientation "
                        f"columns' unit and convention (docs/reference.md, \"Pose measurements\")")
    if not train_inliers["rms_mm"] <= 1e3 * ABSURD_TRANSLATION_M:
        failures.append(f"the fit leaves {train_inliers['rms_mm'] / 1e3:.3g} m rms at the measured points (limit "
                        f"{ABSURD_TRANSLATION_M:g} m): the robot file does not describe the measured robot, or its "
                        f"targets, or the data is not this robot's")
    return Fit(c=c, std=std, cov=cov, redundancy=red, registration=frames[min(frames)], registrations=frames,
               sigma_m=sigma,
               condition_number=cond, observability_index=obs, iterations=it, converged=converged,
               before=before, train=train, warnings=tuple(notes), failures=tuple(failures),
               loss=loss, outlier_limit_m=float(limit), weights=w, outliers=tuple(outliers),
               train_inliers=train_inliers,
               ranges=_ranges(cm, data), measured_dof=m_eff, suspects=suspects, analysis=analysis, held=held)


def _hold_weak(cm: CompiledModel, data: Measurements, red: Redundancy, R: np.ndarray, scale: np.ndarray, m: float,
               noise_m: float | None) -> tuple[Redundancy, list[int], tuple[weak.Held, ...]]:
    """`red` with the weakly determined coefficients (`fit.weak`) moved from kept to eliminated
    ("held"), the positions in red.kept of those left, and the held coefficients with why. R (k+1,
    k+1): the R factor of [H / scale | r] over red.kept at the fit's start, from m degrees of
    freedom; noise_m (m per coordinate) as `weak.hold` takes it, at most weak.NOISE_CAP_M estimated."""
    stay, held = weak.hold(cm, data, red.kept, R, scale, m, noise_m, weak.NOISE_CAP_M)
    if not held:
        return red, stay, ()
    red = replace(red, kept=tuple(int(red.kept[i]) for i in stay),
                  eliminated=tuple(sorted((*red.eliminated, *(Eliminated(h.param, h.index, "held", h.reason)
                                                               for h in held)), key=lambda e: e.index)))
    return red, stay, held


@dataclass(frozen=True)
class _Known:
    """The rows of the known distances and plane relations of relative data in a fit
    (`fit.relative.known_rows`): n of them, weighed against rows of per-coordinate noise sigma_m
    (m; None without any)."""

    cm: CompiledModel
    data: Measurements
    n: int = 0
    sigma_m: float | None = None

    def at(self, sigma_m: float) -> "_Known":
        return self if not self.n else replace(self, sigma_m=sigma_m)

    def squares(self, c: np.ndarray, w: np.ndarray) -> float:
        """Their weighted squared residuals (m^2) at coefficients c, point weights w (R,)."""
        if not self.n:
            return 0.0
        q, wr, aux = _poses_inputs(self.cm, self.data)
        p = self.cm.model_targets(q, wr, aux, c)[self.data.pose, self.data.target]
        return float(np.sum(relative.known_rows(self.data.relative, None, p, w, self.sigma_m)[1] ** 2))


def _known_rows(cm: CompiledModel, data: Measurements) -> _Known:
    n = 0 if data.relative is None else data.relative.n_known
    return _Known(cm, data, n, robust.SCALE_FLOOR_M if n else None)


#: step (rad or m) of the central differences that give a pose's reading columns
READING_STEP = 1e-6


def _suspects(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray, w: np.ndarray, kept: np.ndarray,
              scale: np.ndarray, Rk: np.ndarray, rss: float, m: float, dof: np.ndarray) -> tuple[Suspect, ...]:
    """The poses the other poses do not predict (`fit.influence`) in the fit at coefficients c
    (point weights w (R,), kept columns scaled by scale, R factor Rk, residual sum of squares rss
    (m^2) over m degrees of freedom, dof (R,) per point), each with the reading that explains it."""
    order = np.argsort(data.pose, kind="stable")  # the point order of rows_H_and_residual
    row_pose = np.repeat(data.pose[order], 3)
    blocks = ((H[:, kept] / scale, r) for H, r in rows_H_and_residual(cm, data, y, c, weights=w))
    drop, d = influence.deleted_residuals(blocks, row_pose, Rk, data.n_poses)
    pose_dof = np.bincount(data.pose, dof, data.n_poses)
    found, F = influence.suspects(drop, pose_dof, rss, m, len(kept))
    out, step = [], READING_STEP * np.eye(cm.robot.n)
    for p in found:
        points = order[data.pose[order] == p]
        q = np.vstack([data.q[p] + step, data.q[p] - step])
        n2 = len(q)
        moved = cm.model_targets(q, np.repeat(data.w[p:p + 1], n2, 0),
                                 np.repeat(data.aux_columns(cm.model.aux)[p:p + 1], n2, 0), c)[:, data.target[points]]
        G = (moved[:cm.robot.n] - moved[cm.robot.n:]).reshape(cm.robot.n, -1).T / (2 * READING_STEP)
        at = np.nonzero(row_pose == p)[0]
        j, change, share = influence.joint_turn(G * np.repeat(np.sqrt(w[points]), 3)[:, None], d[at])
        out.append(Suspect(int(data.file_rows[points].min()), int(data.pose_ids[p]),
                           1e3 * float(np.sqrt(3 * (d[at] @ d[at]) / pose_dof[p])), float(F[p]),
                           float(np.delete(F, found).max()), f"q{j + 1}", change, share,
                           "rad" if cm.robot.joints[j].kind == "R" else "m"))
    return tuple(out)


def prediction_std(cm: CompiledModel, fit: Fit, q, w=None, aux=None) -> np.ndarray:
    """Standard deviation (m) of the predicted position of every target, (N, nt), from the
    coefficient covariance: sqrt(trace(H_k cov H_k^T)) per target."""
    kept = np.array(fit.redundancy.kept, int)
    _, H = cm.model_targets(q, w, aux, fit.c, with_H=True)
    Hk = H[:, :, kept]
    var = np.einsum("nrk,kl,nrl->nr", Hk, fit.cov, Hk)
    return np.sqrt(var.reshape(len(Hk), cm.dims.nt, 3).sum(-1))


__all__ = ["Fit", "IDENTITY", "Outlier", "Suspect", "fit_frames", "identify", "position_errors", "prediction_std",
           "redundancy", "row_errors", "squared_error", "summary", "to_world"]
