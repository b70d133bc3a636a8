"""Weakly determined directions: what the data and the noise cannot hold, found and held.

Identifiable (`fit.redundancy`) says the data can separate a coefficient from the others at
all; it does not say by how much. A laser tracker measuring one reflector while the tool keeps its
orientation separates the wrist's rotation errors from the rest only through the tool's tiny
deviations from that orientation: the column of H_e is independent, but so nearly dependent that
the noise moves the least-squares value by metres. An undamped Gauss-Newton step then wanders
along that direction, and the fit either never settles or carries an absurd value.

The test is on the noise, not on a fixed rank tolerance. In the column-scaled least squares
(x = c * scale, the R factor Rk = U S V^T of the kept columns), the direction V[:, i] is
determined to sigma / S[i], sigma the noise per coordinate (stated, or the residual of the
linearised fit). Moving along it by that much changes coefficient j by V[j, i] / scale[j]
times it, and each generalized error by the sum of its coefficients' changes times their terms
(RMS over the measured poses). When the largest such change is beyond a plausible size
(PLAUSIBLE_M, PLAUSIBLE_RAD: a value known only that roughly is no robot's error), the direction
is weak: the coefficient it moves most is held at zero (the data cannot tell its value from zero),
and the test repeats on the rest, until every direction left is determined. Holding a coefficient rather than
a combination lets every later stage (covariance, significance gate, compensation) work on the
coefficients it knows; the fit's steps then lie in the determined subspace only. `identify` does
this when the fit of every coefficient cannot be trusted, and when a fit that stands carries a
generalized error beyond a plausible size (`largest`) that holding its weak directions removes at a
cost in residual the noise explains; any other fit that stands is judged by the significance gate.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.kinematics import tool_poses
from gecgen.fit.registration import nearest_rotation, rotation_angle

#: 1-sigma of a generalized error beyond which the data do not determine it (m, rad): real robots
#: are off their nominal model by tenths of a millimetre to a few, and a value known only to 5 mm
#: (5 mrad) is noise the compensation would carry to every pose
PLAUSIBLE_M = 0.005
PLAUSIBLE_RAD = 0.005
#: an estimated noise (m per coordinate) is taken at most as this: no instrument a calibration uses is
#: noisier, and a larger residual is the model missing the data (gross glitches under least squares, a
#: wrong robot file), which must not pass for noise and hold every direction
NOISE_CAP_M = 1e-3
#: the tool "never turns" when its nominal orientation stays within this (rad) of its mean over the data
TURN_RAD = 0.02
#: a joint "barely moves" when its readings span less than this (rad; m for a prismatic joint)
BARELY_RAD, BARELY_M = 0.05, 0.01


@dataclass(frozen=True)
class Held:
    """A coefficient held at zero because its direction is weakly determined: its name and index,
    the 1-sigma of its generalized error along that direction (`std`, in `unit`: mm or mrad; None
    when nothing in the data fixes it at all, as the scale without a known distance) and why the
    data leave it undetermined, in words."""

    param: str
    index: int
    std: float | None
    unit: str | None
    reason: str
    #: the 1-sigma along the direction of the generalized error it moves most, in plausible sizes (> 1)
    beyond: float | None = None

    def to_dict(self) -> dict:
        return {"param": self.param, **({} if self.std is None else {f"std_{self.unit}": self.std}),
                **({} if self.beyond is None else {"beyond_plausible": self.beyond}), "reason": self.reason}

    def __str__(self) -> str:
        known = ("" if self.beyond is None else
                 f" (its direction known only to {self.beyond:.3g} times a plausible size)")
        return f"{self.param}{known}: {self.reason}"


def said(held) -> list[str]:
    """The held coefficients as a person reads them: one line per reason (the tool that never turns
    holds a score of coefficients for one cause), the coefficients it holds named in it."""
    by_reason: dict[str, list[Held]] = {}
    for h in held:
        by_reason.setdefault(h.reason, []).append(h)
    return [f"not determined, held at zero: {str(hs[0]) if len(hs) == 1 else ', '.join(h.param for h in hs)}"
            f"{'' if len(hs) == 1 else f' ({len(hs)} coefficients): {reason}'}" for reason, hs in by_reason.items()]


#: poses the generalized errors of a direction are evaluated at, at most (spread through the data)
SAMPLE_POSES = 2000


def term_values(cm, data) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the test works with: each coefficient's term at up to SAMPLE_POSES poses spread through
    `data` (P, nc), the generalized error each scales (nc,) and that error's plausible size (nc,),
    m or rad."""
    poses = np.unique(np.linspace(0, data.n_poses - 1, min(data.n_poses, SAMPLE_POSES)).astype(int))
    terms = [t.text for t in cm.model.unique_terms()]
    f = cm.basis(data.q[poses], data.w[poses], data.aux_columns(cm.model.aux)[poses])
    coefs = cm.model.coefficients
    F = f[:, [terms.index(c.term.text) for c in coefs]]
    error = np.array([c.error for c in coefs])
    return F, error, np.where(error % 6 < 3, PLAUSIBLE_M, PLAUSIBLE_RAD)


def largest(cm, data, c: np.ndarray) -> tuple[float, str]:
    """The largest generalized error that coefficients c (nc,) give at the poses of `data`, in
    plausible sizes (PLAUSIBLE_M, PLAUSIBLE_RAD), and the error's name."""
    F, error, limit = term_values(cm, data)
    size, name = 0.0, ""
    for e in np.unique(error):
        on = error == e
        value = float(np.abs(F[:, on] @ c[on]).max()) / limit[on][0] if len(F) else 0.0
        if value > size:
            size, name = value, cm.robot.error_names()[e]
    return size, name


def weak(Rk: np.ndarray, scale: np.ndarray, F: np.ndarray, error: np.ndarray, limit: np.ndarray,
         sigma: float) -> list[tuple[int, float, float]]:
    """The positions (in Rk's columns) of the coefficients to hold, each with the 1-sigma (m or
    rad, RMS over the poses) of its generalized error along its direction and that direction's
    largest 1-sigma in plausible sizes (> 1), weakest first. Rk (k, k): R factor of the kept
    columns scaled by scale (k,); F, error, limit: `term_values` of those coefficients (P, k), (k,),
    (k,); sigma: the noise per coordinate (m).

    A direction moves every generalized error it touches by the sum of its coefficients' terms,
    which is what is compared with a plausible size: a constant and a slope in Unix seconds are each
    known to metres, their difference (what the data see) to micrometres."""
    active = list(range(Rk.shape[1]))
    out = []
    if not sigma > 0 or not np.isfinite(sigma):
        return out
    while active:
        _, S, Vt = np.linalg.svd(Rk[:, active])
        D = Vt / scale[active]  # per direction (row): the coefficients' change per scaled unit move
        size = np.zeros((len(S), len(active)))  # per direction: each coefficient's error's RMS motion
        err = error[active]
        for e in np.unique(err):
            on = err == e
            motion = np.sqrt(np.mean((F[:, active][:, on] @ D[:, on].T) ** 2, axis=0)) / limit[active][on][0]
            size[:, on] = motion[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(S > 0, sigma / S, np.inf) * size.max(axis=1)
        i = int(np.argmax(ratio))
        if not ratio[i] > 1.0:
            break
        # the coefficient held is the one the direction moves most in the scaled coordinates (QR
        # pivoting's choice): the column the others come nearest to, whose loss conditions the rest best
        j = int(np.argmax(np.abs(Vt[i])))
        with np.errstate(divide="ignore"):
            out.append((active[j], float(sigma / S[i] * size[i, j] * limit[active[j]]), float(ratio[i])))
        active.pop(j)
    return out


def hold(cm, data, kept, R: np.ndarray, scale: np.ndarray, dof: float, noise: float | None,
         cap: float) -> tuple[list[int], tuple[Held, ...]]:
    """Which of the coefficients `kept` (indices into the model's) the data hold and which they leave
    weakly determined: the positions in kept of those to fit and the held ones with why (`weak`,
    `reasons`). R (k+1, k+1): the R factor of [J / scale | r] over kept, from dof degrees of freedom
    (the residual's own unit: m for points, px for pixels; J's other unknowns, such as camera poses,
    already projected out). The noise per coordinate is `noise` when stated, else what the linearised
    fit over every kept column leaves, at most cap: if anything smaller than the noise, as it fits
    some noise too, so that fewer directions are held rather than more."""
    k = len(kept)
    if R.shape[0] < k + 1:  # fewer rows than unknowns: what the rows do not reach is not determined at all
        R = np.vstack([R, np.zeros((k + 1 - R.shape[0], R.shape[1]))])
    # without rows to spare, the residual says nothing of the noise: the cap stands for it
    sigma = noise if noise is not None else cap if dof <= k else \
        min(float(abs(R[k, k]) / np.sqrt(dof - k)), cap)
    F, error, limit = term_values(cm, data)
    kept = np.asarray(kept, int)
    found = weak(R[:k, :k], scale, F[:, kept], error[kept], limit[kept], sigma)
    held = tuple(reasons(cm, data, [int(kept[i]) for i, _, _ in found], [s for _, s, _ in found],
                         [r for _, _, r in found]))
    out = {i for i, _, _ in found}
    return [i for i in range(k) if i not in out], held


def tool_turn(robot, q: np.ndarray) -> float:
    """The largest angle (rad) between the nominal tool orientation at a pose of q (P, n) and
    its mean over them (on a tree: over every branch's tool, the largest)."""
    out = 0.0
    for T in tool_poses(robot, q):
        R = T[:, :3, :3]
        mean = nearest_rotation(R.sum(axis=0))  # the chordal mean
        out = max(out, float(rotation_angle(R @ mean.T).max()))
    return out


def reasons(cm, data, indices, stds, beyond) -> list[Held]:
    """The held coefficients (indices into the model's, with their std in m or rad and their
    direction's in plausible sizes), each with why
    the data leave it undetermined, as far as the data tell: the tool never turns, its joint barely
    moves, no known distance fixes the scale; else the plain statement of its uncertainty."""
    robot = cm.robot
    names = cm.model.coefficient_names(robot)
    turn = tool_turn(robot, data.q)
    span = np.ptp(data.q, axis=0) if len(data.q) else np.zeros(robot.n)
    unscaled = data.relative is not None and not data.relative.distances and \
        not any(r.kind == "offset" for r in data.relative.relations)
    out = []
    for j, std, ratio in zip(indices, stds, beyond):
        e = cm.model.coefficients[j].error
        frame, rotation = e // 6, e % 6 >= 3
        unit, value = ("mrad", 1e3 * std) if rotation else ("mm", 1e3 * std)
        # frame i's errors are told from frame i+1's by joint i+1's motion, and carry joint i's terms
        barely = [i for i in (frame + 1, frame) if 1 <= i <= robot.n
                  and span[i - 1] < (BARELY_RAD if robot.joints[i - 1].kind == "R" else BARELY_M)]
        if unscaled:
            why = ("no known distance between sockets or planes: the data do not fix the scale, and this error "
                   "acts like it; held at zero (give a known distance to determine it)")
        elif turn < TURN_RAD:
            why = (f"the tool never turns (its orientation stays within {1e3 * turn:.3g} mrad over the data): its "
                   f"orientation errors are not determined, nor this error, which only a turn of the tool would "
                   f"tell from them; held at zero (measure poses that turn the tool, or a second target)")
        elif barely:
            i = barely[0]
            joint = robot.joints[i - 1]
            what = f"{span[i - 1]:.3g} {'rad' if joint.kind == 'R' else 'm'}"
            why = (f"joint {i} ({joint.name}) barely moves (its readings span {what}): the errors its motion "
                   f"would tell apart are not determined; held at zero (measure poses that move it)")
        elif not np.isfinite(ratio):
            why = ("the data do not determine it at all (fewer independent measurements than unknowns); held at zero "
                   "(measure more poses, or more targets or cameras)")
        else:
            why = (f"the data determine its direction only to {ratio:.3g} times a plausible size (1-sigma against "
                   f"{1e3 * PLAUSIBLE_M:g} mm, {1e3 * PLAUSIBLE_RAD:g} mrad); held at zero (measure poses that "
                   f"move it)")
        out.append(Held(names[j], int(j), value, unit, why, ratio))
    return out
