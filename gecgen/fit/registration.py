"""Registration: the rigid transform from the robot's world frame to the measurement frame.

A laser tracker or motion-capture system reports points in its own frame, y = R p + t with p in
the robot world. The closed form (Kabsch/Umeyama without scale) on the nominal model brings the
data into the robot world; what is left is small and belongs to frame 0's generalized errors.
A few gross points (a row swapped with another pose's, metres away) would tilt a least-squares
registration and every residual with it, so the closed form is iterated with robust weights
(`fit.robust`): the gross points fall out of it before the fit starts.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from gecgen.model.kinematics import joint_motion
from gecgen.model.validation import ModelError

#: beyond these the measurement frame counts as "far" and is registered before the fit
FAR_ANGLE_RAD = np.radians(1.0)
FAR_DISTANCE_M = 0.02
#: the RMS extent (m) the measured points need across their main direction to fix a tracker frame:
#: a rotation fitted to points closer to a line (or to one point) follows their noise (30 um of noise
#: on one pose measured 60 times turned the frame 131 degrees)
MIN_SPREAD_M = 0.01
#: m: with the data given in the robot's world (`register`'s auto), a direction of the fitted frame whose
#: 1-sigma moves a point of the workspace by more than HOLD_M, and along which the fit would move the
#: frame by more, is weakly determined: the robot's own errors pushed it there, not the frame; it is held
#: at the world frame and reported (a target's placement holds such a move likewise, `fit.placement`).
#: Only while the fitted frame leaves at most FITS_M rms at the points: a robot's own errors leave
#: millimetres, and data the nominal model does not describe (a mirrored world) determine nothing to hold
HOLD_M, FITS_M = 0.05, 0.005
#: Gauss-Newton steps of the registration with its weak directions held (a rigid fit settles within a few)
HELD_STEPS = 10


@dataclass(frozen=True)
class Registration:
    """y_measured = R @ p_world + t; `applied` says whether the data was mapped through it."""

    R: np.ndarray  # (3, 3)
    t: np.ndarray  # (3,) m
    applied: bool
    #: the directions of the frame held at the world frame, each with why (`register`)
    held: tuple[str, ...] = ()

    def to_world(self, y: np.ndarray) -> np.ndarray:
        """Measured points (..., 3) in the robot world frame."""
        return (y - self.t) @ self.R if self.applied else y

    @property
    def angle_rad(self) -> float:
        return rotation_angle(self.R)

    def relative_to(self, other: "Registration") -> dict:
        """How far this tracker frame is from `other`: {angle_deg, distance_mm}, the rotation
        between them and the distance between the tracker origins in the world. A registration
        not applied stands for the world frame itself, since that is what the data was taken in."""
        (R1, t1), (R0, t0) = (r._frame() for r in (self, other))
        return {"angle_deg": float(np.degrees(rotation_angle(R1 @ R0.T))),
                "distance_mm": float(1e3 * np.linalg.norm(R1.T @ t1 - R0.T @ t0))}

    def _frame(self) -> tuple[np.ndarray, np.ndarray]:
        return (self.R, self.t) if self.applied else (np.eye(3), np.zeros(3))

    def to_dict(self) -> dict:
        return {"rotation": self.R.tolist(), "translation": self.t.tolist(), "applied": self.applied,
                "angle_deg": float(np.degrees(self.angle_rad)), "distance_mm": float(1e3 * np.linalg.norm(self.t)),
                **({"held": list(self.held)} if self.held else {})}

    @classmethod
    def from_dict(cls, d: dict) -> "Registration":
        return cls(np.array(d["rotation"]), np.array(d["translation"]), bool(d["applied"]))


IDENTITY = Registration(np.eye(3), np.zeros(3), False)


def rotation_angle(R: np.ndarray) -> float | np.ndarray:
    """Rotation angle (rad, in [0, pi]) of a rotation matrix (3, 3), or of each of a stack (..., 3, 3):
    from |R - I| = 2 sqrt(2) sin(angle / 2) (Frobenius), which keeps its digits at small angles where
    arccos((trace R - 1) / 2) loses half of them."""
    angle = 2 * np.arcsin(np.clip(np.linalg.norm(R - np.eye(3), axis=(-2, -1)) / np.sqrt(8), 0, 1))
    return float(angle) if np.ndim(angle) == 0 else angle


def kabsch(p: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising sum w |y - (R p + t)|^2 over points p, y (N, 3), weights w (N,) (default 1)."""
    w = np.ones(len(p)) if w is None else w
    pc, yc = w @ p / w.sum(), w @ y / w.sum()
    R = nearest_rotation((w[:, None] * (y - yc)).T @ (p - pc))
    return R, yc - R @ pc


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) nearest to M (3, 3) in the Frobenius norm: U diag(1, 1, +-1) V^T from M's SVD,
    the sign making its determinant +1 (for a cross-covariance, Kabsch's rotation; for a sum of
    rotations, their chordal mean)."""
    U, _, Vt = np.linalg.svd(M)
    return U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt


#: reweighted closed-form solves of a robust registration (weights settle within a few)
ROBUST_PASSES = 20


def robust_kabsch(p: np.ndarray, y: np.ndarray, loss: str, prior: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """`kabsch` iterated with robust point weights (`fit.robust`) times the prior weights (N,)
    (default 1; the vertices of a measured frame have 1/4); plain weighted Kabsch for l2."""
    # here, not at the top: fit.robust loads scipy.special (a quarter of a second of start-up), and a
    # command that only reads a calibration's frames (compensate) registers nothing
    from gecgen.fit import robust

    prior = np.ones(len(p)) if prior is None else prior
    R, t = kabsch(p, y, prior)
    if loss == "l2":
        return R, t
    for _ in range(ROBUST_PASSES):
        e = np.linalg.norm(y - p @ R.T - t, axis=1)
        a = robust.outlier_limit(e, loss)
        if not a > 0:  # an exact fit: nothing to reweight
            break
        R_new, t_new = kabsch(p, y, prior * robust.weights(e, a, loss))
        moved = np.abs(R_new - R).max() + np.abs(t_new - t).max()
        R, t = R_new, t_new
        if moved < 1e-12:
            break
    return R, t


def spread_m(y: np.ndarray) -> float:
    """RMS extent (m) of points y (N, 3) across their main direction: the second singular value of
    the centred cloud over sqrt(N); zero for one point or a line."""
    if len(y) < 2:
        return 0.0
    return float(np.linalg.svd(y - y.mean(0), compute_uv=False)[1] / np.sqrt(len(y)))


def register(p_nominal: np.ndarray, y: np.ndarray, mode: str = "auto", loss: str = "cauchy",
             prior: np.ndarray | None = None) -> Registration:
    """Registration of measured points y onto nominal model points (N, 3), weighted by `prior` (N,).

    mode: "auto" applies it when the frames are far apart (over 1 degree or 20 mm), "always",
    or "never" (the data is already in the robot world frame). loss: see `fit.robust`.
    """
    if mode not in ("auto", "always", "never"):
        raise ValueError(f"registration mode {mode!r}: use auto, always or never")
    spread = spread_m(y)
    if len(y) < 3 or spread < MIN_SPREAD_M:
        if mode == "always":
            raise ModelError(f"registration needs measured points spread at least {1e3 * MIN_SPREAD_M:g} mm rms across "
                             f"their main direction per tracker stationing (these: {1e3 * spread:.3g} mm); measure "
                             f"poses apart, or do not register (--register never; register='never' in Python)")
        if mode == "auto" and len(y):
            warnings.warn(f"the measured points spread {1e3 * spread:.3g} mm rms across their main direction: too "
                          f"little to fix a tracker frame (at least {1e3 * MIN_SPREAD_M:g} mm), so none was fitted and "
                          f"the data is taken to be in the robot's world frame", stacklevel=2)
        return IDENTITY
    R, t = robust_kabsch(p_nominal, y, loss, prior)
    held: tuple[str, ...] = ()
    if mode == "auto":
        R, t, held = _hold_weak(p_nominal, y, R, t, prior)
        for why in held:
            warnings.warn(f"registration: {why}", stacklevel=2)
    far = rotation_angle(R) > FAR_ANGLE_RAD or np.linalg.norm(t) > FAR_DISTANCE_M
    return Registration(R, t, mode == "always" or (mode == "auto" and bool(far)), held)


def _skew(v: np.ndarray) -> np.ndarray:
    """(N, 3, 3) cross-product matrices of vectors v (N, 3)."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


def rotation_matrix(v: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) whose rotation vector is v (3,) (axis times angle, rad): a revolute joint's
    motion about v's axis (Rodrigues' formula), its Taylor series below a microradian where the axis
    loses digits."""
    v = np.asarray(v, float)
    theta = float(np.linalg.norm(v))
    if theta < 1e-6:
        K = _skew(v[None])[0]
        return np.eye(3) + K + K @ K / 2
    return joint_motion(v / theta, "R", np.array(theta))[:3, :3]


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """The rotation vector (3,) (axis times angle, rad, angle in [0, pi]) of a rotation R (3, 3): from its
    unit quaternion by Shepperd's choice of the largest of four pivots, accurate at every angle."""
    t = np.trace(R)
    pivots = [t, R[0, 0], R[1, 1], R[2, 2]]
    i = int(np.argmax(pivots))
    if i == 0:
        w = np.sqrt(1 + t) / 2
        v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (4 * w)
    else:
        a, b, c = i - 1, i % 3, (i + 1) % 3
        v = np.empty(3)
        v[a] = np.sqrt(1 + 2 * R[a, a] - t) / 2
        v[b], v[c] = (R[b, a] + R[a, b]) / (4 * v[a]), (R[c, a] + R[a, c]) / (4 * v[a])
        w = (R[c, b] - R[b, c]) / (4 * v[a])
    if w < 0:
        w, v = -w, -v
    n = float(np.linalg.norm(v))
    return v * (2 * np.arctan2(n, w) / n) if n > 0 else 2 * v


def _hold_weak(p: np.ndarray, y: np.ndarray, R: np.ndarray, t: np.ndarray, prior: np.ndarray | None
               ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The fitted frame (R, t) of points p onto y (N, 3; prior weights (N,)) with its weakly
    determined directions held at the world frame, and why each is held.

    The frame's moves are scaled to the workspace: a rotation by its motion at L, the larger of the
    measured points' extent and their distance from the world origin (the robot's base: the robot works
    from there to the data), a translation as it is, both taken about the points' centroid. A direction
    is weakly determined when its 1-sigma (what the residual left at the points, the robot's own errors
    among it, makes of it) is beyond HOLD_M; the fitted move along it is held when it is beyond HOLD_M
    too, and the fitted frame leaves at most FITS_M rms at the points. The frame is then refitted, by
    Gauss-Newton, in the directions the points determine."""
    w = np.ones(len(p)) if prior is None else prior
    pc = w @ p / w.sum()
    L = max(float(np.max(np.linalg.norm(p - pc, axis=1))), float(np.linalg.norm(pc)), MIN_SPREAD_M)
    scale = np.r_[np.full(3, L), np.ones(3)]  # per coordinate of the move: m at the workspace per unit

    def jacobian(R):
        # d(R p + t)/d(rotation vector about the centroid, translation of the centroid), in workspace units
        q = (p - pc) @ R.T
        return np.concatenate([-_skew(q), np.broadcast_to(np.eye(3), (len(p), 3, 3))], 2).reshape(-1, 6) / scale

    sw = np.repeat(np.sqrt(w), 3)
    J = jacobian(R) * sw[:, None]
    r = (y - p @ R.T - t).reshape(-1) * sw
    if np.sqrt(r @ r / w.sum()) > FITS_M:
        return R, t, ()
    sigma = float(np.sqrt(r @ r / max(3 * len(p) - 6, 1)))
    lam, U = np.linalg.eigh(J.T @ J)
    with np.errstate(divide="ignore"):
        std = np.where(lam > 0, sigma / np.sqrt(np.maximum(lam, 0)), np.inf)
    rotvec = rotation_vector(R)
    move = np.r_[L * rotvec, R @ pc + t - pc]  # the fitted frame against the world frame, workspace units
    along = U.T @ move
    weak = (std > HOLD_M) & (np.abs(along) > HOLD_M)
    if not weak.any():
        return R, t, ()
    held = []
    for i in np.nonzero(weak)[0]:
        u = U[:, i]
        turn = np.linalg.norm(u[:3]) >= np.linalg.norm(u[3:])
        axis, kind = (u[:3], "rotation about") if turn else (u[3:], "translation along")
        held.append(f"the {kind} ({', '.join(f'{a / np.linalg.norm(axis):.2f}' for a in axis)}) of the world would "
                    f"move the workspace by {1e3 * abs(along[i]):.0f} mm, further than the data support (its "
                    f"1-sigma {1e3 * std[i]:.0f} mm, beyond {1e3 * HOLD_M:g} mm: the measured points do not spread "
                    f"across it); held at the world frame (measure poses spread across it)")
    free = U[:, ~weak]
    m = free @ (free.T @ move)  # the move with the weak directions held
    for _ in range(HELD_STEPS):
        Rm = rotation_matrix(m[:3] / L)
        tm = pc + m[3:] - Rm @ pc
        r = (y - p @ Rm.T - tm).reshape(-1) * sw
        step = free @ np.linalg.lstsq(jacobian(Rm) * sw[:, None] @ free, r, rcond=None)[0]
        m = m + step
        if np.abs(step).max() < 1e-12:
            break
    Rm = rotation_matrix(m[:3] / L)
    return Rm, pc + m[3:] - Rm @ pc, tuple(held)

