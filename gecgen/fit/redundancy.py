"""Redundancy analysis: which coefficients cannot be identified, and what each one merges into.

Two kinds, both decided by an exact rank test on column-normalised `H_e` (greedy Gram-Schmidt in
a fixed preference order, so ties are broken the same way every time):

* structural - dependent at generic poses (random joints, wrench and aux within the limits), so
  no data can ever separate it. The analytic rules (Meggiolaro and Dubowsky 2000) set the order:
  for a revolute joint i, translation along and rotation about its axis at frame i-1 (for DH,
  `ez` and `er` of frame i-1) act like the joint and frame i; for a prismatic joint, every
  translation of frame i-1 and the rotation about the axis (`ex ey ez er`); with one measured
  point the last frame's rotations act like its translations. These are eliminated first, so the
  counts reproduce 4R + 2P + 6 (full pose) and 4R + 2P + 3 (one point); the same test also
  catches the cross-redundancies polynomial terms add beyond the rules.
* unexcited - independent at generic poses but dependent on the actual data (joints the data
  never moves, a wrench that never changes).
* weak - only with a rank tolerance (`unexcited(rank_tol=...)`, `identify --rank-tol`): independent
  on the data, but so nearly dependent that the data cannot hold its value against the noise.

"Merged into" is the least-squares representation of the eliminated column by the kept ones: a
value c of the eliminated coefficient is indistinguishable from adding factor * c to each.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field

import numpy as np

from gecgen.model.errors import ErrorModel
from gecgen.model.kinematics import constant
from gecgen.model.robot import ERROR_NAMES, Robot

#: a normalised column whose part orthogonal to the kept ones is below this is dependent
RANK_TOL = 1e-7
#: a column shorter than this share of the longest is zero up to rounding (entries are O(1) m per
#: unit error, rounding leaves O(1e-16)); legitimate small columns (high powers of short joint
#: travels) stay far above it
ZERO_COLUMN = 1e-12
#: a generalized error that moves the measured points by less than this per unit (m per m, m per
#: rad: a lever arm of 10 nm) is invisible to them; what a URDF's rounded angles leave (1e-10) is not
#: a lever arm, and no real one is shorter than a micrometre
BLIND_LEVER_M = 1e-8
#: merged-into entries contributing less than this (relative) are not listed
MERGE_REPORT_TOL = 1e-6


@dataclass(frozen=True)
class Eliminated:
    param: str
    index: int
    # "structural", "unexcited", "weak", "relative" (invisible to sockets and planes), (identify's
    # hold) "insignificant", (weakly determined against the noise, `fit.weak`) "held" or (held by the
    # caller of a pixel fit, `fit_pixels(hold=...)`) "given"
    reason: str
    detail: str
    merged_into: tuple[tuple[str, float], ...] = ()
    share: float | None = None  # weak only: the part of its normalised column outside the kept ones

    def to_dict(self) -> dict:
        out = {"param": self.param, "reason": self.reason, "detail": self.detail,
               "merged_into": [{"param": p, "factor": f} for p, f in self.merged_into]}
        return out if self.share is None else {**out, "share": self.share}


@dataclass(frozen=True)
class Redundancy:
    names: tuple[str, ...]
    kept: tuple[int, ...]
    eliminated: tuple[Eliminated, ...] = field(default_factory=tuple)

    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def n_identifiable(self) -> int:
        """What the data can separate: the kept coefficients and those held at zero for being
        insignificant (identifiable, but not determined)."""
        return len(self.kept) + sum(e.reason == "insignificant" for e in self.eliminated)

    def to_dict(self) -> dict:
        counts = {r: sum(e.reason == r for e in self.eliminated)
                  for r in ("structural", "unexcited", "weak", "relative", "insignificant", "held")}
        return {"n_params": self.n_params, "n_identifiable": self.n_identifiable,
                "n_structural": counts["structural"], "n_unexcited": counts["unexcited"], "n_weak": counts["weak"],
                **({"n_relative": counts["relative"]} if counts["relative"] else {}),
                **({"n_held": counts["held"]} if counts["held"] else {}),
                **({"n_insignificant": counts["insignificant"], "n_carried": len(self.kept)}
                   if counts["insignificant"] else {}),
                "identifiable": [self.names[k] for k in self.kept],
                "eliminated": [e.to_dict() for e in self.eliminated]}

    def to_json(self) -> str:
        """Every field, exactly (floats round-trip through JSON): the inverse of `from_json`."""
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> "Redundancy":
        d = json.loads(text)
        return cls(tuple(d["names"]), tuple(d["kept"]),
                   tuple(Eliminated(**{**e, "merged_into": tuple(map(tuple, e["merged_into"]))})
                         for e in d["eliminated"]))


def rule_candidates(robot: Robot, n_targets_measured: int) -> dict[int, str]:
    """Generalized errors (eps index) the analytic rules eliminate, with the rule in words."""
    out: dict[int, str] = {}
    children = [robot.parent(i) for i in range(1, robot.n_frames + 1)]
    for i, joint in enumerate(robot.chain, start=1):
        p = robot.parent(i)
        axis = constant(joint.pre)[:3, :3] @ np.array([float(a) for a in joint.axis])  # in frame p
        k = int(np.argmax(np.abs(axis)))
        if abs(abs(axis[k]) - 1) > 1e-9 or children.count(p) > 1:
            continue  # axis not along a frame axis, or frame p carries other branches too: the rank test decides
        rot = {0: "ep", 1: "es", 2: "er"}[k]
        if joint.kind == "R":
            errs = [f"e{'xyz'[k]}", rot]
            why = f"revolute joint {i} ({joint.name}): translation along and rotation about its axis at frame {p} act like the joint and frame {i}"
        else:
            errs = ["ex", "ey", "ez", rot]
            why = f"prismatic joint {i} ({joint.name}): translations of frame {p} and rotation about its axis act like frame {i}"
        for e in errs:
            out[6 * p + ERROR_NAMES.index(e)] = why
    if n_targets_measured == 1 and not robot.branches:
        for e in ("es", "er", "ep"):
            last = robot.n_frames
            out.setdefault(6 * last + ERROR_NAMES.index(e),
                           f"one measured point: rotations of the last frame ({last}) act like its translations")
    return out


def preference_order(robot: Robot, model: ErrorModel, candidates: dict[int, str]) -> np.ndarray:
    """Coefficient indices, most wanted first: rule-eliminated errors last; lower terms before higher."""
    coefs = model.coefficients
    position = {}
    for e, terms in enumerate(model.terms):
        for k, t in enumerate(terms):
            position[(e, t.text)] = k
    key = [(c.error in candidates, position[(c.error, c.term.text)], c.error) for c in coefs]
    return np.array(sorted(range(len(coefs)), key=lambda j: key[j]))


def zero_columns(A: np.ndarray) -> np.ndarray:
    """(nc,) True where a column of A is zero up to rounding: below ZERO_COLUMN times the median
    of the nonzero columns.

    This must be decided before columns are normalised: a point on the last joint's axis cannot
    see a rotation about that axis, so that column is 1e-16 (rounding noise), and scaled to unit
    length the noise looks like an independent direction (a coefficient of 1e11 rad follows). The
    median, not the largest: one term with a huge constant (1e12*q1, time in Unix seconds squared)
    would otherwise make every other column look like rounding."""
    norms = np.linalg.norm(A, axis=0)
    nonzero = norms[norms > 0]
    return norms <= ZERO_COLUMN * max(float(np.median(nonzero)) if len(nonzero) else 0.0, np.finfo(float).tiny)


def select_independent(A: np.ndarray, order: np.ndarray, tol: float = RANK_TOL,
                       blind: np.ndarray | None = None) -> tuple[list[int], list[int]]:
    """Greedy rank test on the columns of A (m x nc) in `order`: (kept, dependent) indices.
    Columns marked in `blind` (nc,) are dependent whatever their rounding noise says."""
    norms = np.linalg.norm(A, axis=0)
    zero = zero_columns(A) if blind is None else zero_columns(A) | blind
    basis = np.empty((A.shape[0], min(A.shape)))  # filled column by column: no regrowing copies
    kept, dependent = [], []
    for j in order:
        if zero[j]:
            dependent.append(int(j))
            continue
        Q = basis[:, :len(kept)]
        v = A[:, j] / norms[j]
        for _ in range(2):  # twice is enough (Kahan-Parlett) for orthogonality to working precision
            v = v - Q @ (Q.T @ v)
        r = np.linalg.norm(v)
        if r < tol:
            dependent.append(int(j))
        else:
            basis[:, len(kept)] = v / r
            kept.append(int(j))
    return sorted(kept), dependent


def pivoted_order(A: np.ndarray, columns: list[int]) -> list[tuple[int, float]]:
    """Column-pivoted Gram-Schmidt over `columns` of A (QR with column pivoting): each step takes
    the column with the largest part outside those taken before. Returns (column, that part of
    its normalised column) in the order taken; the parts never increase, so the trailing columns
    are the coefficients the data determines worst."""
    V = A[:, columns] / np.linalg.norm(A[:, columns], axis=0)
    left = list(range(len(columns)))
    out = []
    while left:
        r = np.linalg.norm(V[:, left], axis=0)
        best = left[int(np.argmax(r))]
        out.append((columns[best], float(r.max())))
        left.remove(best)
        v = V[:, best] / np.linalg.norm(V[:, best])
        V[:, left] -= np.outer(v, v @ V[:, left])
    return out


def merged_into(A: np.ndarray, kept: list[int], dependent: list[int], names) -> dict[int, tuple]:
    """For each dependent column: ((kept name, factor), ...) largest contribution first."""
    if not dependent or not kept:
        return {j: () for j in dependent}
    X = np.linalg.lstsq(A[:, kept], A[:, dependent], rcond=None)[0]
    norms = np.linalg.norm(A, axis=0)
    out = {}
    for col, j in enumerate(dependent):
        share = np.abs(X[:, col]) * norms[kept] / max(norms[j], 1e-300)
        largest = np.argsort(-share)[:8]
        idx = largest[share[largest] > MERGE_REPORT_TOL]
        out[j] = tuple((names[kept[i]], float(X[i, col])) for i in idx)
    return out


def generic_design(robot: Robot, n_aux: int, n_poses: int, rng: np.random.Generator):
    """Random poses within the limits (continuous joints within +-pi), wrench and aux values."""
    lo, hi = map(np.array, robot.sampling_box())
    q = rng.uniform(lo, hi, (n_poses, robot.n))
    w = np.column_stack([rng.normal(0, 100, (n_poses, 3)), rng.normal(0, 20, (n_poses, 3))])
    return q, w, rng.normal(0, 1, (n_poses, n_aux))


def unmeasured_frames(robot: Robot, targets) -> dict[int, str]:
    """On a tree, the frames that move only branches of which no target is measured (`targets`:
    the measured targets' indices), each with the reason in words: their errors are not seen for
    want of data, which a lever arm of 0 m does not tell. {} on a serial robot."""
    measured = {robot.branch_of(robot.target_names[t]) for t in targets}
    unmeasured = [k for k in range(len(robot.branches)) if k not in measured]
    on = {k: set(robot.path(robot.branches[k].tip)) for k in range(len(robot.branches))}
    out = {}
    for f in range(robot.n_frames + 1):
        carried = [k for k in on if f in on[k]]
        if carried and all(k in unmeasured for k in carried):
            names = [robot.branches[k].name for k in carried]
            wanted = [t for t in robot.target_names if robot.branch_of(t) in carried]
            out[f] = (f"frame {f} moves only branch {', '.join(map(repr, names))}, of which the data measures no "
                      f"target ({', '.join(wanted)}); measure them to calibrate it")
    return out


def structural(A_generic: np.ndarray, lever: np.ndarray, robot: Robot, model: ErrorModel,
               n_targets_measured: int, unmeasured: dict[int, str] | None = None) -> Redundancy:
    """Structural analysis on A_generic (H_e rows at generic poses, or their R factor; m x nc with
    the model's coefficient columns) and each generalized error's lever arm there (ne,), m per m or
    rad: an error below BLIND_LEVER_M moves no measured point (a rotation about an axis through the
    only measured point), whatever rounding leaves in its columns."""
    names = tuple(model.coefficient_names(robot))
    candidates = rule_candidates(robot, n_targets_measured)
    coefs = model.coefficients
    blind = np.array([lever[c.error] < BLIND_LEVER_M for c in coefs], bool)
    kept, dependent = select_independent(A_generic, preference_order(robot, model, candidates), blind=blind)
    merges = merged_into(A_generic, kept, dependent, names)
    unmeasured = unmeasured or {}
    eliminated = [Eliminated(names[j], j, "structural",
                             unmeasured.get(coefs[j].error // 6) or candidates.get(coefs[j].error,
                                            f"the measured points cannot see it (lever arm {lever[coefs[j].error]:.2g} m)"
                                            if blind[j] else "depends on other terms of the model at every pose"),
                             merges[j]) for j in sorted(dependent)]
    return Redundancy(names, tuple(kept), tuple(eliminated))


def unexcited(red: Redundancy, A_data: np.ndarray, robot: Robot, model: ErrorModel,
              n_targets_measured: int, rank_tol: float = RANK_TOL) -> Redundancy:
    """`red` (the structural analysis) with what the data leaves unexcited. A_data (m x len(red.kept)):
    H_e rows of the data, or their R factor, over the structurally kept columns only: a structurally
    dependent coefficient depends on the others at every pose, so it needs no second test.

    rank_tol above RANK_TOL is a numerical rank: of the coefficients left, those whose normalised
    data column keeps less than rank_tol outside the better-excited ones (pivoted QR) are held at
    zero as "weak". Their least-squares values would be mostly noise, and noise the model then
    extrapolates to poses unlike the data's."""
    structural_kept = np.array(red.kept, int)
    names = [red.names[j] for j in structural_kept]  # A_data's columns
    local = -np.ones(red.n_params, int)
    local[structural_kept] = np.arange(len(structural_kept))
    order = local[preference_order(robot, model, rule_candidates(robot, n_targets_measured))]
    kept, dependent = select_independent(A_data, order[order >= 0])
    merges = merged_into(A_data, kept, dependent, names)
    eliminated = {e.index: e for e in red.eliminated}
    zero = zero_columns(A_data)
    for i in dependent:
        why = ("the data never excites it (zero column)" if zero[i]
               else "the data cannot separate it from the kept parameters")
        j = int(structural_kept[i])
        eliminated[j] = Eliminated(red.names[j], j, "unexcited", why, merges[i])
    if rank_tol > RANK_TOL and kept:
        ranked = pivoted_order(A_data, kept)
        weak = [(i, r) for i, r in ranked if r < rank_tol]
        kept = sorted(i for i, r in ranked if r >= rank_tol)
        merges = merged_into(A_data, kept, [i for i, _ in weak], names)
        for i, r in weak:
            j = int(structural_kept[i])
            why = (f"weakly excited: {r:.3g} of its normalised column lies outside the better-excited "
                   f"parameters (rank tolerance {rank_tol:g})")
            eliminated[j] = Eliminated(red.names[j], j, "weak", why, merges[i], r)
    return Redundancy(red.names, tuple(int(structural_kept[i]) for i in kept),
                      tuple(eliminated[j] for j in sorted(eliminated)))
