"""QA checks: a short measurement taken after a calibration (a morning's 5 to 10 poses on a patient
positioner), compared with what the calibration predicts.

Three questions, each answered from the check's own residuals e (measured less calibrated model, in
the calibration's tracker frame):

* does it pass? the largest point error against the user's tolerance;
* is the difference beyond noise? sum |e|^2 / sigma^2 against a chi-square law with 3 degrees of
  freedom per point, sigma the calibration's residual sigma (taken as known: its fit had many more
  points than a check); or, with a baseline (the same poses measured right after the calibration),
  the difference from it against twice the noise's variance, so the model's misfit at the check's
  poses cancels;
* what does it look like? a rigid motion (the tracker, or the robot's base, moved): the residual once
  a rigid transform is fitted to it, tested again (six degrees of freedom fewer); else the joint whose
  offset best explains it (the model's change per reading, by central differences), and its share.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from gecgen.model.measurements import Measurements
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.registration import kabsch

#: a difference is beyond noise when noise alone makes one as large with less than this probability
ALPHA = 0.01
#: a joint offset names the change when it explains at least this share of the residual
EXPLAINS = 0.5
#: rad or m: the central-difference step of a joint reading
STEP = 1e-6


@dataclass(frozen=True)
class Check:
    """A QA check's verdict: rms_mm and max_mm of the points' errors; passed against tolerance_mm
    (None without one); p_value that noise alone leaves a residual this large and beyond_noise
    (p < ALPHA); looks_like: "as calibrated" (not beyond noise), "rigid motion" (rotation_deg,
    translation_mm), "joint" (joint, offset in rad or m, unit, explained share) or "unexplained"."""

    rms_mm: float
    max_mm: float
    tolerance_mm: float | None
    passed: bool | None
    p_value: float
    beyond_noise: bool
    looks_like: dict

    def to_dict(self) -> dict:
        return {"rms_mm": self.rms_mm, "max_mm": self.max_mm, "tolerance_mm": self.tolerance_mm,
                "verdict": "no tolerance given" if self.passed is None else ("pass" if self.passed else "fail"),
                "p_value": self.p_value, "beyond_noise": self.beyond_noise, "looks_like": self.looks_like}


def _p_value(e: np.ndarray, sigma_m: float, dof: int) -> float:
    """Probability that noise of sigma_m per coordinate leaves residuals e (R, 3) as large, over dof."""
    return float(special.chdtrc(max(dof, 1), float(np.sum(e ** 2)) / sigma_m ** 2))


def check(cm: CompiledModel, data: Measurements, y: np.ndarray, c: np.ndarray, sigma_m: float,
          tolerance_mm: float | None = None, baseline: np.ndarray | None = None) -> Check:
    """The verdict on `data` (its measured points y (R, 3) in the robot world, m) for the model at
    coefficients c whose fit left a residual sigma of sigma_m (m per coordinate). With a baseline
    (R, 3): the same points measured right after the calibration, the change is judged against it
    rather than against the model, point by point, with sigma_m then the noise of one measurement:
    the model's own misfit at the check's poses cancels. Pass or fail is the model's error either way."""
    q, w, aux = data.q, data.w, data.aux_columns(cm.model.aux)
    p = cm.model_targets(q, w, aux, c)[data.pose, data.target]
    length = np.linalg.norm(y - p, axis=1)
    ref, sigma = (p, sigma_m) if baseline is None else (baseline, np.sqrt(2) * sigma_m)  # two measurements' noise
    e = y - ref
    p_value = _p_value(e, sigma, e.size)
    beyond = p_value < ALPHA
    looks = {"kind": "as calibrated" if baseline is None else "as at the baseline"}
    R, t = kabsch(ref, y) if beyond and len(y) >= 3 else (None, None)  # three points fix a rigid motion
    if R is not None and _p_value(y - (ref @ R.T + t), sigma, e.size - 6) >= ALPHA:
        angle = np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))
        looks = {"kind": "rigid motion", "rotation_deg": float(angle),
                 "translation_mm": float(1e3 * np.linalg.norm(t + (R - np.eye(3)) @ ref.mean(axis=0)))}
    elif beyond:
        looks = _joint(cm, data, aux, c, e)
    rms, worst = float(1e3 * np.sqrt(np.mean(length ** 2))), float(1e3 * length.max())
    return Check(rms, worst, tolerance_mm, None if tolerance_mm is None else worst <= tolerance_mm, p_value, beyond,
                 looks)


def at_check_joints(cm: CompiledModel, data: Measurements, c: np.ndarray, points: np.ndarray,
                    q_base: np.ndarray) -> np.ndarray:
    """Baseline points (R, 3) measured at readings q_base (P, n), carried to the check's readings
    data.q by the calibrated model's difference between the two (the check's wrench and aux for
    both): a pose read a little apart (a servo's standstill error) then compares like for like."""
    aux = data.aux_columns(cm.model.aux)
    at = (data.pose, data.target)
    return points + cm.model_targets(data.q, data.w, aux, c)[at] - cm.model_targets(q_base, data.w, aux, c)[at]


def _joint(cm: CompiledModel, data: Measurements, aux: np.ndarray, c: np.ndarray, e: np.ndarray) -> dict:
    """The joint whose reading offset best explains the residual e (R, 3), or "unexplained"."""
    n = cm.robot.n
    r = e.ravel()
    best = None
    for j in range(n):
        step = np.zeros(n)
        step[j] = STEP
        up = cm.model_targets(data.q + step, data.w, aux, c)[data.pose, data.target]
        down = cm.model_targets(data.q - step, data.w, aux, c)[data.pose, data.target]
        g = ((up - down) / (2 * STEP)).ravel()
        gg = float(g @ g)
        if gg <= 0:
            continue
        share = float((g @ r) ** 2 / (gg * max(float(r @ r), 1e-300)))
        if best is None or share > best[1]:
            best = (j, share, float(g @ r) / gg)
    if best is None or best[1] < EXPLAINS:
        return {"kind": "unexplained", "best_joint_share": None if best is None else best[1]}
    j, share, offset = best
    return {"kind": "joint", "joint": f"q{j + 1}", "name": cm.robot.joints[j].name, "offset": offset,
            "unit": "rad" if cm.robot.joints[j].kind == "R" else "m", "explained": share}
