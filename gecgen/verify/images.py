"""Accuracy over a volume from images (`gecgen accuracy --cameras`): the statement of `verify.volume`,
read from held-out images through the cameras a pixel calibration fitted.

What a camera measures is a direction: one image point fixes its marker across the ray, not along it.
A position in mm, which the statement is about, therefore needs two cameras or more seeing the same
marker at the same pose: the held-out markers are triangulated from the cameras as the calibration
placed them (their recorded poses and intrinsics), each with its own 1-sigma from the calibration's
pixel noise; a marker one camera alone sees is left out and counted. The triangulated points are
then what a tracker would have measured, and the statement is read from them as from a tracker's
held-out data, their own noise counted as model error (safe: it only widens the bound). The
coefficients' covariance is the pixel fit's, taken image by image (`fit.camera.image_covariance`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.fit.camera import image_covariance, recorded_problem
from gecgen.model.measurements import Measurements
from gecgen.model.validation import require
from gecgen.runtime.compiled import CompiledModel
from gecgen.verify.volume import held_columns, stated, unmodelled

#: Gauss-Newton steps of a triangulated point from its linear first guess (the reprojection error settles in two)
STEPS = 5
#: train data is the calibration's when its residual RMS (px) with the recorded cameras is the fit's within this share
SAME_FIT = 1e-6


@dataclass(frozen=True)
class Triangulated:
    """How the held-out markers were measured: points triangulated (each from two cameras or more) and
    markers left out (seen by one camera only); std_mm the median and largest 1-sigma of a point along
    its worst direction (mm, from the calibration's pixel noise); ray_angle_deg the smallest and median
    largest angle between the rays a point was triangulated from (depth is poor where it is small)."""

    points: int
    single_camera: int
    std_mm: tuple[float, float]
    ray_angle_deg: tuple[float, float]

    def to_dict(self) -> dict:
        return {"method": "triangulation from the calibration's cameras", "points": self.points,
                "single_camera_points": self.single_camera, "std_mm_median": self.std_mm[0],
                "std_mm_max": self.std_mm[1], "ray_angle_deg_min": self.ray_angle_deg[0],
                "ray_angle_deg_median": self.ray_angle_deg[1]}


def triangulate(calibration, where: str, val, cameras: dict, board, sigma_px: float):
    """The held-out image points val (`model.pixels.Pixels`, fixed cameras) as measured positions: every
    marker seen by two cameras or more at a pose, triangulated (least squares in pixels from the
    rays' closest point) with the calibration's cameras; (Measurements, world points (R, 3) m,
    `Triangulated`). Refused in one line when no marker is seen by two cameras."""
    import cv2

    problem, g = recorded_problem(calibration, where, val, cameras, board)
    poses, _, _ = problem.unpack(g)
    cams = problem.cameras_of(g)
    targets = list(calibration.robot.targets)
    pose, target, xyz, row, stds, angles, single = [], [], [], [], [], [], 0
    for p in range(val.n_poses):
        for k in np.unique(val.point[val.pose == p]):
            rows = np.flatnonzero((val.pose == p) & (val.point == k))
            if len(np.unique(val.camera[rows])) < 2:
                single += 1
                continue
            C, D = [], []
            for r in rows:
                cam, (R, t) = cams[val.camera[r]], poses[val.camera[r]]
                x = cv2.undistortPoints(val.uv[r].reshape(1, 1, 2), cam.K, np.array(cam.distortion)).ravel()
                d = R.T @ np.array([x[0], x[1], 1.0])
                C.append(-R.T @ t), D.append(d / np.linalg.norm(d))
            M = [np.eye(3) - np.outer(d, d) for d in D]
            X = np.linalg.solve(sum(M), sum(m @ c for m, c in zip(M, C)))
            for _ in range(STEPS):  # the reprojection error, not the rays' distance, is what the pixels measure
                J, res = [], []
                for r in rows:
                    cam, (R, t) = cams[val.camera[r]], poses[val.camera[r]]
                    uv, P = cam.project((R @ X + t)[None], jacobian=True)
                    J.append(P[0] @ R), res.append(val.uv[r] - uv[0])
                J, res = np.concatenate(J), np.concatenate(res)
                X = X + np.linalg.lstsq(J, res, rcond=None)[0]
            cov = sigma_px ** 2 * np.linalg.pinv(J.T @ J)
            stds.append(1e3 * float(np.sqrt(max(np.linalg.eigvalsh(cov)[-1], 0.0))))
            angles.append(max(float(np.degrees(np.arccos(np.clip(a @ b, -1, 1)))) for a in D for b in D))
            pose.append(p), target.append(targets.index(val.points[k])), xyz.append(X), row.append(int(val.row[rows[0]]))
    require(xyz, f"{val.source}: no marker is seen by two cameras at one pose: one camera measures a marker across "
                 f"its ray, not along it, so no position in mm can be stated from these images; see the markers "
                 f"with two cameras or more, or score the images with gecgen evaluate --cameras (px, and mm across "
                 f"the ray)")
    y = np.array(xyz)
    data = Measurements(val.q, val.w, val.aux, val.aux_names, val.pose_ids, np.array(pose), np.array(target), y,
                        val.source, np.array(row))
    info = Triangulated(len(y), single, (float(np.median(stds)), float(np.max(stds))),
                        (float(np.min(angles)), float(np.median(angles))))
    return data, y, info


def accuracy_from_images(calibration, where: str, volume, train, val, cameras: dict, board,
                         tolerance_mm: float | None, confidence: float, draws: int, rng: np.random.Generator,
                         share: float = 0.95):
    """`verify.volume.accuracy` from images: train (the pixel file the calibration was fitted to) gives
    the coefficients' covariance image by image, val (held-out images) the unmodelled error and the
    measured statement through its triangulated markers (`triangulate`). Returns the samples, the
    statement, the compiled model of the stated points and the `Triangulated` record."""
    report = calibration.report
    require(train.mount == "world", f"{where}: a camera on the tool: accuracy --cameras triangulates markers seen "
                                    f"by two fixed cameras or more; score held-out images of a carried camera with "
                                    f"gecgen evaluate --cameras (px, and mm across the ray)")
    problem, g = recorded_problem(calibration, where, train, cameras, board)
    rms = float(np.sqrt(np.mean(np.sum(problem.residual(g, calibration.c) ** 2, axis=1))))
    fit_rms = report.get("train", {}).get("rms_px")
    require(fit_rms is None or abs(rms - fit_rms) <= SAME_FIT * fit_rms + 1e-9,
            f"{train.source}: not the images the calibration was fitted to (their RMS residual is {rms:.4g} px, the "
            f"fit's {fit_rms} px); give the training images, and held-out images as --val")
    columns = held_columns(calibration)
    cov = image_covariance(problem, g, calibration.c, np.array(columns, int), report.get("loss", "cauchy"))
    data, y, info = triangulate(calibration, where, val, cameras, board, float(report["sigma_px"]))
    fitted = CompiledModel(calibration.robot, calibration.model)
    unmod = unmodelled(fitted, data, y, calibration.c, None)
    notes = []
    if info.single_camera:
        notes.append(f"{info.single_camera} markers seen by one camera only are left out: one camera does not "
                     f"measure depth")
    if report.get("intrinsics"):
        notes.append("the refined intrinsics' own uncertainty is not in the coefficients' covariance")
    noise = (f"the held-out positions are markers triangulated from the calibration's cameras ({info.points} points; "
             f"1 sigma {info.std_mm[0]:.3g} mm median, {info.std_mm[1]:.3g} mm at most, along the worst direction): "
             f"their noise is counted as error the model does not describe, so the bound is pessimistic")
    samples, statement, cm = stated(calibration, volume, train, columns, cov, unmod, (data, y), None, tolerance_mm,
                                    confidence, draws, rng, share, notes, noise)
    return samples, statement, cm, info
