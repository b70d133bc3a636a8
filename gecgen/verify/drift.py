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


def _p_value(e: np.ndarray, sigma_m: float, dof: int, ref_dof: float | None = None) -> float:
    """Probability that noise of sigma_m per coordinate leaves residuals e (R, 3) as large, over dof;
    with ref_dof, sigma_m is itself estimated over that many degrees of freedom (an F test)."""
    x = float(np.sum(e ** 2)) / sigma_m ** 2
    if ref_dof is not None:
        return float(special.fdtrc(max(dof, 1), ref_dof, x / max(dof, 1)))
    return float(special.chdtrc(max(dof, 1), x))


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


def _best_offset(column, n: int, r: np.ndarray) -> tuple[int, float, float] | None:
    """The one joint whose reading offset best explains the residual r (R,): (its index, the share of r's
    sum of squares the offset takes out, the offset in the joint's unit), or None when no joint moves
    anything; column(step) is the derivative of the model's measurements (R,) along a reading step (n,)
    of STEP on that joint."""
    best = None
    for j in range(n):
        g = column(STEP * np.eye(n)[j])
        gg = float(g @ g)
        if gg <= 0:
            continue
        share = float((g @ r) ** 2 / (gg * max(float(r @ r), 1e-300)))
        if best is None or share > best[1]:
            best = (j, share, float(g @ r) / gg)
    return best


def _joint(cm: CompiledModel, data: Measurements, aux: np.ndarray, c: np.ndarray, e: np.ndarray) -> dict:
    """The joint whose reading offset best explains the residual e (R, 3), or "unexplained"."""
    def column(step: np.ndarray) -> np.ndarray:
        up = cm.model_targets(data.q + step, data.w, aux, c)[data.pose, data.target]
        down = cm.model_targets(data.q - step, data.w, aux, c)[data.pose, data.target]
        return ((up - down) / (2 * STEP)).ravel()

    best = _best_offset(column, cm.robot.n, e.ravel())
    if best is None or best[1] < EXPLAINS:
        return {"kind": "unexplained", "best_joint_share": None if best is None else best[1]}
    j, share, offset = best
    return {"kind": "joint", "joint": f"q{j + 1}", "name": cm.robot.joints[j].name, "offset": offset,
            "unit": "rad" if cm.robot.joints[j].kind == "R" else "m", "explained": share}


#: image points a camera's (or the board's) pose is refitted from at least: six unknowns, and as many points
#: left over to judge the refit by
MIN_REFIT_POINTS = 6


@dataclass(frozen=True)
class PixelCheck:
    """A QA check from images (`check_pixels`): `check` as for a tracker, its lengths (rms_mm, max_mm,
    the tolerance) those of the image points' residuals across their rays at the points (mm at the
    target, `fit.camera.at_target_mm`) with the calibration's cameras as it recorded them; rms_px and
    max_px the same residuals in px; sigma_px the residual (px per coordinate) the noise is judged against;
    poses: per camera (and, for a camera on the tool, the board) seen at MIN_REFIT_POINTS points or
    more, what refitting its pose alone, the robot held as calibrated, does: rotation_deg and
    translation_mm (its optical centre's, or the board's origin's, move), rms_px and p_value of its
    image points before and after, and moved (they were beyond the noise before, and the refit took out
    more than noise lets six unknowns take)."""

    check: Check
    rms_px: float
    max_px: float
    sigma_px: float
    poses: list[dict]

    def to_dict(self) -> dict:
        return {**self.check.to_dict(), "rms_px": self.rms_px, "max_px": self.max_px,
                "reference_sigma_px": self.sigma_px, "poses_refitted": self.poses}


def check_pixels(calibration, where: str, data, cameras: dict, board, tolerance_mm: float | None = None,
                 reference: tuple[float, float] | None = None) -> PixelCheck:
    """The verdict on image points `data` (`model.pixels.Pixels`) of the robot a pixel calibration (read
    from `where`) calibrated, seen by the same cameras (and board): their residuals with the cameras as
    it recorded them, judged against its residual sigma_px (chi-square over two coordinates per point);
    when beyond it, what it looks like: a camera (or the board) moved, when refitting that pose alone
    brings its points within the noise; a joint, when one reading offset does (or explains at least
    EXPLAINS of the residual, as for a tracker); both, when either does (the images cannot tell them
    apart: a turn of the base joint is a turn of every fixed camera about it; with two cameras or more
    all moved, the joint is named and the cameras given as the other reading), else unexplained.
    reference: (sigma px per coordinate, its degrees of freedom) of held-out images taken with the
    calibration, judged against by an F test instead (the model's misfit at poses it was not fitted to
    is in both); None: the calibration's training sigma, taken as known (strict: new poses carry the
    misfit the fit did not see)."""
    from scipy.spatial.transform import Rotation

    from gecgen.fit.camera import at_target_mm, recorded_problem, refit_pose

    problem, g = recorded_problem(calibration, where, data, cameras, board)
    c = calibration.c
    sigma, ref_dof = reference or (float(calibration.report["sigma_px"]), None)
    e = problem.residual(g, c)
    length = np.linalg.norm(e, axis=1)
    mm, _ = at_target_mm(problem, g, c, length)
    p_value = _p_value(e, sigma, e.size, ref_dof)
    beyond = p_value < ALPHA
    blocks = [(k, name, data.camera == k) for k, name in enumerate(data.cameras)]
    if data.mount == "tool":  # the carried camera on the tool and the board in the world: each could have moved
        blocks.append((1, "board", np.ones(len(e), bool)))
    poses = []
    for k, name, rows in blocks:
        if rows.sum() < MIN_REFIT_POINTS:  # a pose's six unknowns from fewer points: any residual "moves" it
            continue
        h = refit_pose(problem, g, c, k, np.flatnonzero(rows))
        after = problem.residual(h, c)[rows]
        R0, R1 = (Rotation.from_rotvec(x[6 * k:6 * k + 3]).as_matrix() for x in (g, h))
        if data.mount == "tool" and name == "board":  # X_w = R x_b + t: its origin t
            move = h[6 * k + 3:6 * k + 6] - g[6 * k + 3:6 * k + 6]
        else:  # X_cam = R X + t: its optical centre -R^T t
            move = R1.T @ h[6 * k + 3:6 * k + 6] - R0.T @ g[6 * k + 3:6 * k + 6]
        drop = float(np.sum(e[rows] ** 2) - np.sum(after ** 2)) / sigma ** 2
        before_p = _p_value(e[rows], sigma, e[rows].size, ref_dof)
        poses.append({"pose": "board" if name == "board" else "camera", "name": name,
                      "rotation_deg": float(np.degrees(Rotation.from_matrix(R1 @ R0.T).magnitude())),
                      "translation_mm": float(1e3 * np.linalg.norm(move)),
                      "rms_px_before": float(np.sqrt(np.mean(np.sum(e[rows] ** 2, axis=1)))),
                      "rms_px_after": float(np.sqrt(np.mean(np.sum(after ** 2, axis=1)))),
                      "p_value_before": before_p,
                      "p_value_after": _p_value(after, sigma, after.size - 6, ref_dof),
                      # its points beyond the noise, and its refit takes out more than noise lets six unknowns take
                      "moved": before_p < ALPHA and _taken(drop, 6, ref_dof) < ALPHA, "_after": after})
    looks = {"kind": "as calibrated"}
    if beyond:
        looks = _pixel_looks(problem, g, c, e, sigma, ref_dof, poses, data.mount == "tool")
    for p in poses:
        del p["_after"]
    rms, worst = float(np.sqrt(np.mean(mm ** 2))), float(mm.max())
    verdict = Check(rms, worst, tolerance_mm, None if tolerance_mm is None else worst <= tolerance_mm, p_value,
                    beyond, looks)
    return PixelCheck(verdict, float(np.sqrt(np.mean(length ** 2))), float(length.max()), sigma, poses)


def pixel_reference(calibration, where: str, data, cameras: dict, board) -> tuple[float, float]:
    """(sigma px per coordinate, degrees of freedom) of held-out images `data` taken with a pixel
    calibration, their residuals with its cameras as recorded: what `check_pixels` judges new images
    against, the model's misfit at poses it was not fitted to included."""
    from gecgen.fit.camera import recorded_problem

    problem, g = recorded_problem(calibration, where, data, cameras, board)
    e = problem.residual(g, calibration.c)
    return float(np.sqrt(np.mean(e ** 2))), float(e.size)


def _pixel_looks(problem, g: np.ndarray, c: np.ndarray, e: np.ndarray, sigma: float, ref_dof: float | None,
                 poses: list[dict], tool: bool) -> dict:
    """What a residual e (R, 2) px beyond the noise sigma looks like (`check_pixels`)."""
    moved = [p for p in poses if p["moved"]]
    if tool and len(moved) == 2:  # the carried camera or the board: the one whose refit takes out more
        moved = [max(moved, key=lambda p: p["p_value_after"])]
    left = e.copy()
    for p in moved:
        left[problem.data.camera == problem.data.cameras.index(p["name"]) if p["pose"] == "camera" else
             slice(None)] = p["_after"]
    # every moved pose refitted, the images are within the noise
    camera = bool(moved) and _p_value(left, sigma, left.size - 6 * len(moved), ref_dof) >= ALPHA
    r = e.ravel()
    # a reading offset moves the model's image points, and the residual (measured - model) the other way
    best = _best_offset(lambda step: ((_at_readings(problem, -step).residual(g, c)
                                       - _at_readings(problem, step).residual(g, c)) / (2 * STEP)).ravel(),
                        problem.robot.n, r)
    joint = None
    if best is not None:
        j, share, offset = best
        rest = float(r @ r) * (1 - share)
        p_after = _p_value(np.sqrt(rest), sigma, r.size - 1, ref_dof)
        # the offset takes out more than noise alone lets one unknown take, and leaves the noise
        significant = _taken(float(r @ r) * share / sigma ** 2, 1, ref_dof) < ALPHA
        joint = {"kind": "joint", "joint": f"q{j + 1}", "name": problem.robot.joints[j].name, "offset": offset,
                 "unit": "rad" if problem.robot.joints[j].kind == "R" else "m", "explained": share,
                 "p_value_after": p_after}
    joint_explains = joint is not None and significant and joint["p_value_after"] >= ALPHA
    names = [p["name"] for p in moved]
    if camera and joint_explains and len(moved) >= 2:
        # one reading offset against every camera moved at once, by 6 unknowns each: the robot, named so
        return joint | {"or": f"every camera moved ({', '.join(names)}), each refit alone explaining its images"}
    if camera and joint_explains:
        return {"kind": "moved or joint", "moved": names, "joint": joint,
                "why": f"refitting {', '.join(names)} alone and a reading offset of {joint['joint']} alone each bring "
                       f"the images within the noise: these images cannot tell them apart"}
    if camera:
        return {"kind": "board moved" if names == ["board"] else "camera moved", "moved": names,
                "best_joint_share": None if joint is None else joint["explained"]}
    if joint is not None and (joint_explains or joint["explained"] >= EXPLAINS):
        return joint
    return {"kind": "unexplained", "best_joint_share": None if joint is None else joint["explained"]}


def _taken(drop: float, k: int, ref_dof: float | None) -> float:
    """Probability that noise alone lets k unknowns take `drop` (the fall of the residual sum of squares
    over sigma^2) or more; with ref_dof, sigma estimated over that many degrees of freedom."""
    drop = max(drop, 0.0)
    return float(special.chdtrc(k, drop) if ref_dof is None else special.fdtrc(k, ref_dof, drop / k))


def _at_readings(problem, step: np.ndarray):
    """The pixel problem with every pose's joint readings moved by step (n,)."""
    import copy

    shifted = copy.copy(problem)
    shifted.inputs = (problem.data.q + step, *problem.inputs[1:])
    return shifted
