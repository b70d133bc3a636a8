"""Designs for calibration without a tracker: which configurations to record in each socket and on
each plane (`gecgen design --fixtures`).

A socket's or plane's position is a nuisance the fit eliminates (`fit.relative`), so what a set
of configurations tells about the coefficients is what is left once each fixture's own unknowns have
taken their share. For fixture g with rows A_g (r per configuration over the k coefficients: a
socket's three coordinates of H_e, a plane's normal component n^T H_e) and nuisance regressors B_g
(a socket's three coordinates, B = I per configuration; a plane's offset and two tilts, B = [1, u, v]
for a touch at tangential offset (u, v) from the plane's point), the information is

    M_g = A_g^T A_g - A_g^T B_g (B_g^T B_g)^-1 B_g^T A_g,

the rows' scatter about what the nuisance explains (for a socket, sum (H_i - mean H)^T (H_i - mean H)).
Adding configuration i raises it by a~^T S^-1 a~ (recursive least squares): a~ = a_i - b_i P_g the part
of its rows the fixture's current nuisance fit does not predict (P_g = (B^T B)^-1 B^T A), S = I + b_i
(B^T B)^-1 b_i^T; so log det M rises by log det(S + a~ M^-1 a~^T) - log det S.

* candidates: per fixture, configurations from inverse kinematics of the nominal robot from random
  starts within the joint limits (`simulate.fixtures.reach`), so each socket is offered in many
  postures and each plane at many points of a square patch around its given point;
* criterion: D-optimal (log det M), in the directions the information of all candidates together
  informs at all - what no configuration can show (the base placement, the scale without a known
  distance; `relative` in the fit's redundancy analysis) is left out and counted, `unseen` - and
  whitened there, so that the mean candidate informs each direction alike and RIDGE means the same
  in all of them;
* search: Fedorov exchange from a seeded random start (the poses spread evenly over the fixtures:
  the comparison reported beside the design): each chosen configuration is taken out in turn and the
  candidate of largest gain, of any fixture, put in when that raises log det M by more than SWAP_TOL
  (a fixture keeps at least the configurations that make it say anything: 2 in a socket, 4 on a
  plane). So the design chooses how many configurations each listed fixture gets beyond that minimum;
  whether a fixture is worth placing at all is what `by_count` answers (the same poses designed over
  the first k fixtures only). Passes stop when one gains less than PASS_TOL, or after MAX_PASSES.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.fixture_file import Fixture
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import Measurements
from gecgen.model.robot import Robot
from gecgen.model.validation import ModelError, require
from gecgen.runtime.compiled import CompiledModel
from gecgen.plan.design import MAX_PASSES, PASS_TOL, RIDGE, SWAP_TOL, logdet
from gecgen.fit.identify import structural_analysis
from gecgen.simulate.fixtures import reach

#: configurations tried per fixture (inverse kinematics from random starts)
CANDIDATES = 200
#: half-width (m) of the square patch of a plane whose points the touches are planned at
PATCH_M = 0.1
#: seating noise (m per coordinate of a seat, along the normal for a touch) the predicted figures assume
NOISE_M = 1e-5
#: fewest configurations that make a fixture say anything: a socket's two, a plane's four
MINIMUM = {False: 2, True: 4}
#: candidates keep this share of each joint's range from its limits: a hand-guided arm is not held at a stop
LIMIT_MARGIN = 0.02
#: directions of the candidates' information below this share of the largest are what no
#: configuration shows (rigid motions of the whole set: they vanish to rounding)
UNSEEN_TOL = 1e-9


@dataclass(frozen=True)
class FixtureCandidates:
    """Per fixture: configurations q (K_g, n) that put the target at goal (K_g, 3) m on the nominal robot."""

    fixtures: tuple[Fixture, ...]
    q: tuple[np.ndarray, ...]
    goal: tuple[np.ndarray, ...]


def fixture_candidates(robot: Robot, fixtures: tuple[Fixture, ...], target: int, n: int,
                       rng: np.random.Generator, patch_m: float = PATCH_M) -> FixtureCandidates:
    """Up to n configurations per fixture (socket: the target at its centre; plane: at points uniform
    over a square patch of half-width patch_m, m, around its point), each joint LIMIT_MARGIN of its
    range inside its limits; a fixture too few starts reach is refused, naming it."""
    lo, hi = (np.array(v) for v in robot.sampling_box())
    lo, hi = lo + LIMIT_MARGIN * (hi - lo), hi - LIMIT_MARGIN * (hi - lo)

    def position(q: np.ndarray, rows: np.ndarray = slice(None)) -> np.ndarray:
        return target_positions(robot, q[rows])[:, target]

    qs, goals = [], []
    for f in fixtures:
        goal = np.tile(f.point, (n, 1))
        if f.is_plane:
            goal = goal + rng.uniform(-patch_m, patch_m, (n, 2)) @ f.tangents
        q, ok = reach(robot, position, position, goal, rng)  # the nominal robot is the truth here
        ok &= ((q >= lo) & (q <= hi)).all(axis=1)
        require(ok.sum() >= MINIMUM[f.is_plane],
                f"fixture {f.name}: the {robot.target_names[target]} reaches it in {int(ok.sum())} of {n} tries; "
                f"check its position (m, in the robot's world frame) and the robot's reach")
        qs.append(q[ok])
        goals.append(goal[ok])
    return FixtureCandidates(tuple(fixtures), tuple(qs), tuple(goals))


def recorded_candidates(robot: Robot, data: Measurements, target: int) -> tuple[FixtureCandidates, tuple]:
    """Configurations already recorded per socket or plane (the relative rows of `data` measuring
    `target`) as candidates, each fixture where the nominal model puts its rows (a socket at their
    mean, a plane through their mean, normal to their least spread); and per fixture the poses of
    `data` its candidates are (for `data.subset`)."""
    rel = data.relative
    require(rel is not None, f"{data.source}: no socket or plane rows to choose from")
    p = target_positions(robot, data.q)[data.pose, data.target]
    fixtures, qs, goals, poses = [], [], [], []
    for g, name in enumerate(rel.names):
        on = np.nonzero((rel.group == g) & (data.target == target))[0]
        need = MINIMUM[bool(rel.is_plane()[g])]
        require(len(on) >= need, f"{data.source}: {name} has {len(on)} rows of {robot.target_names[target]}; a design "
                                 f"needs at least {need} to choose from")
        centre = p[on].mean(axis=0)
        normal = np.linalg.svd(p[on] - centre)[2][2] if rel.is_plane()[g] else None
        fixtures.append(Fixture(name, centre, normal))
        qs.append(data.q[data.pose[on]])
        goals.append(p[on])
        poses.append(data.pose[on])
    return FixtureCandidates(tuple(fixtures), tuple(qs), tuple(goals)), tuple(poses)


def _rows(cm: CompiledModel, cands: FixtureCandidates, target: int, columns: np.ndarray):
    """Per fixture: its candidates' rows a (K_g, r, k) over `columns` and nuisance regressors b (K_g, r, 3)."""
    out = []
    for f, q, goal in zip(cands.fixtures, cands.q, cands.goal):
        K = len(q)
        _, H = cm.model_targets(q, np.zeros((K, 6)), np.zeros((K, 0)), np.zeros(cm.dims.nc), with_H=True)
        H = H[:, 3 * target:3 * target + 3][:, :, columns]
        if f.is_plane:
            a = np.einsum("i,nik->nk", f.normal, H)[:, None, :]
            b = np.column_stack([np.ones(K), (goal - f.point) @ f.tangents.T])[:, None, :]
        else:
            a, b = H, np.tile(np.eye(3), (K, 1, 1))
        out.append((a, b))
    return out


def _nuisance(a: np.ndarray, b: np.ndarray, chosen: list[int]):
    """For a fixture's chosen rows: (B^T B)^-1 (3, 3), P = (B^T B)^-1 B^T A (3, k), and the information
    M_g (k, k) they leave once the nuisance is fitted."""
    k = a.shape[-1]
    if not chosen:
        return np.zeros((3, 3)), np.zeros((3, k)), np.zeros((k, k))
    A, B = a[chosen].reshape(-1, k), b[chosen].reshape(-1, 3)
    G = np.linalg.pinv(B.T @ B)
    P = G @ (B.T @ A)
    return G, P, A.T @ A - (B.T @ A).T @ P


def _gains(a: np.ndarray, b: np.ndarray, G: np.ndarray, P: np.ndarray, Minv: np.ndarray) -> np.ndarray:
    """log det M's rise (K_g,) from adding each candidate of a fixture whose nuisance fit is (G, P)."""
    resid = a - b @ P
    S = np.eye(a.shape[1]) + b @ G @ b.transpose(0, 2, 1)
    return np.linalg.slogdet(S + resid @ Minv @ resid.transpose(0, 2, 1))[1] - np.linalg.slogdet(S)[1]


class _Exchange:
    """Fedorov exchange over the fixtures' whitened rows (module docstring)."""

    def __init__(self, rows, chosen: list[list[int]], minimum: list[int]):
        self.rows, self.chosen, self.minimum = rows, [list(c) for c in chosen], minimum
        self.k = rows[0][0].shape[-1]
        self.state = [_nuisance(a, b, c) for (a, b), c in zip(rows, self.chosen)]
        self.value = self._objective()

    def information(self) -> np.ndarray:
        return sum(s[2] for s in self.state)

    def _objective(self) -> float:
        return logdet(self.information() + RIDGE * np.eye(self.k))

    def passes(self, max_passes: int) -> tuple[int, int]:
        """(swaps, passes) until a pass gains less than PASS_TOL."""
        swaps = passes = 0
        while passes < max_passes:
            passes += 1
            start = self.value
            for g in range(len(self.rows)):
                for j in list(self.chosen[g]):
                    swaps += self._try(g, j)
            if self.value - start < PASS_TOL:
                break
        return swaps, passes

    def _try(self, g: int, j: int) -> bool:
        a, b = self.rows[g]
        without = [i for i in self.chosen[g] if i != j]
        state_g = _nuisance(a, b, without)
        M = self.information() - self.state[g][2] + state_g[2] + RIDGE * np.eye(self.k)
        Minv, base = np.linalg.inv(M), logdet(M)
        best = (-np.inf, None, None)
        for h, (ah, bh) in enumerate(self.rows):
            if h != g and len(self.chosen[g]) <= self.minimum[g]:
                continue  # g keeps the configurations that make it say anything
            G, P, _ = state_g if h == g else self.state[h]
            taken = without if h == g else self.chosen[h]
            gain = _gains(ah, bh, G, P, Minv) if len(taken) else np.zeros(len(ah))  # a lone row says nothing
            gain[taken] = -np.inf
            if h == g:
                gain[j] = -np.inf  # putting back what was taken out is no swap
            i = int(np.argmax(gain))
            if gain[i] > best[0]:
                best = (gain[i], h, i)
        gain, h, i = best
        if h is None or base + gain <= self.value + SWAP_TOL:
            return False
        self._move(g, j, h, i)
        value = self._objective()
        if value <= self.value:  # rounding made a swap that is no gain: undo it
            self._move(h, i, g, j)
            return False
        self.value = value
        return True

    def _move(self, g: int, j: int, h: int, i: int):
        """Candidate j of fixture g out, candidate i of fixture h in, their nuisance fits redone."""
        self.chosen[g] = [c for c in self.chosen[g] if c != j]
        self.chosen[h] = self.chosen[h] + [i]
        for f in {g, h}:
            self.state[f] = _nuisance(*self.rows[f], self.chosen[f])


@dataclass(frozen=True)
class FixtureDesign:
    """A design: `chosen` per fixture the candidate indices (into its configurations), `random` the
    seeded even start it was exchanged from; `log_det` {design, random} of the whitened information
    (no ridge; nats, higher is better, only the difference means something); `predicted_mm` {design,
    random}: the RMS over the candidates of the error (mm) the coefficients' uncertainty adds to a
    configuration's residual about its fixture (refitted on all candidates, as held-out rows are), at
    noise_mm per coordinate: what held-out consistency or flatness gains above the noise;
    `n_identifiable` the directions the criterion works in and `unseen` those no configuration shows;
    `by_count` ((k, log_det, predicted_mm), ...) the design of the same number of poses over the first k
    fixtures only, scored on the candidates of all of them (None: k fixtures leave a direction
    undetermined that all of them determine), the last k all."""

    chosen: tuple[np.ndarray, ...]
    random: tuple[np.ndarray, ...]
    log_det: dict
    predicted_mm: dict
    noise_mm: float
    n_identifiable: int
    unseen: int
    n_candidates: tuple[int, ...]
    swaps: int
    passes: int
    by_count: tuple = ()

    def to_dict(self, fixtures: tuple[Fixture, ...]) -> dict:
        return {"n_poses": int(sum(len(c) for c in self.chosen)), "criterion": "D",
                "log_det": self.log_det["design"], "random_log_det": self.log_det["random"],
                "predicted": {"noise_mm": self.noise_mm, "rms_mm": self.predicted_mm["design"],
                              "random_rms_mm": self.predicted_mm["random"]},
                "fixtures": [{"name": f.name, "kind": "plane" if f.is_plane else "point", "poses": len(c),
                              "candidates": K} for f, c, K in zip(fixtures, self.chosen, self.n_candidates)],
                "n_identifiable": self.n_identifiable, "unseen": self.unseen, "swaps": self.swaps,
                "passes": self.passes,
                "by_fixtures": [{"fixtures": k, "log_det": d, "predicted_rms_mm": v} for k, d, v in self.by_count]}


def _predicted_rms(chosen_information: np.ndarray, held: list[np.ndarray], noise_m: float) -> float:
    """RMS (m) over every candidate of the error the coefficients' covariance noise^2 M^-1 (M the
    chosen rows' information) adds to its residual about its fixture (a seat's 3-D distance, a
    touch's along the normal): `held` per fixture its candidates' rows projected off the nuisance of
    all of them (K_g, r, k), as a held-out set's fixture is refitted on its own rows."""
    Minv = np.linalg.pinv(chosen_information)
    var = sum(float(np.einsum("nik,kl,nil->", h, Minv, h)) for h in held)
    return noise_m * float(np.sqrt(var / sum(len(h) for h in held)))


def design_fixtures(cm: CompiledModel, cands: FixtureCandidates, n_poses: int, target: int, seed: int = 0,
                    noise_m: float = NOISE_M, max_passes: int = MAX_PASSES) -> FixtureDesign:
    """Choose n_poses configurations over the fixtures of `cands` for measuring `target` (index into
    robot.targets), D-optimal as the module docstring says; noise_m (m per coordinate of a seat, or
    along a plane's normal) scales the predicted figures."""
    fixtures = cands.fixtures
    minimum = [MINIMUM[f.is_plane] for f in fixtures]
    need = sum(minimum)
    require(n_poses >= need, f"--poses {n_poses}: {len(fixtures)} fixtures need at least {need} configurations "
                             f"(2 in a socket, 4 on a plane) before they say anything; give more poses")
    require(n_poses <= sum(len(q) for q in cands.q),
            f"--poses {n_poses}: only {sum(len(q) for q in cands.q)} candidate configurations; raise --candidates")
    columns = np.array(structural_analysis(cm, np.array([target])).kept, int)
    rows = _rows(cm, cands, target, columns)
    n_rows = sum(a.shape[0] * a.shape[1] for a, _ in rows)
    scale = np.sqrt(sum(np.einsum("nrk,nrk->k", a, a) for a, _ in rows) / n_rows)
    scale = np.where(scale > 0, scale, 1.0)
    rows = [(a / scale, b) for a, b in rows]
    # every candidate's rows projected off its fixture's nuisance fitted on all of them: their
    # information (the projection is idempotent, so A^T (A - B P) = (A - B P)^T (A - B P)) decides what
    # is seen and the whitening, and they are the held-out rows the predicted figure is scored on
    held = [a - b @ _nuisance(a, b, list(range(len(a))))[1] for a, b in rows]
    values, vectors = np.linalg.eigh(sum(np.einsum("nri,nrj->ij", h, h) for h in held) / sum(len(h) for h in held))
    seen = values > UNSEEN_TOL * values.max()
    require(seen.any(), "no candidate configuration informs any coefficient: check the fixtures and the error model")
    T = vectors[:, seen] / np.sqrt(values[seen])
    rows, held = [(a @ T, b) for a, b in rows], [h @ T for h in held]

    start, chosen, swaps, passes = _search(rows, minimum, n_poses, np.random.default_rng(seed), max_passes)
    out = {name: _figures(rows, c, held, noise_m) for name, c in (("design", chosen), ("random", start))}
    if out["design"][1] is None:
        raise ModelError(f"{n_poses} configurations leave some coefficient undetermined over these fixtures; give "
                         f"more poses or more fixtures")
    # how many fixtures: the same number of poses over the first k of them, scored on all
    by_count = []
    for k in range(1, len(fixtures)):
        if sum(minimum[:k]) <= n_poses <= sum(len(a) for a, _ in rows[:k]):
            sub = _search(rows[:k], minimum[:k], n_poses, np.random.default_rng(seed), max_passes)[1]
            by_count.append((k, *_figures(rows, sub + [[] for _ in rows[k:]], held, noise_m)))
    by_count.append((len(fixtures), *out["design"]))
    return FixtureDesign(tuple(np.array(sorted(c), int) for c in chosen), tuple(np.array(c, int) for c in start),
                         {k: v[0] for k, v in out.items()}, {k: v[1] for k, v in out.items()}, 1e3 * noise_m,
                         int(seen.sum()), int((~seen).sum()), tuple(len(q) for q in cands.q), swaps, passes,
                         tuple(by_count))


def _search(rows, minimum: list[int], n_poses: int, rng: np.random.Generator, max_passes: int):
    """(start, chosen, swaps, passes): the even random start over the fixtures of `rows` and the
    exchange's choice from it, per fixture lists of candidate indices."""
    share = np.full(len(rows), n_poses // len(rows)) + (np.arange(len(rows)) < n_poses % len(rows))
    share = np.minimum(np.maximum(share, minimum), [len(a) for a, _ in rows])
    while share.sum() < n_poses:  # a fixture with few reachable candidates leaves its share to the others
        share[np.argmax([len(a) - s for (a, _), s in zip(rows, share)])] += 1
    while share.sum() > n_poses:
        share[np.argmax(share - minimum)] -= 1
    start = [sorted(rng.choice(len(a), s, replace=False).tolist()) for (a, _), s in zip(rows, share)]
    search = _Exchange(rows, start, minimum)
    swaps, passes = search.passes(max_passes)
    return start, search.chosen, swaps, passes


def _figures(rows, chosen, held, noise_m: float) -> tuple[float | None, float | None]:
    """(log det of the whitened information, predicted RMS in mm, `_predicted_rms` on `held`) of chosen
    rows per fixture; None for both when they leave a direction every candidate together informs
    undetermined."""
    M = sum(_nuisance(a, b, c)[2] for (a, b), c in zip(rows, chosen))
    values = np.linalg.eigvalsh(M)
    if values.min() <= UNSEEN_TOL * values.max():
        return None, None
    return float(np.sum(np.log(values))), 1e3 * _predicted_rms(M, held, noise_m)
