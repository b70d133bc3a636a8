"""Registration: the rigid transform from the robot's world frame to the measurement frame.

A laser tracker or motion-capture system reports points in its own frame, y = R p + t with p in
the robot world. The closed form (Kabsch/Umeyama without scale) on the nominal model brings the
data into the robot world; what is left is small and belongs to frame 0's generalized errors.
A few gross points (a row swapped with another pose's, metres away) would tilt a least-squares
registration and every residual with it, so the closed form is iterated with robust weights
(`runtime.robust`): the gross points fall out of it before the fit starts.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from gecgen.model.validation import ModelError
from gecgen.runtime import robust

#: beyond these the measurement frame counts as "far" and is registered before the fit
FAR_ANGLE_RAD = np.radians(1.0)
FAR_DISTANCE_M = 0.02
#: the RMS extent (m) the measured points need across their main direction to fix a tracker frame:
#: a rotation fitted to points closer to a line (or to one point) follows their noise (30 um of noise
#: on one pose measured 60 times turned the frame 131 degrees)
MIN_SPREAD_M = 0.01


@dataclass(frozen=True)
class Registration:
    """y_measured = R @ p_world + t; `applied` says whether the data was mapped through it."""

    R: np.ndarray  # (3, 3)
    t: np.ndarray  # (3,) m
    applied: bool

    def to_world(self, y: np.ndarray) -> np.ndarray:
        """Measured points (..., 3) in the robot world frame."""
        return (y - self.t) @ self.R if self.applied else y

    @property
    def angle_rad(self) -> float:
        return _angle(self.R)

    def relative_to(self, other: "Registration") -> dict:
        """How far this tracker frame is from `other`: {angle_deg, distance_mm}, the rotation
        between them and the distance between the tracker origins in the world. A registration
        not applied stands for the world frame itself, since that is what the data was taken in."""
        (R1, t1), (R0, t0) = (r._frame() for r in (self, other))
        return {"angle_deg": float(np.degrees(_angle(R1 @ R0.T))),
                "distance_mm": float(1e3 * np.linalg.norm(R1.T @ t1 - R0.T @ t0))}

    def _frame(self) -> tuple[np.ndarray, np.ndarray]:
        return (self.R, self.t) if self.applied else (np.eye(3), np.zeros(3))

    def to_dict(self) -> dict:
        return {"rotation": self.R.tolist(), "translation": self.t.tolist(), "applied": self.applied,
                "angle_deg": float(np.degrees(self.angle_rad)), "distance_mm": float(1e3 * np.linalg.norm(self.t))}

    @classmethod
    def from_dict(cls, d: dict) -> "Registration":
        return cls(np.array(d["rotation"]), np.array(d["translation"]), bool(d["applied"]))


IDENTITY = Registration(np.eye(3), np.zeros(3), False)


def _angle(R: np.ndarray) -> float:
    """Rotation angle (rad) of a rotation matrix (3, 3)."""
    return float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)))


def kabsch(p: np.ndarray, y: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """R, t minimising sum w |y - (R p + t)|^2 over points p, y (N, 3), weights w (N,) (default 1)."""
    w = np.ones(len(p)) if w is None else w
    pc, yc = w @ p / w.sum(), w @ y / w.sum()
    U, _, Vt = np.linalg.svd((w[:, None] * (y - yc)).T @ (p - pc))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return R, yc - R @ pc


#: reweighted closed-form solves of a robust registration (weights settle within a few)
ROBUST_PASSES = 20


def robust_kabsch(p: np.ndarray, y: np.ndarray, loss: str, prior: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """`kabsch` iterated with robust point weights (`runtime.robust`) times the prior weights (N,)
    (default 1; the vertices of a measured frame have 1/4); plain weighted Kabsch for l2."""
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
    or "never" (the data is already in the robot world frame). loss: see `runtime.robust`.
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
    far = _angle(R) > FAR_ANGLE_RAD or np.linalg.norm(t) > FAR_DISTANCE_M
    return Registration(R, t, mode == "always" or (mode == "auto" and bool(far)))
