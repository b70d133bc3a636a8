"""Optimal experiment design: which poses to measure so that the calibration learns the most.

The measured target errors are linear in the coefficients through H_e, so the information a set
of poses carries about them is M = sum_p H_p^T H_p (H_p: the 3 nt rows of the measured targets at
pose p, nt targets, over the identifiable coefficients). Over a finite set of candidate poses the
design either maximises log det M (criterion "D", D-optimality: the smallest joint confidence
region of the coefficients) or minimises tr(M^-1 W), W the candidates' mean information per pose
(criterion "I", I-optimality: the mean over the candidates of the predicted variance of the
measured positions, what a validation RMS over poses like the candidates measures):

* columns: the coefficients the structural analysis keeps for the measured targets, less those
  no candidate excites (a wrench term when every candidate carries the same load); the reported
  log det scales each column by its RMS over the candidates, so metres and radians, newtons and
  squared joint angles weigh alike. The search itself runs in whitened coordinates (the mean
  candidate informs every direction alike, W = I): D-optimal choices do not depend on a linear
  change of the coefficients, only log det's constant does, and I's criterion becomes tr(M^-1);
* greedy start: the pose with the largest gain, log det(I + D_i) for D (the matrix determinant
  lemma for a block of 3 nt rows) or the fall tr((I + D_i)^-1 E_i) of tr(M^-1) for I (Woodbury),
  D_i = H_i M^-1 H_i^T and E_i = H_i M^-2 H_i^T of every candidate updated by Woodbury after each
  pick. A small ridge makes M invertible before the chosen poses span every coefficient;
* exchanges (Fedorov, one chosen pose at a time): remove pose j (M_-j), find the candidate i with
  the largest gain against M_-j, swap when that improves the criterion by more than SWAP_TOL
  (on a log scale: log det M, or -log tr(M^-1)), each swap checked again from the inverse, so the
  criterion never worsens; passes over the chosen poses until one gains less than PASS_TOL, or
  MAX_PASSES;
* scale: candidates' H_e is computed in blocks of BLOCK poses; at most MAX_POOL candidates (and
  POOL_BYTES of their H_e, in single precision) are held at once. With more, the pool is the
  candidates of largest gain against the information N average candidates would give, and after
  the exchange the whole set is screened again against the design (MAX_ROUNDS times): a candidate
  outside the pool enters when its gain ranks it there. An exchange pass spends at most
  EXCHANGE_BUDGET multiply-adds per chosen pose: on a larger pool it tries the candidates of
  largest gain and a fresh random sample of the rest each pass.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from gecgen.model.kinematics import sensor_wrench, tool_poses
from gecgen.model.measurements import LIMIT_TOLERANCE, Measurements, read_commands
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.validation import ModelError, require
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import qr_accumulate, rows_H_and_residual, structural_analysis
from gecgen.fit.redundancy import Redundancy, unexcited
from gecgen.runtime.threads import one_blas_thread
from gecgen.simulate.designs import random_design, with_payloads

#: poses whose H_e is evaluated at once (the PPS default model: 12 x 330 doubles per pose, 63 MB)
BLOCK = 2000
#: candidates whose whitened H_e the search holds in memory at once, and the bytes that may take
MAX_POOL = 10_000
POOL_BYTES = 256 * 2 ** 20
#: candidates (a random sample of more) whose H_e decides what is excited and the whitening: the
#: mean information of 20,000 i.i.d. poses is within a few per cent of that of any more
BASIS_SAMPLE = 20_000
#: ridge on the whitened information (the mean candidate adds the identity): keeps M invertible
#: while the greedy start spans the coefficients (a new direction then gains log(1/RIDGE) = 7, far
#: above what strengthening a spanned one gains), and negligible once N poses inform every one
RIDGE = 1e-3
#: a swap must raise the objective (log det M, or -log tr(M^-1)) by more than this; smaller gains
#: are rounding and could cycle
SWAP_TOL = 1e-6
#: exchange passes stop when one raises the objective by less than this (det, or 1 / tr(M^-1), by
#: 1%; for k coefficients the confidence ellipsoid's axes by 1/k % on average) or after MAX_PASSES
PASS_TOL = 1e-2
MAX_PASSES = 10
MAX_ROUNDS = 1
#: multiply-adds an exchange trial may spend on the candidates (T r^2 (k + r) for T candidates, twice
#: that for a criterion that uses E_i = H_i M^-2 H_i^T as well)
EXCHANGE_BUDGET = 2e7
DEFAULT_CRITERION = "D"
N_VALIDATION = 500
NOISE_M = 5e-5


@dataclass(frozen=True)
class Candidates:
    """Poses a design may choose from. q (K, n) m or rad; w (K, 6) the wrench at the sensor, N and
    N m in the sensor frame; aux (K, naux) the model's auxiliary signals; payload_kg (K,) the
    payload behind the wrench, or None when the wrench came from a file."""

    q: np.ndarray
    w: np.ndarray
    aux: np.ndarray
    payload_kg: np.ndarray | None = None
    has_wrench: bool = False  # the wrench is part of the pose (payloads, or wrench columns in the file)

    def __len__(self) -> int:
        return len(self.q)

    def subset(self, idx) -> "Candidates":
        return Candidates(self.q[idx], self.w[idx], self.aux[idx],
                          None if self.payload_kg is None else self.payload_kg[idx], self.has_wrench)


def uniform_candidates(robot: Robot, n: int, rng: np.random.Generator, payloads_kg=None,
                       gravity=None) -> Candidates:
    """n poses uniform within the joint limits (continuous joints within +-pi), as `gecgen simulate
    --design random` draws them: with payloads (kg), each pose carries one drawn at random, at the
    tool origin, and the wrench is what the sensor reads of its weight (gravity (3,), m/s^2, world;
    None: the robot file's)."""
    design = random_design(robot, n, rng, payloads_kg if payloads_kg is not None else (0.0,))
    if payloads_kg is None:
        return Candidates(design.q, np.zeros((n, 6)), np.zeros((n, 0)))
    return Candidates(design.q, sensor_wrench(robot, design.q, design.payload_kg, design.payload_at,
                                              _gravity(robot, gravity)), np.zeros((n, 0)), design.payload_kg, True)


def _gravity(robot: Robot, gravity) -> np.ndarray:
    """The gravity (3,) m/s^2 in the world: the given one, else the robot file's."""
    return np.array([float(v) for v in (robot.gravity if gravity is None else gravity)])


def file_candidates(path, robot: Robot, aux_names: tuple[str, ...], payloads_kg=None, gravity=None) -> Candidates:
    """The allowed configurations of a CSV: q1..qn, optional wrench fx..mz and the model's aux
    columns. With payloads (kg) and no wrench columns, every row is offered with every payload
    (the wrench as in `uniform_candidates`). A joint outside its limits is refused with its row."""
    c = read_commands(path, robot, aux_names)
    lo = np.array([j.lower for j in robot.joints]) - LIMIT_TOLERANCE
    hi = np.array([j.upper for j in robot.joints]) + LIMIT_TOLERANCE
    out = np.argwhere((c.q < lo) | (c.q > hi))
    if len(out):
        r, j = out[0]
        raise ModelError(f"{path}: row {r + 2}, column 'q{j + 1}': {c.q[r, j]:g} is outside the joint limits "
                         f"[{robot.joints[j].lower:g}, {robot.joints[j].upper:g}]; fix the row or the robot file")
    has_wrench = any(col in c.header for col in WRENCH)
    if payloads_kg is None:
        return Candidates(c.q, c.w, c.aux, None, has_wrench)
    require(not has_wrench, f"--payload-kg: {path} has wrench columns already; drop them or the option")
    q, payload, _ = with_payloads(c.q, payloads_kg, "from")
    w = sensor_wrench(robot, q, payload, np.zeros(3), _gravity(robot, gravity))
    return Candidates(q, w, np.vstack([c.aux] * len(payloads_kg)), payload, True)


def constraint_mask(robot: Robot, cands: Candidates, targets: np.ndarray, min_z: float | None = None,
                    tracker=None, max_incidence_deg: float | None = None) -> np.ndarray:
    """(K,) True where a candidate satisfies the constraints on the nominal model: every measured
    target (indices into robot.targets) at world z >= min_z (m); and, with a tracker position (3,)
    in the world (m), the line of sight from each measured target to the tracker within
    max_incidence_deg of the tool z axis (a reflector facing along tool z)."""
    tools = np.stack(tool_poses(robot, cands.q))  # (branches, K, 4, 4)
    T = tools[[robot.branch_of(robot.target_names[t]) for t in targets]]  # (nt, K, 4, 4): each target's tool
    local = np.array(list(robot.targets.values()))[targets]  # (nt, 3) tool frame
    p = np.einsum("tkij,tj->kti", T[..., :3, :3], local) + T[..., :3, 3].transpose(1, 0, 2)
    ok = np.ones(len(cands), bool)
    if min_z is not None:
        ok &= (p[..., 2] >= min_z).all(axis=1)
    if tracker is not None:
        sight = np.asarray(tracker, float) - p
        cos = np.einsum("kti,tki->kt", sight, T[..., :3, 2]) / np.maximum(np.linalg.norm(sight, axis=2), 1e-12)
        ok &= (cos >= np.cos(np.radians(max_incidence_deg))).all(axis=1)
    return ok


def _logdet_blocks(D: np.ndarray, E=None, t=None) -> np.ndarray:
    """log det(I + D_i) for a stack D (T, r, r) of symmetric blocks; -inf where I + D_i is not
    positive definite (a removal that would leave M singular). (E, t: see Criterion.)"""
    sign, value = np.linalg.slogdet(D + np.eye(D.shape[-1]))
    return np.where(sign > 0, value, -np.inf)


def _log_trace_blocks(D: np.ndarray, E: np.ndarray, t: float) -> np.ndarray:
    """-log(1 - tr((I + D_i)^-1 E_i) / t) for stacks D, E (T, r, r): how much adding block i lowers
    log tr(M^-1), t = tr(M^-1) (Woodbury: the trace falls by tr((I + D_i)^-1 E_i)); -inf where
    I + D_i is not positive definite."""
    A = D + np.eye(D.shape[-1])
    sign, _ = np.linalg.slogdet(A)
    ok = sign > 0
    drop = np.zeros(len(D))
    drop[ok] = np.einsum("tii->t", np.linalg.solve(A[ok], E[ok]))
    # single-precision blocks can put a pose that spans nearly every direction a hair above the
    # whole trace; its gain is then the largest, not NaN
    left = np.maximum(1.0 - drop / t, 1e-300)
    return np.where(ok, -np.log(left), -np.inf)


def logdet(M: np.ndarray) -> float:
    """log det of a symmetric matrix; -inf when it is not positive definite."""
    try:
        return 2.0 * float(np.log(np.diag(np.linalg.cholesky(M))).sum())
    except np.linalg.LinAlgError:
        return -np.inf


def inverse(M: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive definite matrix, symmetric to the last bit."""
    L_inv = np.linalg.inv(np.linalg.cholesky(M))
    return L_inv.T @ L_inv


def trace_inverse(M: np.ndarray) -> float:
    """tr(M^-1) of a symmetric matrix; inf when it is not positive definite."""
    try:
        return float(np.trace(inverse(M)))
    except np.linalg.LinAlgError:
        return np.inf


@dataclass(frozen=True)
class Criterion:
    """What the search maximises, on a log scale so that one set of tolerances serves every criterion:
    `objective(M)` of the whitened information M (k, k); `gain(D, E, t)` (T,) what adding each block
    H_i raises it by, from D_i = H_i M^-1 H_i^T, E_i = H_i M^-2 H_i^T (None unless `uses_E`) and
    t = tr(M^-1); removing a chosen block H_j raises it by gain(-D_j, -E_j, t)."""

    name: str
    objective: Callable[[np.ndarray], float]
    gain: Callable[..., np.ndarray]
    uses_E: bool


#: D-optimality: log det M, the (log) volume of the coefficients' confidence ellipsoid, flipped
D_OPTIMAL = Criterion("D", logdet, _logdet_blocks, False)
#: I-optimality: -log tr(M^-1). In whitened coordinates tr(M^-1) = tr(M_raw^-1 W), W the candidates'
#: mean information per pose: the mean over the candidates of the predicted variance of the measured
#: coordinates per unit noise variance, which the validation RMS over such poses measures
I_OPTIMAL = Criterion("I", lambda M: -np.log(trace_inverse(M)), _log_trace_blocks, True)
CRITERIA = {c.name: c for c in (D_OPTIMAL, I_OPTIMAL)}


def observability(M: np.ndarray, m: int) -> dict:
    """Observability indices of a design whose scaled information is M = A^T A, A with m rows (Sun and
    Hollerbach 2008, singular values s of A): O1 = (prod s)^(1/k) / sqrt(m), O2 = s_max / s_min (the
    condition number; their O2 is its inverse), O3 = s_min. None when A is rank deficient."""
    s = np.sqrt(np.clip(np.linalg.eigvalsh(M), 0.0, None))
    if s[0] <= 1e-12 * s[-1]:
        return {"O1": None, "O2": None, "O3": 0.0}
    return {"O1": float(np.exp(np.mean(np.log(s))) / np.sqrt(m)), "O2": float(s[-1] / s[0]), "O3": float(s[0])}


class _Search:
    """Greedy and exchange on a pool of candidates whose whitened blocks H (P, r, k) are in memory.
    M (k, k) = M0 (given poses and the ridge) + sum over the chosen of H_i^T H_i. Its inverse is
    updated by Woodbury (rank 3 nt) after each change and refactored every REFACTOR updates and
    at every pass: a k x k factorisation per change would cost more than the passes over the pool.
    (numpy's linear algebra only: scipy brings a second BLAS whose threads contend with numpy's
    on a shared machine, 60 ms per 156 x 156 Cholesky factorisation measured.)"""

    REFACTOR = 32

    def __init__(self, H: np.ndarray, M0: np.ndarray, rng: np.random.Generator, criterion: Criterion = D_OPTIMAL):
        # single precision: the passes over the pool are memory-bound, and a gain's relative
        # rounding (1e-6) is far below the differences that decide; M accumulates the rounded
        # blocks in double, so every checked swap is exact for the problem held
        self.H, self.rng, self.criterion = H.astype(np.float32), rng, criterion
        self.P, self.r, self.k = H.shape
        self.M = M0.copy()
        self.chosen: list[int] = []
        self._refactor()

    def start(self, chosen):
        """Begin from the given pool indices (a design carried over from another pool)."""
        self.chosen = list(chosen)
        Hc = self.H[self.chosen].astype(float)
        self.M = self.M + np.einsum("pik,pil->kl", Hc, Hc)
        self._refactor()

    def row(self, i: int) -> np.ndarray:
        return self.H[i].astype(float)

    def _cross(self, flat: np.ndarray, W: np.ndarray) -> np.ndarray:
        """H_t W for the stacked pool rows flat (T r, k), (T, r, r) in double."""
        return (flat @ W.astype(flat.dtype)).astype(float).reshape(-1, self.r, self.r)

    def _refactor(self):
        self.Minv = inverse(self.M)
        self.updates = 0

    def _update(self, Hi: np.ndarray, sign: float):
        """M += sign H_i^T H_i, and its inverse."""
        self.M += sign * (Hi.T @ Hi)
        self.updates += 1
        if self.updates >= self.REFACTOR:
            self._refactor()
            return
        W = self.Minv @ Hi.T
        self.Minv -= sign * W @ np.linalg.solve(np.eye(self.r) + sign * (Hi @ W), W.T)

    def _gain(self, D, E, Minv) -> np.ndarray:
        return self.criterion.gain(D, E, float(np.trace(Minv)))

    def _blocks(self, H: np.ndarray, Minv: np.ndarray):
        """(D, E) of the blocks H (T, r, k) against the inverse Minv: H_i Minv H_i^T and, when the
        criterion uses it, H_i Minv^2 H_i^T (else None); in chunks that bound the temporaries."""
        D = np.empty((len(H), self.r, self.r))
        E = np.empty_like(D) if self.criterion.uses_E else None
        step = max(1, int(5e6 // (self.r * self.k)))
        for s in range(0, len(H), step):
            D[s:s + step], e = _quadratic(H[s:s + step], Minv, Minv if E is not None else None)
            if E is not None:
                E[s:s + step] = e
        return D, E

    def _after(self, D, E, flat, Minv, Ha, sign):
        """(D, E, C) of the blocks flat (T r, k) against M + sign H_a^T H_a from (D, E) against M
        (inverse Minv), C_i = H_i M^-1 H_a^T. Woodbury: the new inverse is Minv - sign W G W^T with
        W = Minv H_a^T, G = (I + sign H_a W)^-1, so D_i falls by sign C_i G C_i^T and E_i changes by
        -sign (P_i + P_i^T) + (C_i G) W^T W (C_i G)^T, P_i = C_i G F_i^T, F_i = H_i Minv W."""
        W = Minv @ Ha.T
        G = np.linalg.inv(np.eye(self.r) + sign * (Ha @ W))
        C = self._cross(flat, W)
        D = D - sign * _sandwich(C, G)
        if E is not None:
            CG = np.matmul(C, G)
            P = np.matmul(CG, self._cross(flat, Minv @ W).transpose(0, 2, 1))
            E = E - sign * (P + P.transpose(0, 2, 1)) + _sandwich(CG, W.T @ W)
        return D, E, C

    def greedy(self, n: int):
        """Add n poses one by one, each of largest gain. Every candidate's D_i (and E_i) is updated
        after each addition by Woodbury (r^2 k per candidate, not r k^2 afresh), and recomputed
        whenever the inverse is refactored or tr(M^-1) has fallen tenfold since: an update's
        rounding is relative to the blocks before it, and while the chosen poses span the
        coefficients the ridge's directions make those blocks 1/RIDGE times larger than after."""
        flat = self.H.reshape(-1, self.k)
        D, E = self._blocks(self.H, self.Minv)
        fresh = np.trace(self.Minv)
        for _ in range(n):
            g = self._gain(D, E, self.Minv)
            g[self.chosen] = -np.inf
            i = int(np.argmax(g))
            Hi = self.row(i)
            D, E, _ = self._after(D, E, flat, self.Minv, Hi, 1.0)
            self.chosen.append(i)
            self._update(Hi, 1.0)
            if self.updates == 0 or np.trace(self.Minv) < fresh / 10:
                D, E = self._blocks(self.H, self.Minv)
                fresh = np.trace(self.Minv)

    def _trial_set(self, size: int) -> np.ndarray:
        """Candidates an exchange pass evaluates: every unchosen one when they fit the budget, else
        the half of largest gain and a random sample of the rest."""
        free = np.setdiff1d(np.arange(self.P), self.chosen)
        if len(free) <= size:
            return free
        g = self._gain(*self._blocks(self.H[free], self.Minv), self.Minv)  # the gain of adding each
        top = free[np.argsort(-g)[:size // 2]]
        rest = np.setdiff1d(free, top)
        return np.concatenate([top, self.rng.choice(rest, size - len(top), replace=False)])

    def exchange(self, max_passes: int = MAX_PASSES) -> tuple[int, int, list[float]]:
        """Fedorov exchanges; returns (swaps, passes, the objective after the greedy start and each pass).

        For chosen pose j, with W = M^-1 H_j^T and S = I - H_j W, every trial candidate's
        H_i M_-j^-1 H_i^T is D_i + C_i S^-1 C_i^T (C_i = H_i W, Woodbury; E_i likewise), so the
        objective after swapping j for i is the current one plus the gain of removing j plus that
        of adding i against M_-j: one pass over the trial set per chosen pose. The best swap is
        checked once more from the inverse before it is made."""
        size = max(1, int(EXCHANGE_BUDGET // ((1 + self.criterion.uses_E) * self.r ** 2 * (self.k + self.r))))
        history, swaps, passes = [self.criterion.objective(self.M)], 0, 0
        if len(self.chosen) >= self.P:  # every candidate is in the design: none to exchange for
            return swaps, passes, history
        for passes in range(1, max_passes + 1):
            self._refactor()
            trial = self._trial_set(size)
            Ht = self.H[trial]  # contiguous: one read per chosen pose
            flat = Ht.reshape(-1, self.k)
            D, E = self._blocks(Ht, self.Minv)
            made = 0
            for slot in range(len(self.chosen)):
                j = self.chosen[slot]
                Hj = self.row(j)
                Dj, Ej = self._blocks(Hj[None], self.Minv)
                loss = self._gain(-Dj, None if Ej is None else -Ej, self.Minv)[0]
                if not np.isfinite(loss):
                    continue  # the other poses leave a direction only j spans: j stays
                W = self.Minv @ Hj.T
                minus = self.Minv + W @ np.linalg.solve(np.eye(self.r) - Hj @ W, W.T)  # (M - H_j^T H_j)^-1
                D_minus, E_minus, _ = self._after(D, E, flat, self.Minv, Hj, -1.0)
                net = self._gain(D_minus, E_minus, minus) + loss
                b = int(np.argmax(net))
                i = int(trial[b])
                Hi = self.row(i)
                # checked in double from the inverse alone: the pool's blocks are single precision
                if net[b] <= SWAP_TOL or loss + self._gain(*self._blocks(Hi[None], minus), minus)[0] <= SWAP_TOL:
                    continue
                D, E, _ = self._after(D_minus, E_minus, flat, minus, Hi, 1.0)
                self.chosen[slot] = i
                self._update(Hj, -1.0)
                self._update(Hi, 1.0)
                trial[b], Ht[b] = j, Hj  # j becomes a trial candidate in i's place
                Db, Eb = self._blocks(Hj[None], self.Minv)
                D[b] = Db[0]
                if E is not None:
                    E[b] = Eb[0]
                made += 1
            swaps += made
            history.append(self.criterion.objective(self.M))
            if history[-1] - history[-2] < PASS_TOL:
                break
        return swaps, passes, history


def _quadratic(H: np.ndarray, A: np.ndarray, B: np.ndarray | None = None):
    """(D, E) for a stack H (T, r, k): D_i = H_i A H_i^T and, with B, E_i = (H_i B)(H_i B)^T (else
    None), (T, r, r) in double (computed in H's precision); B = A reuses the product."""
    shape = (-1, H.shape[-1])
    HA = (H.reshape(shape) @ A.astype(H.dtype)).reshape(H.shape)
    # optimize: BLAS, 10x numpy's own loop
    D = np.einsum("tik,tjk->tij", HA, H, optimize=True).astype(float)
    if B is None:
        return D, None
    HB = HA if B is A else (H.reshape(shape) @ B.astype(H.dtype)).reshape(H.shape)
    return D, np.einsum("tik,tjk->tij", HB, HB, optimize=True).astype(float)


def _sandwich(C: np.ndarray, A: np.ndarray) -> np.ndarray:
    """C_i A C_i^T for a stack C (T, r, r)."""
    # batched matmul, not one flat product: BLAS's overhead on an inner dimension of r is 20x
    return np.matmul(np.matmul(C, A), C.transpose(0, 2, 1))


@dataclass(frozen=True)
class PoseDesign:
    """A design: `chosen` (N,) candidate indices in the order chosen; `random` (N,) the seeded
    random comparison; `criterion` the one chosen by, "D" or "I". `values` maps "design" and
    "random" to both criteria's values (given poses included, no ridge): "D" log det of the scaled
    information (higher is better), "I" tr(M^-1) in whitened coordinates, the mean over the
    candidates of the summed variance of the measured coordinates' prediction per unit noise
    variance (lower is better); `value`, `random_value` those of `criterion`. `history` the
    criterion's value (with the ridge) after the greedy start and each exchange pass.
    `columns` the coefficient indices of the criterion, `scale` (k,) their RMS over the
    candidates (the column scaling of the reported values); `observability` and
    `predicted_std_mm` map "design" and "random" to {O1, O2, O3} and to {rms_mm, max_mm} of the
    predicted target position std over the validation poses at noise_mm per coordinate."""

    chosen: np.ndarray
    random: np.ndarray
    criterion: str
    values: dict
    observability: dict
    predicted_std_mm: dict
    noise_mm: float
    n_validation: int
    columns: np.ndarray
    scale: np.ndarray
    redundancy: Redundancy
    targets: np.ndarray
    n_candidates: int
    swaps: int
    passes: int
    rounds: int
    history: list = field(default_factory=list)

    @property
    def value(self) -> float:
        return self.values["design"][self.criterion]

    @property
    def random_value(self) -> float:
        return self.values["random"][self.criterion]

    def to_dict(self) -> dict:
        names = self.redundancy.names
        unexcitable = [e.param for e in self.redundancy.eliminated if e.reason == "unexcited"]
        # flat, "random_" before the comparison's figures, as value and random_value
        obs = {**self.observability["design"], **{f"random_{k}": v for k, v in self.observability["random"].items()}}
        std = {**self.predicted_std_mm["design"],
               **{f"random_{k}": v for k, v in self.predicted_std_mm["random"].items()}}
        both = {f"{prefix}{key}": _finite(self.values[name][c]) for name, prefix in (("design", ""), ("random", "random_"))
                for c, key in (("D", "log_det"), ("I", "mean_variance"))}
        return {"n_poses": len(self.chosen), "criterion": self.criterion, "value": _finite(self.value),
                "random_value": _finite(self.random_value), **both, "observability": obs,
                "predicted_std": {"noise_mm": self.noise_mm, "n_validation_poses": self.n_validation, **std},
                "n_candidates": self.n_candidates, "n_identifiable": len(self.columns),
                "identifiable": [names[j] for j in self.columns], "unexcitable": unexcitable,
                "swaps": self.swaps, "passes": self.passes, "rounds": self.rounds,
                "history": [_finite(v) for v in self.history]}


def pose_rank(robot: Robot, targets: np.ndarray) -> int:
    """Most coefficients one pose can inform: the targets sit on the tool, so every error moves
    them as one rigid body (3 for one point, 5 for two, 6 for three not in a line)."""
    points = np.array(list(robot.targets.values()))[targets]
    rigid = [np.hstack([np.eye(3), -np.cross(np.eye(3), p)]) for p in points]  # d p = d x + d theta x p
    return int(np.linalg.matrix_rank(np.vstack(rigid), tol=1e-9))


def _measured_rows(targets: np.ndarray) -> np.ndarray:
    return (3 * np.asarray(targets)[:, None] + np.arange(3)).ravel()


@dataclass(frozen=True)
class _Basis:
    """The criterion's coordinates: H_e rows `rows` (measured targets), coefficient `columns`, and
    T (k, k) upper triangular with T^T T the candidates' mean information per pose over those
    columns. Blocks are whitened, H T^-1: the mean candidate then informs every direction alike, so
    the ridge and the rounding mean the same in every direction however unequal the columns' units
    and however nearly dependent they are (the D-optimal choice is unchanged: log det shifts by a
    constant). `scale` (k,) the columns' RMS over the candidates, for the reported values."""

    rows: np.ndarray
    columns: np.ndarray
    T: np.ndarray
    scale: np.ndarray
    T_inv: np.ndarray

    def whiten(self, A: np.ndarray) -> np.ndarray:
        """A (..., k) over the columns -> A T^-1."""
        return (A.reshape(-1, A.shape[-1]) @ self.T_inv).reshape(A.shape)

    def scaled_information(self, M_w: np.ndarray) -> np.ndarray:
        """The column-scaled information S^-1 T^T M_w T S^-1 of a whitened M_w."""
        A = self.T / self.scale
        return A.T @ M_w @ A

    def scaled_logdet(self, M_w: np.ndarray) -> float:
        """log det of the column-scaled information from that of the whitened one (exact, no refactor)."""
        return logdet(M_w) + 2.0 * float(np.sum(np.log(np.abs(np.diag(self.T))) - np.log(self.scale)))


def measured_blocks(cm: CompiledModel, cands: Candidates, idx: np.ndarray, rows: np.ndarray, columns: np.ndarray):
    """Yield (start, H (b, r, k)): the H_e rows of the measured targets over the chosen columns
    (at the nominal model) for the candidates idx, in blocks of BLOCK poses."""
    c = np.zeros(cm.dims.nc)
    for s in range(0, len(idx), BLOCK):
        sel = idx[s:s + BLOCK]
        _, H = cm.model_targets(cands.q[sel], cands.w[sel], cands.aux[sel], c, with_H=True)
        yield s, H[:, rows][:, :, columns]


def _whitened(cm, cands, idx, basis: _Basis) -> np.ndarray:
    out = np.empty((len(idx), len(basis.rows), len(basis.columns)))
    for s, H in measured_blocks(cm, cands, idx, basis.rows, basis.columns):
        out[s:s + len(H)] = basis.whiten(H)
    return out


def _basis(cm: CompiledModel, cands: Candidates, rows: np.ndarray, struct: Redundancy, n_struct_targets: int,
           rng: np.random.Generator) -> tuple[_Basis, Redundancy]:
    """The coefficients the candidates excite (the structurally kept ones less those the rank test
    on the candidates' H_e finds dependent) and the whitening; over at most BASIS_SAMPLE candidates
    (a seeded random sample of more), whose R factor is streamed through a QR."""
    K = len(cands)
    sample = np.sort(rng.choice(K, BASIS_SAMPLE, replace=False)) if K > BASIS_SAMPLE else np.arange(K)
    kept = np.array(struct.kept, int)
    R = qr_accumulate((H.reshape(-1, len(kept)), np.zeros(H.shape[0] * H.shape[1]))
                      for _, H in measured_blocks(cm, cands, sample, rows, kept))[0][:-1, :-1]
    red = unexcited(struct, R, cm.robot, cm.model, n_struct_targets)
    local = np.searchsorted(kept, red.kept)
    T = np.linalg.qr(R[:, local], mode="r") / np.sqrt(len(sample))
    T *= np.sign(np.diag(T))[:, None]  # a positive diagonal: T is then the Cholesky factor
    return _Basis(rows, kept[local], T, np.linalg.norm(T, axis=0), np.linalg.inv(T)), red


def given_information(cm: CompiledModel, given: Measurements, basis: _Basis) -> tuple[np.ndarray, int]:
    """Whitened information (k, k) of the measured points of `given`, and their number of rows."""
    k = len(basis.columns)
    M, m = np.zeros((k, k)), 0
    for H, r in rows_H_and_residual(cm, given, given.xyz, np.zeros(cm.dims.nc)):
        A = basis.whiten(H[:, basis.columns])
        M += A.T @ A
        m += len(r)
    return M, m


def predicted_std(M: np.ndarray, H: np.ndarray, noise_m: float, nt: int) -> np.ndarray:
    """Std (m) of each measured target's predicted position, (V, nt), at validation blocks H (V, r, k)
    for coefficients estimated with covariance noise^2 M^-1 (M in H's coordinates): the square root
    of the trace of that covariance propagated to the target's r / nt coordinates (a point's 3; an
    image point's 2, in px for a noise in px)."""
    try:
        L = np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        return np.full((len(H), nt), np.inf)
    Z = np.linalg.solve(L, H.reshape(-1, H.shape[-1]).T)  # (k, V r)
    var = (Z ** 2).sum(axis=0).reshape(len(H), nt, -1).sum(axis=2)
    return noise_m * np.sqrt(var)


@one_blas_thread
def design_poses(cm: CompiledModel, cands: Candidates, n_poses: int, targets: np.ndarray,
                 given: Measurements | None = None, seed: int = 0, noise_m: float = NOISE_M,
                 n_validation: int = N_VALIDATION, max_passes: int = MAX_PASSES,
                 criterion: str = DEFAULT_CRITERION) -> PoseDesign:
    """Choose n_poses of the candidates measuring `targets` (indices into robot.targets), added to
    `given` measurements if any, by `criterion`: "D" maximises log det of the information, "I"
    minimises the mean over the candidates of the predicted variance of the measured positions
    (tr(M^-1 W), W the candidates' mean information per pose). The random comparison and the
    validation poses are drawn (seeded) from the same candidates."""
    require(criterion in CRITERIA, f"--criterion {criterion}: expected one of {', '.join(CRITERIA)}")
    crit = CRITERIA[criterion]
    K = len(cands)
    require(n_poses >= 1, f"--poses {n_poses}: give at least 1 pose to design")
    require(n_poses <= K, f"--poses {n_poses}: only {K} candidates to choose from; raise --candidates, "
                          f"relax the constraints or lower --poses")
    # three streams, so the comparison and the validation poses do not depend on the search's draws
    rng, rng_random, rng_val = (np.random.default_rng([seed, s]) for s in range(3))
    rows = _measured_rows(targets)
    r = len(rows)
    struct_targets = np.unique(np.concatenate([targets, given.target])) if given is not None else np.asarray(targets)
    basis, red = _basis(cm, cands, rows, structural_analysis(cm, struct_targets), len(struct_targets), rng)
    k = len(basis.columns)
    M0, m0 = given_information(cm, given, basis) if given is not None else (np.zeros((k, k)), 0)
    m = m0 + r * n_poses
    per_pose = pose_rank(cm.robot, targets)
    known = np.linalg.matrix_rank(M0) if given is not None else 0
    wanted = f"{k - known} directions of the {k} identifiable coefficients the given data leaves open" if known \
        else f"{k} identifiable coefficients"
    require(known + per_pose * n_poses >= k,
            f"--poses {n_poses}: {n_poses} poses inform at most {per_pose * n_poses} of the {wanted} ({per_pose} "
            f"each: the targets move with the tool as one rigid body); give at least "
            f"{int(np.ceil((k - known) / per_pose))} poses")
    M_start = M0 + RIDGE * np.eye(k)

    pool_cap = int(min(MAX_POOL, max(n_poses + 1, POOL_BYTES // (4 * r * k))))
    rounds = 0
    if K <= pool_cap:
        pool = np.arange(K)
    else:  # rank by the gain against what N average candidates would give (I each, whitened)
        pool = _top_gains(cm, cands, basis, M_start + n_poses * np.eye(k), pool_cap, [], crit)
    picked, swaps, passes, history, M = choose(_whitened(cm, cands, pool, basis), M_start, n_poses, rng, crit,
                                              max_passes)
    chosen = pool[picked]
    while K > pool_cap and rounds < MAX_ROUNDS:
        rounds += 1
        new_pool = _top_gains(cm, cands, basis, M, pool_cap - n_poses, chosen, crit)
        if np.isin(new_pool, pool).all():
            break  # no candidate outside the pool ranks among the best: nothing new to try
        pool = np.concatenate([chosen, new_pool])
        search = _Search(_whitened(cm, cands, pool, basis), M_start, rng, crit)
        search.start(range(n_poses))
        more, p, h = search.exchange(max_passes)
        swaps, passes, history = swaps + more, passes + p, history + h[1:]
        chosen, M = pool[search.chosen], search.M
        if not more:
            break

    random_pick = rng_random.choice(K, n_poses, replace=False)
    val = rng_val.choice(K, min(n_validation, K), replace=False)
    H_val = _whitened(cm, cands, val, basis)
    out = {}
    for name, idx in (("design", chosen), ("random", random_pick)):
        Hc = _whitened(cm, cands, idx, basis)
        M = M0 + np.einsum("pik,pil->kl", Hc, Hc)
        std = predicted_std(M, H_val, noise_m, len(targets))
        out[name] = (*scores(basis, M, m), {"rms_mm": _finite(1e3 * np.sqrt(np.mean(std ** 2))),
                                            "max_mm": _finite(1e3 * std.max())})
    history = reported_history(basis, history, crit)
    return PoseDesign(chosen=chosen, random=random_pick, criterion=criterion, values={n: o[0] for n, o in out.items()},
                      observability={n: o[1] for n, o in out.items()},
                      predicted_std_mm={n: o[2] for n, o in out.items()}, noise_mm=1e3 * noise_m,
                      n_validation=len(val), columns=basis.columns, scale=basis.scale, redundancy=red,
                      targets=np.asarray(targets), n_candidates=K, swaps=swaps, passes=passes, rounds=rounds,
                      history=history)


def choose(H: np.ndarray, M0: np.ndarray, n_poses: int, rng: np.random.Generator, criterion: Criterion = D_OPTIMAL,
           max_passes: int = MAX_PASSES) -> tuple[np.ndarray, int, int, list, np.ndarray]:
    """n_poses of the whitened blocks H (P, r, k) by `criterion`: the greedy start and the exchange
    passes from the information M0 (k, k) (what is given, and the ridge). Returns the chosen indices
    (n_poses,) in the order chosen, the swaps and passes made, the objective after the start and
    each pass, and the information (k, k) reached, M0 included."""
    search = _Search(H, M0, rng, criterion)
    search.greedy(n_poses)
    swaps, passes, history = search.exchange(max_passes)
    return np.array(search.chosen, int), swaps, passes, history, search.M


def scores(basis: _Basis, M: np.ndarray, m: int) -> tuple[dict, dict]:
    """What a design's whitened information M (k, k, no ridge) of m rows is worth: both criteria's
    values ({"D": log det of the column-scaled information, "I": tr(M^-1)}) and its `observability`."""
    return {"D": basis.scaled_logdet(M), "I": trace_inverse(M)}, observability(basis.scaled_information(M), m)


def reported_history(basis: _Basis, history: list, criterion: Criterion) -> list:
    """The search's objective after each pass as the criterion's value is reported: D's log det of the
    column-scaled information, I's tr(M^-1)."""
    shift = basis.scaled_logdet(np.eye(len(basis.columns)))  # whitened -> column-scaled log det
    return [v + shift for v in history] if criterion is D_OPTIMAL else [float(np.exp(-v)) for v in history]


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _top_gains(cm, cands, basis: _Basis, M: np.ndarray, n: int, exclude, criterion: Criterion) -> np.ndarray:
    """The n candidates (not in `exclude`) of largest gain against the whitened M, streamed over all
    candidates."""
    Minv = inverse(M)
    # in the raw columns, no whitening pass: H_w M^-1 H_w^T = H A H^T, H_w M^-1 = H B
    B = basis.T_inv @ Minv
    A = B @ basis.T_inv.T
    gains = np.empty(len(cands))
    for s, H in measured_blocks(cm, cands, np.arange(len(cands)), basis.rows, basis.columns):
        gains[s:s + len(H)] = criterion.gain(*_quadratic(H, A, B if criterion.uses_E else None), float(np.trace(Minv)))
    gains[np.asarray(exclude, int)] = -np.inf
    return np.sort(np.argsort(-gains)[:n])
