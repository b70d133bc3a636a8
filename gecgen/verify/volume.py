"""Accuracy over a declared volume: the worst compensated error, with a stated confidence.

After compensation the robot's error at a pose x is what the calibrated model does not predict:

    e(x) = G(x) (c_true - c) + u(x),

G(x) (3, k) the rows of H_e of the stated point over the identified coefficients, c - c_true the
coefficients' estimation error (its covariance taken pose by pose, `pose_covariance`), and u(x) the
error the model's terms cannot describe. The statement is about max_x |e(x)| over the region, which
no single pose's standard deviation bounds: it is drawn jointly, by Monte Carlo. Each draw takes a
coefficient error from N(0, cov) and an unmodelled error independently at every sample, and records
the worst |e| over the samples. The bound is the `confidence` quantile of those worsts. "Does not
meet" is said only when the coefficients' uncertainty alone puts the worst past the tolerance in all
but a (1 - confidence) share of the draws (the unmodelled error is drawn pessimistically, so the low
quantile of the full worst is no evidence of failure), and nothing undermines the model's figures.

A bound read from residuals cannot see an effect the data never excited, so "meets" also needs a
statement that rests on no model (`Measured`): the errors the calibration leaves at held-out poses
measured inside the volume, read by order statistics. With n such poses drawn over the volume, the
k-th largest error is at least the share-p quantile of the volume's error with confidence
P(Binomial(n, p) <= n - k) (k = 1: 1 - p^n). The verdict is signed with the more cautious of the two.

The unmodelled error is read from measured residuals, less the measurement noise the user states
(instrument and repeatability). Where every pose measures three or more targets, it is a rigid motion
of the tool (`Unmodelled`): a tilt the model misses, hidden in the noise at targets near the flange,
grows with the lever arm to a point 40 cm above them, and a point-wise sigma would miss that. Without
a stated noise the whole residual counts as unmodelled error, which is safe and pessimistic.
Independent draws at every sample are pessimistic for a smooth unmodelled error and optimistic where
it is concentrated in one corner of the volume; docs/volume.md gives the coverage measured on
simulated truths.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy import special, stats

from gecgen.model.kinematics import sensor_wrench, tool_pose
from gecgen.model.measurements import Measurements, Poses
from gecgen.model.robot import Robot
from gecgen.model.validation import require
from gecgen.model.volume import Volume
from gecgen.fit.calibration import Calibration, extrapolation
from gecgen.fit.significance import clustered_covariance
from gecgen.runtime.compiled import FAILED, OUTSIDE_LIMITS, CompiledModel

#: place_at: a sample is solved when the point is this close to its place (m) within the limits
PLACED_M = 1e-9
#: place_at: Newton iterations per start, and random starts per sample before it counts as unreachable
NEWTON_STEPS, STARTS = 30, 4
#: rad or m: the central-difference step of a free joint
STEP = 1e-7
#: Newton steps on the wrench the sensor reads (the map is nearly linear: three settle it to rounding),
#: their difference step (N or N m), and the loop gain from which the reading is not settled
WRENCH_PASSES, WRENCH_STEP, LOOP_GAIN = 3, 1e-3, 0.5
#: coefficient draws per block of the Monte Carlo (memory: a few times 3 x samples x block doubles)
BLOCK = 250
#: samples times draws at most: the Monte Carlo keeps every sample's error of every draw (8 bytes each)
MAX_CELLS = 5e7


@dataclass(frozen=True)
class Samples:
    """The region's samples: q (N, n) joints, w (N, 6) the wrench the sensor reads, payload_kg (N,);
    point (N, 3) the stated tool-frame point (with a tool box) and target (N,) the stated target's
    index in robot.targets (-1 for a tool-box point); world (N, 3) where the nominal robot puts it, m;
    unreachable: samples of the declaration that no joints within the limits place."""

    q: np.ndarray
    w: np.ndarray
    payload_kg: np.ndarray
    point: np.ndarray
    target: np.ndarray
    world: np.ndarray
    unreachable: int


def _box(robot: Robot, volume: Volume) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = map(np.array, robot.sampling_box())
    for k, (a, b) in volume.joints.items():
        lo[k], hi[k] = a, b
    return lo, hi


def _placed(robot: Robot, q: np.ndarray, point: np.ndarray) -> np.ndarray:
    """World position (N, 3) of tool-frame points (N, 3) on the nominal robot."""
    T = tool_pose(robot, q)
    return np.einsum("nij,nj->ni", T[:, :3, :3], point) + T[:, :3, 3]


def _solve(robot: Robot, q: np.ndarray, point: np.ndarray, goal: np.ndarray, free: list[int]) -> np.ndarray:
    """Newton on the free joints so that the tool point (N, 3) sits at goal (3,): q (N, n) solved in
    place from its values as starts; (N,) True where it converged."""
    for _ in range(NEWTON_STEPS):
        r = goal - _placed(robot, q, point)
        J = np.empty((len(q), 3, len(free)))
        for i, k in enumerate(free):
            step = np.zeros(robot.n)
            step[k] = STEP
            J[:, :, i] = (_placed(robot, q + step, point) - _placed(robot, q - step, point)) / (2 * STEP)
        with np.errstate(all="ignore"):
            ok = np.abs(np.linalg.det(J)) > 1e-12
            delta = np.zeros((len(q), len(free)))
            delta[ok] = np.linalg.solve(J[ok], r[ok][..., None])[..., 0]
        q[:, free] += delta
    return np.linalg.norm(goal - _placed(robot, q, point), axis=1) < PLACED_M


def sample(robot: Robot, volume: Volume, rng: np.random.Generator) -> Samples:
    """volume.samples configurations drawn uniformly over the declared joint ranges and tool box,
    each with every payload; with place_at, the free joints solved from random starts."""
    lo, hi = _box(robot, volume)
    n = volume.samples
    q = rng.uniform(lo, hi, (n, robot.n))
    if volume.tool_box is not None:
        point = rng.uniform(volume.tool_box[0], volume.tool_box[1], (n, 3))
        target = np.full(n, -1)
    else:
        names = list(robot.targets)
        target = rng.choice([names.index(t) for t in volume.targets], n)
        point = np.array(list(robot.targets.values()), float)[target]
    unreachable = 0
    if volume.place_at is not None:
        free = volume.free(robot)
        joint_lo = np.array([j.lower for j in robot.joints])
        joint_hi = np.array([j.upper for j in robot.joints])
        todo = np.arange(n)
        for _ in range(STARTS):
            trial = q[todo]
            trial[:, free] = rng.uniform(lo[free], hi[free], (len(todo), len(free)))
            ok = _solve(robot, trial, point[todo], volume.place_at, free)
            ok &= ((trial >= joint_lo - 1e-9) & (trial <= joint_hi + 1e-9)).all(axis=1)
            q[todo[ok]] = trial[ok]
            todo = todo[~ok]
            if not len(todo):
                break
        unreachable = len(todo)
        keep = np.setdiff1d(np.arange(n), todo)
        q, point, target = q[keep], point[keep], target[keep]
    m = len(volume.payload_kg)
    q, point, target = np.vstack([q] * m), np.vstack([point] * m), np.tile(target, m)
    payload = np.repeat(np.array(volume.payload_kg, float), len(q) // m)
    w = sensor_wrench(robot, q, payload, volume.payload_at, np.array(robot.gravity, float))
    return Samples(q, w, payload, point, target, _placed(robot, q, point), unreachable)


def random_poses(robot: Robot, volume: Volume, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Poses to hold out, drawn at random over the volume as its statement needs them: n configurations
    (`sample`; fewer when some cannot be placed), each with one payload drawn from the volume's. Returns
    joints (m, n_joints) and payloads (m,) kg."""
    s = sample(robot, dataclasses.replace(volume, samples=n), rng)
    m = len(s.q) // len(volume.payload_kg)
    rows = rng.integers(len(volume.payload_kg), size=m) * m + np.arange(m)
    return s.q[rows], s.payload_kg[rows]


def read_wrench(cm: CompiledModel, c: np.ndarray, samples: Samples, volume: Volume) -> tuple[np.ndarray, float]:
    """The wrench (N, 6) the sensor reads at the samples on the calibrated robot, and the largest loop
    gain of that reading. The robot as built is tilted by its errors, so the sensor sees small force
    components the nominal robot does not, and a model may use them (fz*q3 stands for payload*q3 when
    the carriage tilts): predicting with the nominal wrench would misjudge it. The reading is the fixed
    point of wrench -> generalized errors -> wrench, by Newton; the loop gain is the spectral radius of
    that map's Jacobian, 1 or more where the model's tilt feeds itself through the reading."""
    gravity = np.array(cm.robot.gravity, float)
    aux = np.zeros((len(samples.q), cm.dims.naux))

    def reads(w):
        return sensor_wrench(cm.robot, samples.q, samples.payload_kg, volume.payload_at, gravity,
                             cm.eps(samples.q, w, aux, c))

    def jacobian(w):
        J = np.empty((len(w), 6, 6))
        for k in range(6):
            step = np.zeros(6)
            step[k] = WRENCH_STEP
            J[:, :, k] = (reads(w + step) - reads(w - step)) / (2 * WRENCH_STEP)
        return J

    w = samples.w
    for _ in range(WRENCH_PASSES):
        with np.errstate(all="ignore"):
            step = np.linalg.solve(jacobian(w) - np.eye(6), (reads(w) - w)[..., None])[..., 0]
        w = w - np.where(np.isfinite(step), step, 0.0)
    gain = float(np.abs(np.linalg.eigvals(jacobian(w))).max()) if len(w) else 0.0
    return w, gain


def point_rows(cm: CompiledModel, samples: Samples, c: np.ndarray, kept) -> np.ndarray:
    """G (N, 3, k): the rows of H_e of each sample's stated point over the kept coefficients. A
    tool-box point's rows are the affine combination of four tool points' (`affine_model`): a rigid
    tool moves every point of it by the same affine map, so the weights are exact."""
    aux = np.zeros((len(samples.q), cm.dims.naux))
    _, H = cm.model_targets(samples.q, samples.w, aux, c, with_H=True)
    H = H.reshape(len(H), cm.dims.nt, 3, cm.dims.nc)[..., list(kept)]
    if (samples.target >= 0).all():
        return H[np.arange(len(H)), samples.target]
    basis = np.array(list(cm.robot.targets.values()), float)  # origin corner, then one per axis
    u = (samples.point - basis[0]) / np.diag(basis[1:] - basis[0])
    weights = np.column_stack([1 - u.sum(axis=1), u])  # (N, 4): sum to one
    return np.einsum("nt,ntrk->nrk", weights, H)


def affine_model(robot: Robot, volume: Volume) -> Robot:
    """The robot whose targets are four tool points spanning the volume's tool box (its min corner and
    one step along each tool axis): every point of the box is an affine combination of them."""
    lo, hi = volume.tool_box
    span = np.where(hi > lo, hi - lo, 1.0)
    corners = [lo, *(lo + span[i] * np.eye(3)[i] for i in range(3))]
    return dataclasses.replace(robot, targets={f"box{i}": tuple(map(float, p)) for i, p in enumerate(corners)},
                               estimated=(), target_frames={})


#: poses with three or more targets needed to read the unmodelled error as a rigid tool motion
MIN_TWIST_POSES = 20
#: the unmodelled motion's variance is taken at the confidence limit it exceeds with this probability
UPPER = 0.05


def _skew(v: np.ndarray) -> np.ndarray:
    """[v]x (..., 3, 3): [v]x a = v x a."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1), np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def _factor(cov: np.ndarray) -> np.ndarray:
    """L with L L^T = cov for a symmetric positive semi-definite cov (rounding below zero dropped)."""
    vals, vecs = np.linalg.eigh((cov + cov.T) / 2) if len(cov) else (np.zeros(0), np.zeros((0, 0)))
    return vecs * np.sqrt(np.clip(vals, 0.0, None))


def pose_covariance(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray, kept) -> np.ndarray:
    """The coefficients' covariance (k, k) over `kept`, robust to what the fit's own assumes away: the
    points of a pose are independent only of other poses' (`fit.significance.clustered_covariance`)."""
    q, w, aux = data.q, data.w, data.aux_columns(cm.model.aux)
    p, H = cm.model_targets(q, w, aux, c, with_H=True)
    H = H.reshape(len(H), cm.dims.nt, 3, cm.dims.nc)[data.pose, data.target][..., list(kept)]  # (R, 3, k)
    r = y - p[data.pose, data.target]
    return clustered_covariance(H.reshape(-1, H.shape[-1]), r.ravel(), np.repeat(data.pose, 3), data.n_poses)


@dataclass(frozen=True)
class Unmodelled:
    """The error the model leaves, read from residuals (per coordinate residual_m, m):
    a rigid motion of the tool, xi = (translation m, rotation rad) in the tool frame ~ N(0, twist_cov),
    when the data measured three or more targets per pose; else a point error of sigma_m per
    coordinate (twist_cov None)."""

    residual_m: float
    sigma_m: float
    twist_cov: np.ndarray | None

    def maps(self, R: np.ndarray, point: np.ndarray) -> np.ndarray:
        """U (N, 3, d): the unmodelled error at tool-frame points (N, 3) of tools turned by R (N, 3, 3)
        is U z, z ~ N(0, I_d): R (t + r x point) for a tool motion (t, r)."""
        if self.twist_cov is None:
            return np.broadcast_to(self.sigma_m * np.eye(3), (len(point), 3, 3))
        A = np.concatenate([np.broadcast_to(np.eye(3), (len(point), 3, 3)), -_skew(point)], axis=2)
        return R @ A @ _factor(self.twist_cov)


def unmodelled(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray, noise_m: float | None,
               repeatability_m: float = 0.0, shrink: float = 1.0) -> Unmodelled:
    """The unmodelled error from residuals of measured points y (R, 3, world, m) of `data` at
    coefficients c, less the instrument's noise_m per point and coordinate (None: nothing taken off)
    and the robot's repeatability_m per pose and coordinate (it moves every target of a pose alike).
    shrink (>= 1) undoes what a fit took out of its own training residuals (m / (m - k)); 1 for
    held-out data. A pose's tool motion is fitted to its targets' residuals; the motions' covariance,
    less what the noise puts into them (noise_m^2 (A^T A)^-1 per pose, repeatability_m^2 on the
    translation), is the tool's. Noise stated as one figure is taken off per point, which leaves the
    repeatability's share in the motion: safe."""
    q, w, aux = data.q, data.w, data.aux_columns(cm.model.aux)
    r = y - cm.model_targets(q, w, aux, c)[data.pose, data.target]
    residual = float(np.sqrt(shrink * np.mean(r ** 2)))
    noise2 = (noise_m or 0.0) ** 2
    if noise_m is None:  # nothing taken off, as for the tool motion below
        repeatability_m = 0.0
    # point by point, the residual's variance at its upper confidence limit (r.size coordinates), less the noise
    upper = residual ** 2 * r.size / special.chdtri(r.size, 1 - UPPER)
    point = float(np.sqrt(max(upper - noise2 - repeatability_m ** 2, 0.0)))
    if cm.robot.branches:
        return Unmodelled(residual, point, None)
    R = tool_pose(cm.robot, q)[:, :3, :3]
    targets = np.array(list(cm.robot.targets.values()), float)
    S, noise_part, used = np.zeros((6, 6)), np.zeros((6, 6)), 0
    order = np.argsort(data.pose, kind="stable")
    for rows in np.split(order, np.flatnonzero(np.diff(data.pose[order])) + 1):
        if len(rows) < 3:
            continue
        p = data.pose[rows[0]]
        A = np.concatenate([np.broadcast_to(np.eye(3), (len(rows), 3, 3)), -_skew(targets[data.target[rows]])],
                           axis=2).reshape(-1, 6)
        AtA = A.T @ A
        if np.linalg.cond(AtA) > 1e12:  # collinear targets: a turn about their line is not seen
            continue
        xi = np.linalg.solve(AtA, A.T @ (r[rows] @ R[p]).ravel())
        S += np.outer(xi, xi)
        noise_part += np.linalg.inv(AtA)
        used += 1
    if used < MIN_TWIST_POSES:
        return Unmodelled(residual, point, None)
    seen = shrink * S / used
    noise = noise2 * noise_part / used + np.diag([repeatability_m ** 2] * 3 + [0.0] * 3)
    if noise_m is None or not np.all(np.linalg.eigvalsh(noise) > 0):
        return Unmodelled(residual, point, seen)
    # whitened by the noise, the motions' covariance is I plus the unmodelled part. Each direction's
    # variance is taken at its upper confidence limit (a variance of `used` poses: lam used / chi2):
    # a bound must not read "not detected" as "absent", least of all from a few held-out poses
    W = np.linalg.inv(np.linalg.cholesky(noise))
    lam, V = np.linalg.eigh(W @ seen @ W.T)
    excess = np.clip(lam * used / special.chdtri(used, 1 - UPPER) - 1, 0.0, None)
    Wi = np.linalg.inv(W)
    return Unmodelled(residual, point, Wi @ (V * excess) @ V.T @ Wi.T)


def poses_needed(share: float, confidence: float) -> int:
    """The fewest poses n whose largest error bounds the share-quantile with the confidence: the
    smallest n with 1 - share^n >= confidence."""
    n = max(1, int(np.ceil(np.log1p(-confidence) / np.log(share))))
    while 1 - share ** n < confidence:  # rounding of the logarithms
        n += 1
    return n


def order_statistic(errors: np.ndarray, share: float, confidence: float) -> tuple[int, float, float] | None:
    """(k, the k-th largest of errors (n,), the confidence that it is at least the share-quantile of the
    distribution they were drawn from): the largest k whose confidence P(Binomial(n, share) <= n - k)
    is at least `confidence` (k = 1: 1 - share^n); None when even the largest has less."""
    n = len(errors)
    k = 0
    while k < n and stats.binom.cdf(n - k - 1, n, share) >= confidence:
        k += 1
    if not k:
        return None
    return k, float(np.sort(errors)[::-1][k - 1]), float(stats.binom.cdf(n - k, n, share))


@dataclass(frozen=True)
class Measured:
    """The distribution-free statement from held-out poses measured inside the volume: poses (how many
    are inside; outside: how many are not), each pose's error the largest distance (mm) between a
    measured stated point and where the calibrated model puts it; share of the volume within error_mm
    (the rank-th largest error) with confidence `achieved` (at least the requested `confidence`);
    needed: the poses inside the volume the share needs at that confidence (rank 1). error_mm, rank
    and achieved are None when fewer than `needed` poses are inside."""

    poses: int
    outside: int
    share: float
    confidence: float
    needed: int
    rank: int | None
    error_mm: float | None
    achieved: float | None
    largest_mm: float | None

    def to_dict(self) -> dict:
        return {"n": self.poses, "outside": self.outside, "share": self.share, "confidence": self.confidence,
                "needed": self.needed, "rank": self.rank, "error_mm": self.error_mm,
                "achieved_confidence": self.achieved, "largest_error_mm": self.largest_mm}


def measured(errors_mm: np.ndarray, outside: int, share: float, confidence: float) -> Measured:
    """The distribution-free statement from the errors (n,) of the held-out poses inside the volume."""
    found = order_statistic(errors_mm, share, confidence)
    rank, error, achieved = found if found else (None, None, None)
    return Measured(len(errors_mm), outside, share, confidence, poses_needed(share, confidence), rank, error,
                    achieved, float(errors_mm.max()) if len(errors_mm) else None)


@dataclass(frozen=True)
class Statement:
    """The worst compensated error over the samples (mm): bound (the confidence quantile of the worst
    over Monte Carlo draws), lower (the 1 - confidence quantile of the worst the coefficients'
    uncertainty alone makes), parametric (the confidence quantile of that worst); per_point (N,) the
    confidence quantile of each sample's own error, for the map; worst (the sample where the bound is
    reached: the one most often the worst in the draws whose worst is the bound or more) and
    worst_share (the share of those draws it is the worst in); unmodelled_mm the unmodelled error's
    RMS per coordinate over the samples, read as a rigid tool motion or a point error
    (`unmodelled_as`); measured: the distribution-free statement from held-out poses (None without
    them); verdict against tolerance_mm."""

    bound_mm: float
    lower_mm: float
    parametric_mm: float
    per_point_mm: np.ndarray
    unmodelled_mm: float
    unmodelled_as: str
    residual_mm: float
    noise_mm: float | None
    confidence: float
    draws: int
    tolerance_mm: float | None
    verdict: str
    reasons: tuple[str, ...]
    worst: int
    worst_share: float
    measured: Measured | None

    def to_dict(self) -> dict:
        return {"bound_mm": self.bound_mm, "lower_mm": self.lower_mm, "parametric_bound_mm": self.parametric_mm,
                "unmodelled_rms_mm": self.unmodelled_mm, "unmodelled_as": self.unmodelled_as,
                "residual_sigma_mm": self.residual_mm, "noise_mm": self.noise_mm, "confidence": self.confidence,
                "draws": self.draws, "tolerance_mm": self.tolerance_mm, "verdict": self.verdict,
                "reasons": list(self.reasons),
                "measured": None if self.measured is None else self.measured.to_dict()}


def worst_over_draws(G: np.ndarray, cov: np.ndarray, U: np.ndarray, draws: int,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Monte Carlo of e = G dc + U z: G (N, 3, k), dc ~ N(0, cov (k, k)); U (N, 3, d), z ~ N(0, I_d)
    independently per sample. Returns worst |e| per draw (draws,), worst |G dc| per draw (draws,)
    and |e| per sample and draw (N, draws), all in m."""
    L = _factor(cov)
    N = len(G)
    flat = G.reshape(3 * N, -1)
    worst, worst_param, norms = [], [], []
    for start in range(0, draws, BLOCK):
        b = min(BLOCK, draws - start)
        e = (flat @ (L @ rng.standard_normal((L.shape[1], b)))).reshape(N, 3, b)
        worst_param.append(np.linalg.norm(e, axis=1).max(axis=0))
        e += U @ rng.standard_normal((N, U.shape[2], b))
        n = np.linalg.norm(e, axis=1)
        worst.append(n.max(axis=0))
        norms.append(n)
    return np.concatenate(worst), np.concatenate(worst_param), np.hstack(norms)


def _ordinal(k: int) -> str:
    return {1: "largest", 2: "2nd largest", 3: "3rd largest"}.get(k, f"{k}th largest")


def _measured_reasons(m: Measured, tolerance_mm: float) -> tuple[list[str], list[str]]:
    """(what keeps the measured statement from signing, what it states)."""
    where = f"{m.poses} held-out poses lie inside the volume" + (f" ({m.outside} outside it)" if m.outside else "")
    if m.rank is None:
        return [f"{where}: a statement that rests on no model, {m.share:.0%} of the volume within the largest "
                f"measured error at {m.confidence:.0%} confidence, needs at least {m.needed} (1 - {m.share:g}^n >= "
                f"{m.confidence:g}); measure {m.needed - m.poses} more held-out poses inside the volume, drawn at "
                f"random over it"], []
    said = (f"measured, without a model: {m.share:.0%} of the volume within {m.error_mm:.3g} mm (the "
            f"{_ordinal(m.rank)} error of the {m.poses} held-out poses inside it) with {m.achieved:.1%} confidence, "
            f"taking those poses as drawn at random over the volume; their errors include the instrument's noise")
    if m.error_mm > tolerance_mm:
        return [f"{where}: the {_ordinal(m.rank)} of their errors is {m.error_mm:.3g} mm, above the tolerance, so "
                f"the measured poses do not support it"], [said]
    return [], [said]


#: what a statement without a stated noise says of it (`state`'s unstated)
NO_NOISE = ("no measurement noise stated (--noise-mm): the whole residual is counted as error the model does not "
            "describe, so the bound is pessimistic")


def state(G: np.ndarray, cov: np.ndarray, U: np.ndarray, unmod: Unmodelled, noise_m: float | None,
          tolerance_mm: float | None, confidence: float, draws: int, rng: np.random.Generator,
          blocks: list[str], doubts: list[str], notes: list[str], held: Measured | None = None,
          unstated: str = NO_NOISE) -> Statement:
    """The statement for rows G (N, 3, k), coefficient covariance cov (k, k) and unmodelled error
    maps U (N, 3, d) (`Unmodelled.maps`); noise_m the stated noise per coordinate (None: unknown).
    blocks: what undermines the model's figures (the verdict is then "cannot tell", whatever they
    say); doubts: what keeps the bound from being signed ("cannot tell" unless the coefficients'
    uncertainty alone fails the tolerance, when they are left out as moot); notes: what the reader
    must know; held: the distribution-free statement from held-out poses inside the volume, which
    "meets" needs beside the bound."""
    worst, worst_param, norms = worst_over_draws(G, cov, U, draws, rng)
    # the bound takes the unmodelled error pessimistically, so its low quantile is no evidence of failure:
    # "does not meet" needs the coefficients' own uncertainty to push the worst past the tolerance
    bound, lower = 1e3 * float(np.quantile(worst, confidence)), 1e3 * float(np.quantile(worst_param, 1 - confidence))
    # where the bound is reached: the sample most often the worst in the draws at or past it
    at = np.argmax(norms[:, worst >= np.quantile(worst, confidence)], axis=0)
    counts = np.bincount(at, minlength=len(G))
    if noise_m is None:
        notes = [unstated, *notes]
    if tolerance_mm is None:
        verdict, reasons = "no tolerance given", blocks + doubts + notes
    elif blocks:
        verdict, reasons = "cannot tell", blocks + doubts + notes
    elif lower > tolerance_mm:
        verdict = "does not meet"
        reasons = [f"the coefficients' uncertainty alone puts the worst error above the tolerance in all but "
                   f"{1 - confidence:.0%} of the draws ({lower:.3g} mm, against {tolerance_mm:.3g} mm)", *notes]
    else:
        short, said = _measured_reasons(held, tolerance_mm) if held is not None else ([], [])
        over = ([f"the bound, {bound:.3g} mm at {confidence:.0%}, is above the tolerance"]
                if bound > tolerance_mm else [])
        reasons = over + doubts + short + said + notes
        verdict = "cannot tell" if over or doubts or short else "meets"
    rms_u = float(np.sqrt(np.einsum("nrd,nrd->", U, U) / (3 * len(U))))
    return Statement(bound, lower, 1e3 * float(np.quantile(worst_param, confidence)),
                     1e3 * np.quantile(norms, confidence, axis=1), 1e3 * rms_u,
                     "point" if unmod.twist_cov is None else "rigid tool motion", 1e3 * unmod.residual_m,
                     None if noise_m is None else 1e3 * noise_m, confidence, draws, tolerance_mm, verdict,
                     tuple(reasons), int(np.argmax(counts)), float(counts.max() / len(at)), held)


def _outside(calib: Calibration, q: np.ndarray, w: np.ndarray) -> dict[str, int]:
    """{input: samples} outside the training ranges at joints q (N, n) and wrenches w (N, 6): every joint
    (each moves the chain), and the forces the model's terms read (a force no term reads is no
    extrapolation; the payload is checked apart, `_heavier`)."""
    used = calib.model.variables() | {f"q{i + 1}" for i in range(calib.robot.n)}
    return {k: n for k, n in extrapolation(calib, q, w, np.zeros((len(q), 0))).items() if k in used}


#: how a reason begins when samples (or their compensated commands) leave the training ranges:
#: the next step is then to train over them (`report.verdict.accuracy_next_step`)
OUTSIDE_TRAINING = "samples outside the ranges the calibration was fitted over"
COMPENSATED_OUTSIDE = "samples whose compensated command leaves the ranges the calibration was fitted over"


def _per_input(robot, counts: dict[str, int], n: int, what: str) -> str:
    """'what, per input: q4 (theta) 4, fz 10 (of n)': a joint's reading named with its joint, as the
    extrapolation warnings name it."""
    def name(k: str) -> str:
        return f"{k} ({robot.joints[int(k[1:]) - 1].name})" if k[0] == "q" and k[1:].isdigit() else k

    return f"{what}, per input: {', '.join(f'{name(k)} {v}' for k, v in counts.items())} (of {n})"


def _commanded_span(calib: Calibration, q_c: np.ndarray, names: dict[str, int]) -> str:
    """The span (in the robot file's angle unit, m for a prismatic joint) the compensated commands
    q_c (N, n) take on each named input, against the training range."""
    ranges = calib.report.get("training_ranges") or {}
    parts = []
    for name in (n for n in names if n in ranges and n[0] == "q" and n[1:].isdigit()):
        k = int(name[1:]) - 1
        scale, unit = ((np.degrees(1.0) if calib.robot.angle_unit == "deg" else 1.0, calib.robot.angle_unit)
                       if calib.robot.joints[k].kind == "R" else (1.0, "m"))
        lo, hi = ranges[name]
        parts.append(f"{calib.robot.joints[k].name} {scale * q_c[:, k].min():.4g} to {scale * q_c[:, k].max():.4g} "
                     f"{unit} (trained over {scale * lo:.4g} to {scale * hi:.4g})")
    return "; ".join(parts)


def _findings(calib: Calibration, data: Poses, samples: Samples, q_c: np.ndarray, status: np.ndarray,
              gain: float, held_out: bool, n_columns: int,
              n_declared: int) -> tuple[list[str], list[str], list[str]]:
    """(blocks, doubts, notes) about a statement: what undermines the model's figures (no verdict but
    "cannot tell"), what keeps it from being signed, and what it assumes."""
    blocks, doubts, notes, n = [], [], [], len(samples.q)
    outside = _outside(calib, samples.q, samples.w)
    if outside:
        doubts.append(_per_input(calib.robot, outside, n, OUTSIDE_TRAINING) +
                      ": the model is not validated there")
    force, carried = (np.linalg.norm(x[:, :3], axis=1) for x in (samples.w, data.w))
    heavier = int(((force < carried.min() - 1.0) | (force > carried.max() + 1.0)).sum())  # 1 N: the sensor's tilt
    if heavier:
        doubts.append(f"{heavier} of {n} samples carry a payload the data never carried (force {force.min():.4g} to "
                      f"{force.max():.4g} N against {carried.min():.4g} to {carried.max():.4g} N measured): the "
                      f"model's load terms are not validated there")
    if gain >= LOOP_GAIN:
        blocks.append(f"the model turns the tool by the force its own tilt makes the sensor read (loop gain "
                      f"{gain:.2g}): what it predicts depends on a reading it cannot settle; drop the force terms "
                      f"gravity does not excite (e.g. fx, fz when the tool stays level)")
    failed = int(np.isin(status, FAILED).sum())
    if failed:
        blocks.append(f"the calibration's compensation does not converge at {failed} of {n} samples (singular, or "
                      f"the model's correction not settling there): the robot cannot be corrected there")
    if data.n_poses < 2 * n_columns:
        blocks.append(f"{data.n_poses} poses for {n_columns} coefficients: the covariance taken pose by pose needs "
                      f"at least twice as many poses as coefficients ({2 * n_columns}); until then neither bound can "
                      f"be trusted")
    if not held_out:
        doubts.append("the bound rests on the training residuals alone, which cannot show an effect the model lacks "
                      "where the poses did not reach (docs/volume.md): measure held-out poses inside the volume, at "
                      "random over it, and give them as --val to sign it")
    limits = ((q_c < [j.lower for j in calib.robot.joints]) | (q_c > [j.upper for j in calib.robot.joints]))
    beyond = {f"q{i + 1}": int(k) for i, k in enumerate(limits[status == OUTSIDE_LIMITS].sum(axis=0)) if k}
    if beyond:
        notes.append(_per_input(calib.robot, beyond, n, "samples whose compensated command leaves the joint limits") +
                     ": the statement holds there only if the controller may go beyond them; narrow the declared "
                     "ranges otherwise")
    moved = {k: v for k, v in _outside(calib, q_c, samples.w).items() if k not in outside}
    if moved:
        doubts.append(_per_input(calib.robot, moved, n, COMPENSATED_OUTSIDE) +
                      ": compensation moves joints beyond what the data moved, and the error of that motion is not "
                      "in the bound; measure with them moving over what compensation needs: " +
                      _commanded_span(calib, q_c, moved))
    if samples.unreachable:
        notes.append(f"{samples.unreachable} of {n_declared} declared samples cannot be placed within the joint "
                     f"limits; the statement covers the others")
    return blocks, doubts, notes


#: held-out poses count as inside the volume within this of its declared joint ranges and tool box (m or rad)
INSIDE = 1e-6
#: ... and within this of the forces its samples carry (N: the sensor's tilt, as for the payload check)
INSIDE_N = 1.0


def held_out_errors(calib: Calibration, volume: Volume, samples: Samples, data: Measurements,
                    y: np.ndarray) -> tuple[np.ndarray, int]:
    """The error (mm) at each held-out pose inside the volume, and how many poses are not inside: a
    pose is inside when its joints listed in the volume lie in their ranges, its force within those
    the samples carry, and, with place_at, the stated point placed there lies in the tool box (or is
    the stated target); its error is the largest distance between a measured stated point (a target
    in the tool box, or a stated target) and where the calibrated model puts it. y (R, 3): data's
    measured points in the calibration's world, m."""
    robot = calib.robot
    names = list(robot.targets)
    points = np.array(list(robot.targets.values()), float)
    if volume.tool_box is not None:
        lo, hi = volume.tool_box
        stated = ((points >= lo - INSIDE) & (points <= hi + INSIDE)).all(axis=1)
    else:
        stated = np.isin(names, volume.targets)
    ok = np.ones(data.n_poses, bool)
    for k, (a, b) in volume.joints.items():
        ok &= (data.q[:, k] >= a - INSIDE) & (data.q[:, k] <= b + INSIDE)
    force, carried = (np.linalg.norm(x[:, :3], axis=1) for x in (data.w, samples.w))
    ok &= (force >= carried.min() - INSIDE_N) & (force <= carried.max() + INSIDE_N)
    if volume.place_at is not None:
        T = tool_pose(robot, data.q)
        there = np.einsum("nji,nj->ni", T[:, :3, :3], volume.place_at - T[:, :3, 3])  # place_at in the tool frame
        if volume.tool_box is not None:
            ok &= ((there >= volume.tool_box[0] - INSIDE) & (there <= volume.tool_box[1] + INSIDE)).all(axis=1)
        else:
            ok &= (np.linalg.norm(there[:, None] - points[stated], axis=2) <= INSIDE).any(axis=1)
    cm = CompiledModel(robot, calib.model)
    model = cm.model_targets(data.q, data.w, data.aux_columns(cm.model.aux), calib.c)[data.pose, data.target]
    err = np.where(stated[data.target], np.linalg.norm(y - model, axis=1), -np.inf)
    per_pose = np.full(data.n_poses, -np.inf)
    np.maximum.at(per_pose, data.pose, err)
    inside = ok & np.isfinite(per_pose)
    return 1e3 * per_pose[inside], int((~inside).sum())


#: DATA is taken for the data the calibration was fitted to when its RMS residual is within this share
SAME_FIT = 1e-6


def _require_fitted(calib: Calibration, cm: CompiledModel, data: Measurements, y: np.ndarray):
    """Refuse data that is not what the calibration was fitted to: its residual RMS at the calibration's
    coefficients must be the fit's own training RMS (the covariance is taken pose by pose from it)."""
    train = calib.report.get("train", {}).get("rms_mm")
    if train is None:
        return
    p = cm.model_targets(data.q, data.w, data.aux_columns(cm.model.aux), calib.c)[data.pose, data.target]
    rms = 1e3 * float(np.sqrt(np.mean(np.sum((y - p) ** 2, axis=1))))
    require(abs(rms - train) <= SAME_FIT * train + 1e-9,
            f"{data.source}: not the data the calibration was fitted to (its RMS residual is {rms:.4g} mm, the fit's "
            f"{train:.4g} mm); give the training data, and held-out data as --val")


def _inliers(calib: Calibration, data: Measurements, y: np.ndarray) -> tuple[Measurements, np.ndarray, int]:
    """The data without the rows the fit found to be outliers (its report's file rows), their world
    points, and how many were left out: a glitch the robust fit down-weighted must not count as
    model error here either."""
    bad = {o["row"] for o in calib.report.get("outliers", [])}
    keep = ~np.isin(data.file_rows, list(bad))
    return (data, y, 0) if keep.all() else (data.rows_of(keep), y[keep], int((~keep).sum()))


def accuracy(calib: Calibration, volume: Volume, data: Measurements, y: np.ndarray,
             held_out: tuple[Measurements, np.ndarray] | None, noise_m: float | None, repeatability_m: float,
             tolerance_mm: float | None, confidence: float, draws: int,
             rng: np.random.Generator, share: float = 0.95) -> tuple[Samples, Statement, CompiledModel]:
    """The statement for a calibration over a declared volume from the data it was fitted to (world
    points y (R, 3), m): the coefficients' covariance by pose (`pose_covariance`), and the unmodelled
    error (`unmodelled`) from a held-out set (data, world points) when given, else from the fit's
    residuals scaled up for the coefficients fitted to them; less the stated instrument noise and
    robot repeatability per coordinate (m); with held-out data, the share of the volume the measured
    statement (`Measured`) is about. Returns the samples, the statement, and the compiled model whose
    targets are the stated points (the tool box's affine basis, or the robot's)."""
    _require_draws(draws, confidence)
    fitted = CompiledModel(calib.robot, calib.model)
    _require_fitted(calib, fitted, data, y)
    data, y, dropped = _inliers(calib, data, y)
    columns = held_columns(calib)
    cov = pose_covariance(fitted, data, y, calib.c, columns)
    m = 3 * len(data.xyz)
    residuals, shrink = held_out or (data, y), 1.0 if held_out else m / max(m - len(calib.kept), 1)
    unmod = unmodelled(fitted, *residuals, calib.c, noise_m, repeatability_m, shrink)
    notes = [f"{dropped} measured rows the fit found to be outliers are left out of the covariance and the "
             f"unmodelled error"] if dropped else []
    return stated(calib, volume, data, columns, cov, unmod, held_out, noise_m, tolerance_mm, confidence, draws, rng,
                  share, notes)


def held_columns(calib: Calibration) -> list[int]:
    """The coefficients the statement's covariance is over: those fitted, and those held at zero for want
    of significance, which are not known to be zero and stay uncertain."""
    names = calib.model.coefficient_names(calib.robot)
    held = {names.index(e["param"]) for e in calib.report.get("eliminated", []) if e["reason"] == "insignificant"}
    return sorted(set(calib.kept) | held)


def _require_draws(draws: int, confidence: float):
    require(draws >= 20 / (1 - confidence) if confidence < 1 else False,
            f"{draws} draws for a {confidence:g} confidence: give at least {20 / max(1 - confidence, 1e-12):.0f} "
            f"(20 beyond the quantile), or a lower confidence")


def stated(calib: Calibration, volume: Volume, poses, columns: list[int], cov: np.ndarray, unmod: Unmodelled,
           held_out: tuple[Measurements, np.ndarray] | None, noise_m: float | None, tolerance_mm: float | None,
           confidence: float, draws: int, rng: np.random.Generator, share: float,
           notes: list[str], unstated: str = NO_NOISE,
           frame_rows=None) -> tuple[Samples, Statement, CompiledModel]:
    """`accuracy`'s statement from what it read off the data: the training poses (`Poses`: their count
    and the forces they carried), the covariance cov of c[columns], the unmodelled error, the held-out
    (data, world points) when given, and notes of how they were read (said after the statement's own);
    unstated: what it says of the noise when none is stated (noise_m None); frame_rows: with a reference
    frame fitted with the coefficients (fixed cameras, a board), a function of the stated points (N, 3), m,
    giving how they move against it with its m parameters (N, 3, m), cov then being over those parameters
    and c[columns] together (in that order): the error is bounded against that frame."""
    _require_draws(draws, confidence)
    samples = sample(calib.robot, volume, rng)
    require(len(samples.q), f"{volume.source}: no sample can be placed within the joint limits; check place_at, "
                            f"the tool box and the joint ranges against the robot")
    require(len(samples.q) * draws <= MAX_CELLS, f"{volume.source}: {len(samples.q)} samples (with their payloads) "
                                                 f"times {draws} draws is more than {MAX_CELLS:.0e} errors to draw; "
                                                 f"give fewer samples or draws")
    robot = affine_model(calib.robot, volume) if volume.tool_box is not None else calib.robot
    cm = CompiledModel(robot, calib.model)
    w, gain = read_wrench(cm, calib.c, samples, volume)
    samples = dataclasses.replace(samples, w=w)
    U = unmod.maps(tool_pose(calib.robot, samples.q)[:, :3, :3], samples.point)
    q_c, status = cm.compensate(samples.q, samples.w, None, calib.c)
    blocks, doubts, own = _findings(calib, poses, samples, q_c, status, gain, held_out is not None, len(columns),
                                    volume.samples)
    held = None if held_out is None else measured(*held_out_errors(calib, volume, samples, *held_out), share,
                                                  confidence)
    own += notes
    if unmod.twist_cov is None and volume.tool_box is not None:
        own.append("the unmodelled error is read point by point (fewer than three targets a pose, or too few such "
                   "poses): a tilt's growth with the lever arm to the tool box is not in it")
    G = point_rows(cm, samples, calib.c, columns)
    if frame_rows is not None:
        G = np.concatenate([frame_rows(samples.world), G], axis=2)
    statement = state(G, cov, U, unmod, noise_m, tolerance_mm, confidence, draws, rng, blocks, doubts, own, held,
                      unstated)
    return samples, statement, cm


__all__ = ["Measured", "Samples", "Statement", "Unmodelled", "accuracy", "affine_model", "held_columns",
           "held_out_errors", "measured",
           "order_statistic", "point_rows", "pose_covariance", "poses_needed", "random_poses", "read_wrench",
           "sample", "state", "stated", "unmodelled", "worst_over_draws"]
