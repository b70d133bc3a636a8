"""Accuracy over a volume from images (`gecgen accuracy --cameras`): the statement of `verify.volume`,
read from held-out images through the cameras a pixel calibration fitted.

What a camera measures is a direction: one image point fixes its marker across the ray, not along it.
A position in mm, which the statement is about, therefore needs two cameras or more seeing the same
marker at the same pose: the held-out markers are triangulated from the cameras as the calibration
placed them (their recorded poses and intrinsics), each with its own 1-sigma from the calibration's
pixel noise; a marker one camera alone sees is left out and counted. A camera on the tool sees a
board of known size, which fixes the camera's whole pose (OpenCV's PnP) and so, through the board's
pose and the camera's pose on the tool the calibration fitted, where every target of the tool is.
These points are then what a tracker would have measured, and the statement is read from them as
from a tracker's held-out data, their own noise counted as model error (safe: it only widens the
bound). The coefficients' covariance is the pixel fit's, taken image by image
(`fit.camera.image_covariance`) with the cameras' (the board's) poses, and the error is bounded against
the first camera (the board), where the images measure it (`against_reference`).
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
class Positions:
    """How the held-out positions were measured from images: `method`; `points` measured; std_mm the
    median and largest 1-sigma of a point along its worst direction (mm, from the calibration's pixel
    noise); `extra`: what the method leaves out and how well placed its rays are."""

    method: str
    points: int
    std_mm: tuple[float, float]
    extra: dict

    def to_dict(self) -> dict:
        return {"method": self.method, "points": self.points, "std_mm_median": self.std_mm[0],
                "std_mm_max": self.std_mm[1], **self.extra}


def triangulate(calibration, where: str, val, cameras: dict, board, sigma_px: float):
    """The held-out image points val (`model.pixels.Pixels`, fixed cameras) as measured positions: every
    marker seen by two cameras or more at a pose, triangulated (least squares in pixels from the
    rays' closest point) with the calibration's cameras; (Measurements, world points (R, 3) m,
    `Positions`: `single_camera_points` left out, `ray_angle_deg_min` and `_median` the smallest and
    median largest angle between the rays a point was triangulated from, depth being poor where it
    is small). Refused in one line when no marker is seen by two cameras."""
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
    return _measured(val, pose, target, xyz, row, stds, "triangulation from the calibration's cameras",
                     {"single_camera_points": single, "ray_angle_deg_min": float(np.min(angles)),
                      "ray_angle_deg_median": float(np.median(angles))})


def _measured(val, pose: list, target: list, xyz: list, row: list, stds: list, method: str, extra: dict):
    """The positions measured from the held-out images val as tracker-like data: (Measurements, world points
    (R, 3) m, `Positions`), pose/target/row the data's indices of each point and stds its 1-sigma (mm)."""
    y = np.array(xyz)
    data = Measurements(val.q, val.w, val.aux, val.aux_names, val.pose_ids, np.array(pose), np.array(target), y,
                        val.source, np.array(row))
    return data, y, Positions(method, len(y), (float(np.median(stds)), float(np.max(stds))), extra)


#: board corners an image needs for its camera's pose (OpenCV's iterative PnP takes six or more)
MIN_CORNERS = 6
#: step of the central differences of a PnP pose and of the reference pose (rad, m)
STEP = 1e-7


def from_carried_camera(calibration, where: str, val, cameras: dict, board, sigma_px: float):
    """The held-out images val of a camera on the tool as measured positions: per image, the camera's
    pose from the board's corners (OpenCV's PnP, through the intrinsics the calibration used) and the
    board where the calibration placed it give the tool's pose through the camera's pose on the tool the
    calibration fitted, and so every robot target's position; (Measurements, world points (R, 3) m,
    `Positions`: `images_left_out` with fewer than MIN_CORNERS corners). Each point's 1-sigma is the
    PnP pose's (the calibration's pixel noise through its Jacobian) carried to it."""
    import cv2
    from scipy.spatial.transform import Rotation

    problem, g = recorded_problem(calibration, where, val, cameras, board)
    (Rc, tc), = problem.unpack(g)[0]
    Rb, tb = problem.unpack(g)[1]
    cam = problem.cameras_of(g)[0]
    K, dist = cam.K, np.array(cam.distortion)
    names = list(calibration.robot.targets)
    local = np.array([calibration.robot.targets[n] for n in names], float) @ Rc.T + tc  # targets in the camera frame

    def world(x):  # x = (rvec, tvec) of the board in the camera: X_cam = R x_b + t
        R = Rotation.from_rotvec(x[:3]).as_matrix()
        return ((local - x[3:]) @ R) @ Rb.T + tb

    pose, target, xyz, row, stds, left = [], [], [], [], [], 0
    for p in range(val.n_poses):
        rows = np.flatnonzero(val.pose == p)
        if len(rows) < MIN_CORNERS:
            left += 1
            continue
        corners = board.corners[val.point[rows]]
        ok, rvec, tvec = cv2.solvePnP(corners, val.uv[rows], K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            left += 1
            continue
        _, J = cv2.projectPoints(corners, rvec, tvec, K, dist)
        cov = sigma_px ** 2 * np.linalg.pinv(J[:, :6].T @ J[:, :6])
        x = np.concatenate([rvec.ravel(), tvec.ravel()])
        D = np.stack([(world(x + STEP * e) - world(x - STEP * e)) / (2 * STEP) for e in np.eye(6)], -1)  # (T, 3, 6)
        for k, X in enumerate(world(x)):
            stds.append(1e3 * float(np.sqrt(max(np.linalg.eigvalsh(D[k] @ cov @ D[k].T)[-1], 0.0))))
            pose.append(p), target.append(k), xyz.append(X), row.append(int(val.row[rows[0]]))
    require(xyz, f"{val.source}: no image shows {MIN_CORNERS} board corners or more: the camera's pose, and so a "
                 f"position in mm, cannot be had from these images; take images that show the board")
    return _measured(val, pose, target, xyz, row, stds,
                     "the carried camera's pose from the board (PnP), carried to the targets through the camera's "
                     "pose on the tool the calibration fitted", {"images_left_out": left})


def against_reference(problem, g: np.ndarray, mount: str):
    """How stated points move against the set-up's reference when its fitted pose in g moves: the first
    camera for fixed cameras, the board for a camera on the tool. Returns a function of points (N, 3), m,
    in the calibration's world giving (N, 3, len(g)) (central differences; zero but for the reference's
    six entries). The coefficients' covariance is taken with those poses free, so it holds where the
    robot's base sits against them; the images measure the robot against them, and a truth's compensated
    error is read there too: with these rows the draws bound the error against the reference (on simulated
    truths the robot-frame draws made the bound 5 to 50 times the true worst: docs/camera.md)."""
    poses, board, _ = problem.unpack(g)
    R0, t0 = poses[0] if mount == "world" else board
    first = 0 if mount == "world" else 6 * len(poses)

    def mapped(gg, p):
        ps, b, _ = problem.unpack(gg)
        if mount == "world":  # into the camera as gg places it, out of it as g does
            R, t = ps[0]
            return (p @ R.T + t - t0) @ R0
        R, t = b  # into the board as gg places it, out of it as g does
        return (p - t) @ R @ R0.T + t0

    def rows(p: np.ndarray) -> np.ndarray:
        D = np.zeros((len(p), 3, len(g)))
        for j in range(first, first + 6):
            e = np.zeros(len(g))
            e[j] = STEP
            D[:, :, j] = (mapped(g + e, p) - mapped(g - e, p)) / (2 * STEP)
        return D

    return rows


def accuracy_from_images(calibration, where: str, volume, train, val, cameras: dict, board,
                         tolerance_mm: float | None, confidence: float, draws: int, rng: np.random.Generator,
                         share: float = 0.95):
    """`verify.volume.accuracy` from images: train (the pixel file the calibration was fitted to) gives
    the coefficients' covariance image by image, val (held-out images) the unmodelled error and the
    measured statement through its triangulated markers (`triangulate`, fixed cameras) or the targets
    its camera's pose places (`from_carried_camera`, a camera on the tool). Returns the samples, the
    statement, the compiled model of the stated points and the `Positions` record."""
    report = calibration.report
    problem, g = recorded_problem(calibration, where, train, cameras, board)
    rms = float(np.sqrt(np.mean(np.sum(problem.residual(g, calibration.c) ** 2, axis=1))))
    fit_rms = report.get("train", {}).get("rms_px")
    require(fit_rms is None or abs(rms - fit_rms) <= SAME_FIT * fit_rms + 1e-9,
            f"{train.source}: not the images the calibration was fitted to (their RMS residual is {rms:.4g} px, the "
            f"fit's {fit_rms} px); give the training images, and held-out images as --val")
    columns = held_columns(calibration)
    cov = image_covariance(problem, g, calibration.c, np.array(columns, int), report.get("loss", "cauchy"), True)
    measure = triangulate if train.mount == "world" else from_carried_camera
    data, y, info = measure(calibration, where, val, cameras, board, float(report["sigma_px"]))
    fitted = CompiledModel(calibration.robot, calibration.model)
    unmod = unmodelled(fitted, data, y, calibration.c, None)
    notes = []
    if info.extra.get("single_camera_points"):
        notes.append(f"{info.extra['single_camera_points']} markers seen by one camera only are left out: one camera "
                     f"does not measure depth")
    if info.extra.get("images_left_out"):
        notes.append(f"{info.extra['images_left_out']} held-out images with fewer than {MIN_CORNERS} board corners "
                     f"are left out")
    if report.get("intrinsics"):
        notes.append("the refined intrinsics' own uncertainty is not in the coefficients' covariance")
    how = ("markers triangulated from the calibration's cameras" if train.mount == "world" else
           "the targets placed by the carried camera's pose from the board")
    noise = (f"the held-out positions are {how} ({info.points} points; "
             f"1 sigma {info.std_mm[0]:.3g} mm median, {info.std_mm[1]:.3g} mm at most, along the worst direction): "
             f"their noise is counted as error the model does not describe, so the bound is pessimistic")
    samples, statement, cm = stated(calibration, volume, train, columns, cov, unmod, (data, y), None, tolerance_mm,
                                    confidence, draws, rng, share, notes, noise,
                                    against_reference(problem, g, train.mount))
    return samples, statement, cm, info
