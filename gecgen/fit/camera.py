"""Identification from pixels: the robot's error coefficients and the cameras' poses from image points.

Why a Gauss-Newton of its own rather than `fit.identify`: identify fits 3-D points, and the
measuring frame it registers is a rigid motion solved in closed form beside the linear steps in the
coefficients. A pixel is a perspective projection: the camera's pose enters the residual as
nonlinearly as the coefficients do and must be stepped with them, in one system, and the residual
is in pixels, not metres. What is shared is reused: H_e from the compiled model (`model_targets`
with_H), the structural analysis of the error model (`identify.structural_analysis`) and the robust
losses (`fit.robust`).

The chain: the compiled model of the robot with four virtual targets, the tool origin and points
FRAME_ARM along its axes, gives the tool pose of every image and its H_e; a point on the tool and
its rows of H_e are affine in those four. Then
* eye-to-hand (cameras mount: world): X_cam = R_k X_w + t_k for camera k, X_w the robot target;
* eye-in-hand (mount: tool): X_cam = R_c X_tool + t_c, X_tool the board corner X_w = R_b x_b + t_b
  seen from the tool frame.
The unknowns are the coefficients the data determine and, per camera, (R, t) (and the board's pose,
and any target the robot file leaves to `estimate`). The residual is observed minus projected
pixels (`model.cameras.Camera.project`, OpenCV's model); its Jacobian in the coefficients is the
projection's d(u, v)/dX times dX/dc from H_e, in the poses by central differences (cheap: no call of
the generated code). On request each camera's intrinsics join the poses (`intrinsics`). The
coefficients the images determine too weakly against the noise are held first (`fit.weak`, as
identify holds them for a tracker), with the poses projected out of their columns.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.model.cameras import Board, Camera
from gecgen.model.errors import ErrorModel
from gecgen.model.pixels import Pixels
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.validation import ModelError, require
from gecgen.fit import robust, weak
from gecgen.fit.identify import RSS_TOL, WIDEN, noise_rise_limit, structural_analysis
from gecgen.fit.redundancy import Eliminated
from gecgen.fit.significance import clustered_covariance, judge
from gecgen.runtime.compiled import CompiledModel
from gecgen.runtime.threads import one_blas_thread

#: m: the arm of the virtual targets that give the tool frame (its orientation from their differences)
FRAME_ARM = 0.1
#: a coefficient whose scaled column keeps less than this share outside the poses' and the kept
#: coefficients' columns is not determined by pixels
RANK_TOL = 1e-7
#: median of a chi variable with 2 degrees of freedom (an image point's residual length)
MEDIAN_CHI2 = float(np.sqrt(2 * np.log(2)))
#: px: a Gauss-Newton step whose predicted change of the residual is below this per coordinate changes
#: nothing a camera resolves (a corner is found to 0.05 px at best)
STEP_TOL_PX = 1e-4
#: step (rad, m) of the central differences in the poses
STEP = 1e-7
#: px: an estimated noise per coordinate is taken at most as this: sub-pixel corners are found to a few
#: tenths of a pixel, and a larger residual is the model or the camera file missing the data, which must
#: not pass for noise and hold every direction
NOISE_CAP_PX = 1.0
#: a camera's intrinsics the fit refines on request: fx, fy, cx, cy and OpenCV's five distortion coefficients
N_INTRINSICS = 9
#: a refined intrinsic whose 1 sigma moves a point at the image's corner by more than this (px) is
#: not determined by the images
INTRINSICS_PX = 1.0
INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
#: the two reasons pixels leave a coefficient undetermined, named in `eliminated`
CAMERA_POSE = "camera pose"
SCALE = "scale"


@dataclass(frozen=True)
class Outlier:
    """An image point the robust fit flagged: its file line, pose id, camera, point, residual (px)
    and the weight it kept."""

    row: int
    pose: int
    camera: str
    point: str
    residual_px: float
    weight: float

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class PixelFit:
    """Result of `fit_pixels`. c (nc,) the coefficients (0 where eliminated); poses: per camera, its
    (R (3, 3), t (3,)) such that X_cam = R X + t, X in the world (mount world) or in the tool frame
    (mount tool); board: the board's (R, t) in the world (X_w = R x_b + t), None for world cameras;
    targets: the tool-frame position (m) of every target left to estimate; before and train:
    {rms_px, max_px, rms_mm_at_target, max_mm_at_target, distance_m, cameras: {name: the same}} with the
    cameras' first poses and the nominal model, and after the fit (`_summary`);
    eliminated: the coefficients held at zero and why; failures: why the fit must not be used; std (nc,)
    and cov (k, k) over `kept`, the poses' uncertainty carried in; sigma_px the residual per coordinate;
    ranges the span of every input over the data ({"q1": [lo, hi], ...}, as `identify.Fit.ranges`);
    held: the coefficients held at zero because the images determine them too weakly (`fit.weak`),
    each with why (also in eliminated, reason "held"); scale: how well the images fix the calibrated
    robot's scale (`_scale`); cameras: with intrinsics refined, the cameras as fitted, and
    intrinsics_std their 1-sigma per camera ({"fx": px, ..., "k1": ..}), None otherwise; residuals (R, 2)
    every image point's residual length after the fit, px and mm at the point (`at_target_mm`)."""

    c: np.ndarray
    poses: dict[str, tuple[np.ndarray, np.ndarray]]
    board: tuple[np.ndarray, np.ndarray] | None
    targets: dict[str, np.ndarray]
    kept: tuple[int, ...]
    eliminated: tuple[Eliminated, ...]
    before: dict
    train: dict
    outliers: tuple[Outlier, ...]
    iterations: int
    converged: bool
    loss: str
    failures: tuple[str, ...] = ()
    std: np.ndarray | None = None
    cov: np.ndarray | None = None
    sigma_px: float = np.nan
    ranges: dict | None = None
    held: tuple[weak.Held, ...] = ()
    scale: dict | None = None
    cameras: dict[str, Camera] | None = None
    intrinsics_std: dict[str, dict[str, float]] | None = None
    residuals: np.ndarray | None = None
    #: the geometric unknowns as fitted (rotation vectors and translations, in the fit's order) and
    #: every image point's robust weight (R,): where `linearised` takes the fit's least squares
    g: np.ndarray | None = None
    weights: np.ndarray | None = None

    def tool_camera(self) -> tuple[np.ndarray, np.ndarray]:
        """The carried camera's pose in the tool frame: (R, t) with X_tool = R X_cam + t."""
        R, t = next(iter(self.poses.values()))
        return R.T, -R.T @ t


def frame_robot(robot: Robot) -> Robot:
    """The robot with four virtual targets per branch (one on a serial chain): its tool origin and
    FRAME_ARM along each tool axis, a branch's four together, branch by branch."""
    a = FRAME_ARM
    axes = {"o": (0.0, 0.0, 0.0), "x": (a, 0.0, 0.0), "y": (0.0, a, 0.0), "z": (0.0, 0.0, a)}
    if not robot.branches:
        return replace(robot, targets=axes, estimated=(), target_frames={}, vertex_of={})
    targets = {f"{k}{b}": v for b in range(len(robot.branches)) for k, v in axes.items()}
    return replace(robot, targets=targets, target_branch={t: int(t[1:]) for t in targets}, estimated=(),
                   target_frames={}, vertex_of={})


class _Problem:
    """The residual of one pixel data set and its Jacobian (see the module docstring)."""

    def __init__(self, cm: CompiledModel, robot: Robot, data: Pixels, cameras: dict[str, Camera], board: Board | None,
                 intrinsics: bool = False):
        self.cm, self.robot, self.data, self.board = cm, robot, data, board
        self.cams = [cameras[n] for n in data.cameras]
        self.intrinsics = intrinsics
        self.tool = data.mount == "tool"
        self.inputs = (data.q, data.w, data.aux_columns(cm.model.aux) if cm.model.aux else None)
        seen = set(np.array(data.points)[data.point])
        self.estimated = [] if self.tool else [t for t in robot.estimated if t in seen]
        self.n_branches = max(len(robot.branches), 1)
        # each row's (pose, branch): where its point's tool frame is in `frames`' arrays (a board's corners:
        # the first branch's, the only one a camera rides on)
        branch = np.zeros(len(data.points), int) if self.tool else np.array([robot.branch_of(n) for n in data.points])
        self.at = (data.pose, branch[data.point])
        # geometric unknowns: 6 per camera (rotation vector, translation), 6 for the board, 3 per estimated target
        self.n_geom = 6 * len(self.cams) + (6 if self.tool else 0) + 3 * len(self.estimated)
        self.n_poses_geom = self.n_geom  # the unknowns before the intrinsics
        if intrinsics:  # refined: each camera's nine, last (`cameras_of`)
            self.n_geom += N_INTRINSICS * len(self.cams)

    def intrinsics_of(self) -> np.ndarray:
        """The given cameras' intrinsics as the fit's unknowns: fx, fy, cx, cy in units of the given fx
        (so that one finite-difference step suits them all) and the five distortion coefficients."""
        return np.concatenate([[c.fx / c.fx, c.fy / c.fx, c.cx / c.fx, c.cy / c.fx, *c.distortion] for c in self.cams])

    def cameras_of(self, g: np.ndarray) -> list[Camera]:
        """The cameras with the intrinsics of g when they are refined, else as given."""
        if not self.intrinsics:
            return self.cams
        k = self.n_poses_geom
        out = []
        for i, c in enumerate(self.cams):
            v = g[k + N_INTRINSICS * i:k + N_INTRINSICS * (i + 1)]
            out.append(replace(c, fx=c.fx * v[0], fy=c.fx * v[1], cx=c.fx * v[2], cy=c.fx * v[3],
                               distortion=tuple(map(float, v[4:]))))
        return out

    def frames(self, c: np.ndarray, with_H: bool = False):
        """Per pose and branch (B; one on a chain) the tool origin o (P, B, 3), rotation R (P, B, 3, 3)
        and, with_H, H_e of the four points (P, B, 4, 3, nc); a row's are at `self.at`."""
        q, w, aux = self.inputs
        out = self.cm.model_targets(q, w, aux, c, with_H=with_H)
        p, H = out if with_H else (out, None)
        p = p.reshape(len(q), self.n_branches, 4, 3)
        o = p[:, :, 0]
        R = np.stack([p[:, :, 1] - o, p[:, :, 2] - o, p[:, :, 3] - o], -1) / FRAME_ARM
        return o, R, (None if H is None else H.reshape(len(q), self.n_branches, 4, 3, -1))

    def unpack(self, g: np.ndarray):
        k = 6 * len(self.cams)
        poses = [(Rotation.from_rotvec(g[6 * i:6 * i + 3]).as_matrix(), g[6 * i + 3:6 * i + 6])
                 for i in range(len(self.cams))]
        board = (Rotation.from_rotvec(g[k:k + 3]).as_matrix(), g[k + 3:k + 6]) if self.tool else None
        k += 6 if self.tool else 0
        targets = {t: g[k + 3 * i:k + 3 * i + 3] for i, t in enumerate(self.estimated)}
        return poses, board, targets

    def local_points(self, targets: dict) -> np.ndarray:
        """(R, 3) each row's point: in the tool frame (robot targets) or the board frame (corners)."""
        if self.tool:
            return self.board.corners[self.data.point]
        names = self.data.points
        table = np.array([targets[n] if n in targets else self.robot.targets[n] for n in names], float)
        return table[self.data.point]

    def camera_points(self, g: np.ndarray, o: np.ndarray, R: np.ndarray) -> np.ndarray:
        """(R, 3) every row's point in its camera's frame."""
        poses, board, targets = self.unpack(g)
        d = self.data
        x = self.local_points(targets)
        Rp, op = R[self.at], o[self.at]
        if self.tool:
            Xw = x @ board[0].T + board[1]
            Xt = np.einsum("rji,rj->ri", Rp, Xw - op)
        else:
            Xw = np.einsum("rij,rj->ri", Rp, x) + op
        out = np.empty_like(x)
        for k, (Rc, tc) in enumerate(poses):
            rows = d.camera == k
            out[rows] = (Xt[rows] if self.tool else Xw[rows]) @ Rc.T + tc
        return out

    def project(self, X: np.ndarray, g: np.ndarray, jacobian: bool = False):
        uv = np.empty((len(X), 2))
        J = np.empty((len(X), 2, 3)) if jacobian else None
        for k, cam in enumerate(self.cameras_of(g)):
            rows = self.data.camera == k
            if jacobian:
                uv[rows], J[rows] = cam.project(X[rows], True)
            else:
                uv[rows] = cam.project(X[rows])
        return (uv, J) if jacobian else uv

    def residual(self, g: np.ndarray, c: np.ndarray) -> np.ndarray:
        """(R, 2) observed minus projected pixels."""
        o, R, _ = self.frames(c)
        return self.data.uv - self.project(self.camera_points(g, o, R), g)

    def jacobian(self, g: np.ndarray, c: np.ndarray, columns: np.ndarray):
        """Residual (R, 2) and its Jacobian (2R, n_geom + len(columns)) in (g, c[columns])."""
        o, R, H = self.frames(c, with_H=True)
        X = self.camera_points(g, o, R)
        uv, P = self.project(X, g, jacobian=True)
        d = self.data
        Jg = np.empty((len(X), 2, self.n_geom))
        for i in range(self.n_geom):
            e = np.zeros(self.n_geom)
            e[i] = STEP
            Jg[:, :, i] = (self.project(self.camera_points(g + e, o, R), g + e) -
                           self.project(self.camera_points(g - e, o, R), g - e)) / (2 * STEP)
        Jc = np.einsum("rij,rjc->ric", P, self.point_derivative(g, o, R, H[self.at][..., columns]))
        # the Jacobian of the residual: minus that of the projection
        return d.uv - uv, -np.concatenate([Jg, Jc], axis=2).reshape(2 * len(X), -1)

    def point_derivative(self, g: np.ndarray, o: np.ndarray, R: np.ndarray, D: np.ndarray) -> np.ndarray:
        """d(X_cam)/dx (R, 3, m) of every row's point in its camera's frame, from D (R, 4, 3, m): the
        derivative of the four frame points (`frame_robot`) at the row's pose in m unknowns (H_e's
        columns of coefficients, or J_e's of generalized errors)."""
        d = self.data
        dr = (D[:, 1:] - D[:, :1]) / FRAME_ARM  # d(tool axis k)/dx: (R, 3 axes, 3, m)
        poses, board, targets = self.unpack(g)
        x = self.local_points(targets)
        if self.tool:
            v = x @ board[0].T + board[1] - o[self.at]  # X_w - o
            # X_tool[k] = r_k . (X_w - o): d = dr_k . v - r_k . do
            dX = np.einsum("rkic,ri->rkc", dr, v) - np.einsum("rik,ric->rkc", R[self.at], D[:, 0])
        else:
            dX = D[:, 0] + np.einsum("rk,rkic->ric", x, dr)  # d(o + sum_k x_k r_k)
        out = np.empty_like(dX)
        for k, (Rc, _) in enumerate(poses):
            rows = d.camera == k
            out[rows] = np.einsum("ij,rjc->ric", Rc, dX[rows])
        return out


def _initial(problem: _Problem, c0: np.ndarray) -> np.ndarray:
    """The poses' first values from the nominal robot: OpenCV's solvePnP per fixed camera; for a carried
    camera, its pose on every image and the hand-eye solution (Tsai) for the camera on the tool."""
    try:
        import cv2
    except ImportError:
        raise ModelError("pixel data needs OpenCV: pip install 'gecgen[camera]' (opencv-python-headless)") from None
    d, g = problem.data, []
    o, R, _ = problem.frames(c0)
    for k, cam in enumerate(problem.cams):
        rows = np.nonzero(d.camera == k)[0]
        if not problem.tool:
            # targets left to estimate sit at the tool origin until fitted: kept out of the first guess
            # unless nothing else is left
            placed = rows[~np.isin(np.array(d.points)[d.point[rows]], problem.estimated)]
            rows = placed if len(placed) >= 6 else rows
            x = problem.local_points({t: np.zeros(3) for t in problem.estimated})[rows]
            at = problem.at[0][rows], problem.at[1][rows]
            Xw = np.einsum("rij,rj->ri", R[at], x) + o[at]
            ok, rvec, tvec = cv2.solvePnP(Xw, d.uv[rows], cam.K, np.array(cam.distortion), flags=cv2.SOLVEPNP_ITERATIVE)
            require(ok, f"{d.source}: camera {cam.name}: no camera pose explains its points; check the camera file "
                        f"and the point names")
            g.extend([*rvec.ravel(), *tvec.ravel()])
            continue
        Rg, tg, Rb, tb = [], [], [], []
        for p in np.unique(d.pose[rows]):
            at = rows[d.pose[rows] == p]
            if len(at) < 6:
                continue
            ok, rvec, tvec = cv2.solvePnP(problem.board.corners[d.point[at]], d.uv[at], cam.K,
                                          np.array(cam.distortion))
            if ok:
                Rg.append(R[p, 0]), tg.append(o[p, 0]), Rb.append(cv2.Rodrigues(rvec)[0]), tb.append(tvec.ravel())
        require(len(Rg) >= 3, f"{d.source}: camera {cam.name}: fewer than 3 images with 6 board corners or more; "
                              f"take more images of the board")
        Rcg, tcg = cv2.calibrateHandEye(Rg, tg, Rb, tb, method=cv2.CALIB_HAND_EYE_TSAI)
        Rct, tct = Rcg.T, -Rcg.T @ tcg.ravel()  # tool -> camera
        # the board in the world from the first image: X_w = R_g (R_cg (R_b x + t_b) + t_cg) + t_g
        Rw = Rg[0] @ Rcg @ Rb[0]
        tw = Rg[0] @ (Rcg @ tb[0] + tcg.ravel()) + tg[0]
        g.extend([*Rotation.from_matrix(Rct).as_rotvec(), *tct])
        g.extend([*Rotation.from_matrix(Rw).as_rotvec(), *tw])
    for _ in problem.estimated:
        g.extend([0.0, 0.0, 0.0])
    return np.array(g, float)


def at_target_mm(problem: _Problem, g: np.ndarray, c: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What residual lengths e (R,) px mean at the points: the length (mm) across the ray at the point's
    depth (e times depth over the mean focal length) and the depth (R,) m."""
    o, R, _ = problem.frames(c)
    depth = problem.camera_points(g, o, R)[:, 2]
    f = np.array([(cam.fx + cam.fy) / 2 for cam in problem.cameras_of(g)])[problem.data.camera]
    return 1e3 * e * depth / f, depth


def _rms_max(e: np.ndarray, mm: np.ndarray, depth: np.ndarray) -> dict:
    return {"rms_px": float(np.sqrt(np.mean(e ** 2))), "max_px": float(e.max()),
            "rms_mm_at_target": float(np.sqrt(np.mean(mm ** 2))), "max_mm_at_target": float(mm.max()),
            "distance_m": float(np.median(depth))}


def _summary(problem: _Problem, g: np.ndarray, c: np.ndarray, e: np.ndarray) -> dict:
    """The residual lengths e (R,) px: RMS and largest, in px and in mm at the points (`at_target_mm`),
    the median working distance (m), over all points, per camera (`cameras`) and, on a tree, per branch
    over the points it carries (`branches`, by name)."""
    mm, depth = at_target_mm(problem, g, c, e)
    cam = problem.data.camera
    out = _rms_max(e, mm, depth) | {"cameras": {n: _rms_max(e[cam == k], mm[cam == k], depth[cam == k])
                                                for k, n in enumerate(problem.data.cameras) if (cam == k).any()}}
    if problem.robot.branches:
        branch = problem.at[1]
        out["branches"] = {b.name: _rms_max(e[branch == k], mm[branch == k], depth[branch == k])
                           for k, b in enumerate(problem.robot.branches) if (branch == k).any()}
    return out


def _analysis(problem: _Problem, g: np.ndarray, c: np.ndarray, struct_kept: list[int], names: list[str],
              poses_known: bool = False):
    """The coefficients pixels determine (indices) and those they leave, each with why: the scale (a world
    camera's distance trades against the robot's lengths), the camera's (or board's) pose, or no image
    excites it. poses_known: the poses are given, not fitted (nothing merges with them)."""
    _, J = problem.jacobian(g, c, np.array(struct_kept, int))
    J = J / np.where(np.linalg.norm(J, axis=0) > 0, np.linalg.norm(J, axis=0), 1.0)
    ng = problem.n_geom
    kept, out, unexcited = [], [], []
    scale_dir = None
    if not problem.tool and not poses_known:  # does scaling the robot about the origin, cameras following, show?
        o, R, H = problem.frames(c, with_H=True)
        d = problem.data
        x = problem.local_points({t: np.zeros(3) for t in problem.estimated})
        Hc = H[problem.at][..., struct_kept]
        A = (Hc[:, 0] + np.einsum("rk,rkic->ric", x, (Hc[:, 1:] - Hc[:, :1]) / FRAME_ARM)).reshape(-1, len(struct_kept))
        p = (np.einsum("rij,rj->ri", R[problem.at], x) + o[problem.at]).ravel()
        sol, *_ = np.linalg.lstsq(A, p, rcond=None)
        if np.linalg.norm(A @ sol - p) < 1e-6 * np.linalg.norm(p):
            scale_dir = sol
    basis = np.zeros((len(J), 0)) if poses_known else np.linalg.qr(J[:, :ng])[0]
    own = np.zeros((len(J), 0))  # the kept coefficients' columns alone
    for i, j in enumerate(struct_kept):
        col = J[:, ng + i]
        rest = col - basis @ (basis.T @ col)
        alone = col - own @ (own.T @ col)
        if np.linalg.norm(rest) > np.sqrt(RANK_TOL):
            kept.append(j)
            basis = np.column_stack([basis, rest / np.linalg.norm(rest)])
            own = np.column_stack([own, alone / np.linalg.norm(alone)])
        elif np.linalg.norm(alone) > np.sqrt(RANK_TOL):
            out.append(j)
        else:
            unexcited.append(j)
    eliminated = []
    if scale_dir is not None and out:  # the coefficient the scale direction leans on most is the scale's
        weights = {j: abs(scale_dir[struct_kept.index(j)]) for j in out}
        s = max(weights, key=weights.get)
        if weights[s] > 0:
            eliminated.append(Eliminated(names[s], s, "unexcited", f"{SCALE}: pixels fix no length; the robot's "
                                         f"lengths and the cameras' distances trade off (give two targets a known "
                                         f"distance apart, or see a board of known size)"))
            out.remove(s)
    what = ("the carried camera's pose on the tool or the board's pose in the world" if problem.tool else
            "the cameras' poses in the world (pixels cannot tell a camera's pose from the robot base)")
    eliminated += [Eliminated(names[j], j, "unexcited", f"{CAMERA_POSE}: merges with {what}") for j in out]
    eliminated += [Eliminated(names[j], j, "unexcited", "not excited by these images") for j in unexcited]
    return kept, eliminated


def _set_up(robot: Robot, model: ErrorModel, data: Pixels, cameras: dict[str, Camera], board: Board | None,
            fixed_poses: np.ndarray | None, backend: str, intrinsics: bool = False, start: np.ndarray | None = None):
    """The problem, the poses' first values, the coefficients the pixels determine (indices) and those
    eliminated (structurally, and by `_analysis`), at the nominal model. start: the poses to begin
    from (fitted, not fixed) instead of OpenCV's first guess."""
    require(not (robot.branches and data.mount == "tool"), f"{robot.source}: a tree; a camera on the tool is "
                                                            f"supported on serial chains only: see the tree's "
                                                            f"markers with fixed cameras (mount: world)")
    cm = CompiledModel(frame_robot(robot), model, backend)
    problem = _Problem(cm, robot, data, cameras, board, intrinsics)
    c = np.zeros(cm.dims.nc)
    given = fixed_poses if fixed_poses is not None else start
    g = _initial(problem, c) if given is None else np.asarray(given, float)
    if intrinsics:
        g = np.concatenate([g, problem.intrinsics_of()])
    struct = structural_analysis(cm, np.arange(4 * problem.n_branches))
    kept, eliminated = _analysis(problem, g, c, list(struct.kept), model.coefficient_names(robot),
                                 fixed_poses is not None)
    return problem, g, kept, tuple(sorted([*struct.eliminated, *eliminated], key=lambda e: e.index))


def design_rows(robot: Robot, model: ErrorModel, data: Pixels, cameras: dict[str, Camera], board: Board | None,
                g: np.ndarray, sample: np.ndarray, block: int):
    """What a pose design for pixels weighs: the fit's Jacobian at the nominal model and the poses g
    (the fit's order: per camera its rotation vector and translation, then the board's), as its first
    step sees it. The coefficients it is taken in are those the images of the poses `sample` (indices)
    determine; it is computed `block` poses at a time. Returns J (2R, n_geom + k) over the poses and
    those k coefficients (rows (u, v) of every image point in the data's order), the coefficients
    (indices) and the ones eliminated (each with why)."""
    problem, g, kept, eliminated = _set_up(robot, model, data.subset(sample), cameras, board, None, "auto", start=g)
    c = np.zeros(problem.cm.dims.nc)
    parts = (_Problem(problem.cm, robot, data.subset(np.arange(s, min(s + block, data.n_poses))), cameras, board)
             for s in range(0, data.n_poses, block))
    return np.vstack([part.jacobian(g, c, np.array(kept, int))[1] for part in parts]), kept, eliminated


@one_blas_thread
def pixel_redundancy(robot: Robot, model: ErrorModel, data: Pixels, cameras: dict[str, Camera],
                     board: Board | None = None, noise_px: float | None = None) -> dict:
    """What image points leave undetermined, without a fit: `n_params`, `n_identifiable`, `eliminated`
    (structural; what pixels cannot give: `camera pose`, `scale`, not excited; and, merged by name, the
    coefficients `fit_pixels` would hold as weakly determined against the noise, reason `held`, as it
    holds them before its first step), `held` (those, each with why, as `fit_pixels` lists them) and
    `targets` (every target left to estimate: how well the images place it, `_placed_along_rays`).
    noise_px: the corners' noise per coordinate (px), else the linearised fit's residual at the nominal
    model, at most NOISE_CAP_PX."""
    problem, g, kept, eliminated = _set_up(robot, model, data, cameras, board, None, "auto")
    c = np.zeros(problem.cm.dims.nc)
    e = np.linalg.norm(problem.residual(g, c), axis=1)
    wr = robust.weights(e, _limit(e, "cauchy"), "cauchy")
    held = ()
    if kept:
        kept, held, eliminated = _with_held(problem, g, c, kept, eliminated, wr, True, noise_px)
    return {"n_params": len(model.coefficients), "n_identifiable": len(kept),
            **({"n_held": len(held)} if held else {}), "eliminated": [x.to_dict() for x in eliminated],
            "held": [h.to_dict() for h in held], "targets": _placed_along_rays(problem, g, c, kept, noise_px)}


def _limit(e: np.ndarray, loss: str) -> float:
    """The outlier limit (px) of residual lengths e (R,): robust.THRESHOLD times their noise, from the median."""
    return np.inf if loss == "l2" else robust.THRESHOLD * max(float(np.median(e)) / MEDIAN_CHI2, 1e-6)


def _with_held(problem: _Problem, g: np.ndarray, c: np.ndarray, kept: list[int], eliminated: tuple,
               wr: np.ndarray, free_g: bool, noise_px: float | None):
    """kept without the coefficients the images determine too weakly (`_hold_weak`), those held
    (`weak.Held`), and eliminated with them merged in by index (reason `held`)."""
    kept, held = _hold_weak(problem, g, c, kept, wr, free_g, noise_px)
    merged = tuple(sorted([*eliminated, *(Eliminated(h.param, h.index, "held", h.reason) for h in held)],
                          key=lambda x: x.index))
    return kept, held, merged


#: a target left to estimate whose position the images fix only to more than this (m, 1 sigma, along
#: its weakest direction) is not placed by them: as a generalized error of that size (`weak.PLAUSIBLE_M`)
PLACED_M = weak.PLAUSIBLE_M


def _placed_along_rays(problem: _Problem, g: np.ndarray, c: np.ndarray, kept: list[int],
                       noise_px: float | None) -> list[dict]:
    """How well the images place each target left to estimate, the cameras' poses and the coefficients
    kept fitted with it (linearised at poses g and coefficients c: the nominal model's before a fit, the
    fit's after it): `std_mm` the 1-sigma along its worst determined direction, `off_ray_deg` that
    direction's angle from the mean ray to it (camera to marker, in the tool frame), `rays_span_deg`
    the largest angle of a ray to it from that mean (how far apart the directions it is seen from
    are), `placed` (std_mm within PLACED_M) and, when not, `reason`. A marker seen from one direction
    is fixed across its ray by a pixel and along it only by the spread of the rays."""
    if not problem.estimated:
        return []
    cols = np.array(kept, int)
    # every point weighs 1: before a fit a target left to estimate sits at the tool origin, and robust
    # weights of the residual there would count its own points out
    wr = np.ones(len(problem.data.uv))
    A, b, scale = _system(problem, g, c, cols, wr, True)
    dof = max(2 * float(wr.sum()) - A.shape[1], 1.0)
    sigma = noise_px if noise_px is not None else min(float(np.linalg.norm(
        b - A @ np.linalg.lstsq(A, b, rcond=None)[0]) / np.sqrt(dof)), NOISE_CAP_PX)
    o, R, _ = problem.frames(c)
    poses, _, targets = problem.unpack(g)
    d = problem.data
    k0 = 6 * len(problem.cams)
    out = []
    for i, name in enumerate(problem.estimated):
        own = list(range(k0 + 3 * i, k0 + 3 * i + 3))
        rest = [j for j in range(A.shape[1]) if j not in own]
        # its three columns after everything else has taken what it can: the bottom block of R
        Rt = np.linalg.qr(A[:, rest + own], mode="r")[-3:, -3:]
        with np.errstate(all="ignore"):
            cov = sigma ** 2 * np.linalg.pinv(Rt.T @ Rt) / np.outer(scale[own], scale[own])
        w, V = np.linalg.eigh(cov)
        worst = V[:, -1]
        rows = np.nonzero(np.array(d.points)[d.point] == name)[0]
        at = problem.at[0][rows], problem.at[1][rows]
        x = np.einsum("rij,j->ri", R[at], targets[name]) + o[at]
        centres = np.array([-Rc.T @ tc for Rc, tc in poses])[d.camera[rows]]
        rays = np.einsum("rji,rj->ri", R[at], x - centres)  # in the tool frame
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        mean = rays.mean(axis=0) / np.linalg.norm(rays.mean(axis=0))
        span = float(np.degrees(np.arccos(np.clip(rays @ mean, -1, 1)).max()))
        std_mm = 1e3 * float(np.sqrt(max(w[-1], 0.0)))
        entry = {"target": name, "std_mm": std_mm,
                 "off_ray_deg": float(np.degrees(np.arccos(min(abs(float(worst @ mean)), 1.0)))),
                 "rays_span_deg": span, "placed": bool(std_mm <= 1e3 * PLACED_M)}
        if not entry["placed"]:
            entry["reason"] = (f"target {name}: the images see it from one direction (its rays span {span:.3g} deg on "
                               f"the tool): its position along them is determined only to {std_mm:.3g} mm (1 sigma); "
                               f"see it from directions that differ more (poses that turn the tool, or another "
                               f"camera), or give its position in the robot file")
        out.append(entry)
    return out


@one_blas_thread  # small dense algebra: more threads than one on a shared machine only contend
def fit_pixels(robot: Robot, model: ErrorModel, data: Pixels, cameras: dict[str, Camera], board: Board | None = None,
               loss: str = "cauchy", max_iter: int = 50, fixed_poses: np.ndarray | None = None,
               backend: str = "auto", noise_px: float | None = None, hold_weak: bool = True,
               intrinsics: bool = False, significance: bool = True,
               hold: tuple[int, ...] | None = None) -> PixelFit:
    """`_fit_pixels` (its docstring says what it does and what each option means), and then, as identify
    does for a tracker (`identify._plausible`), when the corners' noise is stated (noise_px) and the fit
    stands but gives a generalized error beyond a plausible size (`weak.largest`): the same images
    fitted again with the directions determined to within WIDEN times a plausible size held, in turn, as
    long as what holding them costs in residual is what the stated noise explains (`_costs_only_noise`);
    the fit with the fewest held that lowers the largest value most is returned, with a warning that
    says so, its held coefficients in `held` with why."""
    options = dict(loss=loss, max_iter=max_iter, fixed_poses=fixed_poses, backend=backend, hold_weak=hold_weak,
                   intrinsics=intrinsics, significance=significance, hold=hold)
    fit, notes = _noted(robot, model, data, cameras, board, noise_px, options)
    if hold_weak and hold is None and noise_px is not None and not fit.failures:
        cm = CompiledModel(frame_robot(robot), model, backend)
        size, where = weak.largest(cm, data, fit.c)
        best, best_size, best_notes = fit, size, notes
        for widen in WIDEN if size > 1.0 else ():
            held, held_notes = _noted(robot, model, data, cameras, board, noise_px * widen, options)
            if held.failures or not _costs_only_noise(fit, held, noise_px, fixed_poses is None):
                break
            after, _ = weak.largest(cm, data, held.c)
            if len(held.held) > len(fit.held) and after < best_size:
                best, best_size, best_notes = held, after, held_notes
            if best_size <= 1.0:
                break
        if best is not fit:
            fit, notes = best, [
                f"the fit gives {where} {size:.3g} times a plausible size ({1e3 * weak.PLAUSIBLE_M:g} mm, "
                f"{1e3 * weak.PLAUSIBLE_RAD:g} mrad) along directions the images determine only weakly: refitted with "
                f"those held ({best_size:.3g} times at most), the residual {fit.train['rms_px']:.4g} -> "
                f"{best.train['rms_px']:.4g} px rms, within the noise", *best_notes]
    for note in notes:
        warnings.warn(note, stacklevel=2)
    return fit


def _noted(robot, model, data, cameras, board, noise_px, options) -> tuple[PixelFit, list[str]]:
    """`_fit_pixels` and the warnings it gives, not yet warned: of the fits `fit_pixels` tries, only the
    one it returns speaks."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = _fit_pixels(robot, model, data, cameras, board, noise_px=noise_px, **options)
    return fit, [str(w.message) for w in caught]


def _rss(fit: PixelFit, free_g: bool) -> float:
    """The fit's weighted residual sum of squares (px^2), from its residual per coordinate and degrees of
    freedom (`_uncertainty`'s: the poses counted when fitted, free_g)."""
    unknowns = len(fit.kept) + (len(fit.g) if free_g else 0)
    return fit.sigma_px ** 2 * max(2 * float(fit.weights.sum()) - unknowns, 1.0)


def _costs_only_noise(full: PixelFit, held: PixelFit, noise_px: float, free_g: bool) -> bool:
    """Whether the held fit's larger residual is what the noise alone makes of the coefficients it holds:
    the rise in the weighted residual sum of squares within the identify.HOLD_P chi-square quantile, in
    units of the stated noise noise_px (px per coordinate; `identify._costs_only_noise` for a tracker)."""
    rise = _rss(held, free_g) - _rss(full, free_g)
    return rise / noise_px ** 2 <= noise_rise_limit(len(full.kept) - len(held.kept))


def _fit_pixels(robot: Robot, model: ErrorModel, data: Pixels, cameras: dict[str, Camera], board: Board | None = None,
                loss: str = "cauchy", max_iter: int = 50, fixed_poses: np.ndarray | None = None,
                backend: str = "auto", noise_px: float | None = None, hold_weak: bool = True,
                intrinsics: bool = False, significance: bool = True,
                hold: tuple[int, ...] | None = None) -> PixelFit:
    """Fit the coefficients of `model` and the cameras' (and board's) poses to image points (see the
    module docstring). fixed_poses: the geometric unknowns (rotation vectors and translations, in the
    order of the fit) held at these values instead of fitted (an oracle that knows the cameras).
    hold_weak (default): the coefficients whose direction the images determine too weakly against the
    noise to hold a plausible value (`fit.weak`, as identify does for a tracker; the cameras' poses
    projected out first) are held at zero, each listed in `PixelFit.held` with why; noise_px the
    corner noise per coordinate when known, else the linearised fit's residual (at most
    NOISE_CAP_PX). The steps are Levenberg-Marquardt steps in the determined coefficients and the poses,
    so the fit converges on what the images determine. intrinsics: each camera's fx, fy, cx, cy and
    distortion are refined in the same fit, from the camera file's values (`PixelFit.cameras`, with
    their std in `PixelFit.intrinsics_std`). significance (default): the coefficients the images do not
    determine (|value| / std below 2 after backward elimination, `significance.judge`) are held at zero
    and the rest refitted, each in eliminated (reason "insignificant"), as identify does by default.
    hold: these coefficients (indices) are held at zero (in eliminated, reason "given") and every other
    the images determine is fitted, neither held weak nor gated: a fit that holds what another fit held
    (its `held` and its gate's), e.g. an oracle given the cameras' poses compared like for like with the
    fit that found them (the coefficients that merge with the cameras' poses are the oracle's to fit)."""
    robust.check_loss(loss)
    problem, g, kept, eliminated = _set_up(robot, model, data, cameras, board, fixed_poses, backend, intrinsics)
    if hold is not None:
        names = model.coefficient_names(robot)
        eliminated = tuple(sorted([*eliminated, *(Eliminated(names[j], j, "given", "held at zero by the caller")
                                                  for j in kept if j in hold)], key=lambda x: x.index))
        kept, hold_weak, significance = [j for j in kept if j not in hold], False, False
    c = np.zeros(problem.cm.dims.nc)
    free_g = fixed_poses is None
    e = np.linalg.norm(problem.residual(g, c), axis=1)
    before = _summary(problem, g, c, e)

    limit = _limit(e, loss)
    held = ()
    determinable = len(kept)
    if hold_weak and kept:
        kept, held, eliminated = _with_held(problem, g, c, kept, eliminated, robust.weights(e, limit, loss), free_g,
                                            noise_px)
    def solve(g, c, cols, e, limit):
        """Levenberg-Marquardt over the poses (free_g) and c[cols], robustly reweighted."""
        lam, converged, it = 0.0, False, 0
        for it in range(1, max_iter + 1):
            wr = robust.weights(e, limit, loss)
            obj = robust.objective(e, limit, loss)
            A, b, scale = _system(problem, g, c, cols, wr, free_g)
            predicted = np.linalg.norm(A @ np.linalg.lstsq(A, -b, rcond=None)[0])
            if predicted / np.sqrt(len(b)) < STEP_TOL_PX and it > 1:
                converged = True  # a full step would change nothing a camera resolves
                break
            for _ in range(20):
                M = A.T @ A + lam * np.eye(A.shape[1])
                step = -np.linalg.solve(M, A.T @ b) / scale
                g_t = g + step[:problem.n_geom] if free_g else g
                c_t = c.copy()
                c_t[cols] += step[problem.n_geom:] if free_g else step
                e_t = np.linalg.norm(problem.residual(g_t, c_t), axis=1)
                obj_t = robust.objective(e_t, limit, loss)
                if np.isfinite(obj_t) and obj_t <= obj:
                    break
                lam = 1e-6 if lam == 0 else 10 * lam
            else:
                break
            g, c, e, lam = g_t, c_t, e_t, lam / 10 if lam > 1e-9 else 0.0
            new_limit = _limit(e, loss)
            settled = loss == "l2" or abs(new_limit - limit) <= 0.01 * limit
            limit = new_limit
            if settled and obj - obj_t <= RSS_TOL * max(obj, 1e-30):
                converged = True
                break
        return g, c, e, limit, converged, it

    cols = np.array(kept, int)
    g, c, e, limit, converged, it = solve(g, c, cols, e, limit)
    insignificant, ungated = {}, None
    if significance and converged and len(cols):
        # the significance gate of tracker data (`significance.judge`), the poses' unknowns counted out of
        # the degrees of freedom and their uncertainty carried in the coefficients' covariance
        wr = robust.weights(e, limit, loss)
        std, cov, sigma, _ = _uncertainty(problem, g, c, cols, wr, free_g)
        names = model.coefficient_names(robot)
        _, insignificant = judge(names, c, std, cols, cov, sigma, 2 * float(wr.sum()) - (problem.n_geom if free_g else 0))
        if insignificant:
            ungated = (c, cols, cov)
            cols = np.array([j for j in cols if j not in insignificant], int)
            c = c.copy()
            c[list(insignificant)] = 0.0
            e = np.linalg.norm(problem.residual(g, c), axis=1)
            g, c, e, limit, converged, it = solve(g, c, cols, e, _limit(e, loss))
            eliminated = tuple(sorted([*eliminated, *(Eliminated(names[j], j, "insignificant", why)
                                                      for j, why in insignificant.items())], key=lambda x: x.index))
    kept = [int(j) for j in cols]
    if len(kept) < determinable:
        left = [h.param for h in held] + [model.coefficient_names(robot)[j] for j in insignificant]
        warnings.warn(f"the images determine {len(kept)} of the {determinable} coefficients the model can have "
                      f"({', '.join(left[:6])}{', ...' if len(left) > 6 else ''} held at zero: `held` and "
                      f"`eliminated` say why): the calibration corrects only what "
                      f"{'that one carries' if len(kept) == 1 else f'those {len(kept)} carry'}; more "
                      f"poses, targets or cameras determine more", stacklevel=2)
    wr = robust.weights(e, limit, loss)
    std, cov, sigma, std_g = _uncertainty(problem, g, c, cols, wr, free_g)
    scale = _scale(problem, c, cols, cov, ungated)
    flagged = np.nonzero(e > limit)[0]
    d = data
    outliers = tuple(Outlier(int(d.row[r]), int(d.pose_ids[d.pose[r]]), d.cameras[d.camera[r]], d.points[d.point[r]],
                             float(e[r]), float(wr[r])) for r in flagged[np.argsort(-e[flagged])])
    failures = [] if converged else [f"Gauss-Newton did not converge in {it} iterations ({np.sqrt(np.mean(e ** 2)):.3g} "
                                     f"px rms left): the images may not determine this model (fewer terms, e.g. "
                                     f"--errors with constant errors, or more images), or the camera file is not "
                                     f"this camera's"]
    smaller = _smaller_images(data, cameras)
    if smaller and not converged:
        failures[0] += f" ({smaller})"
    elif smaller and np.sqrt(np.mean(e ** 2)) > NOISE_CAP_PX:  # converged on what no corner detector leaves
        failures.append(f"{np.sqrt(np.mean(e ** 2)):.3g} px rms left after the fit, more than corners are found to "
                        f"({NOISE_CAP_PX:g} px): {smaller}")
    poses, board_pose, targets = problem.unpack(g)
    inliers = e <= limit
    train = _summary(problem, g, c, e) | {
        "rms_px_inliers": float(np.sqrt(np.mean(e[inliers] ** 2))) if inliers.any() else np.nan}
    if not np.isfinite(e).all():
        failures.append("a point lies behind its camera after the fit; check the camera file's mount and the data")
    names = [f"q{i + 1}" for i in range(robot.n)] + list(WRENCH) + list(model.aux)
    values = np.column_stack([d.q, d.w, *(() if problem.inputs[2] is None else (problem.inputs[2],))])
    ranges = {n: [float(v.min()), float(v.max())] for n, v in zip(names, values.T)}
    if free_g and converged and np.isfinite(e).all():
        for target in _placed_along_rays(problem, g, c, kept, noise_px):
            if not target["placed"]:
                warnings.warn(f"{target['reason']}; the calibration places it where the fit put it", stacklevel=2)
    refined = problem.cameras_of(g)
    intrinsics_std = {}
    if intrinsics and free_g:
        for i, cam in enumerate(cameras[n] for n in d.cameras):
            v = std_g[problem.n_poses_geom + N_INTRINSICS * i:problem.n_poses_geom + N_INTRINSICS * (i + 1)]
            intrinsics_std[cam.name] = dict(zip(INTRINSICS, [*(cam.fx * v[:4]), *v[4:]]))
        for name, spread in intrinsics_std.items():
            loose = [k for k, v in spread.items() if not v * _px_per_unit(cameras[name], k) <= INTRINSICS_PX]
            if loose:
                warnings.warn(f"camera {name}: the images determine {', '.join(loose)} only to more than "
                              f"{INTRINSICS_PX:g} px at the image's corner (1 sigma; JSON intrinsics std): their "
                              f"refined values are not the camera's; keep the camera file's (leave out "
                              f"--refine-intrinsics, or refine them from board images that fill the frame)",
                              stacklevel=2)
    return PixelFit(c, dict(zip(d.cameras, poses)), board_pose, targets, tuple(kept), eliminated, before, train,
                    outliers, it, converged, loss, tuple(failures), std, cov, sigma, ranges, held, scale,
                    {cam.name: cam for cam in refined} if intrinsics else None, intrinsics_std or None,
                    np.column_stack([e, at_target_mm(problem, g, c, e)[0]]), g, wr)


def _smaller_images(data: Pixels, cameras: dict[str, Camera]) -> str:
    """What the points say of a camera file made for larger images than these (intrinsics of another
    resolution: every point then lies in the top-left quarter of the image the file states, where the
    pixel file's own rows cannot be refused as outside it), in words; "" when nothing."""
    for k, name in enumerate(data.cameras):
        cam, uv = cameras[name], data.uv[data.camera == k]
        if len(uv) and uv[:, 0].max() < cam.width / 2 and uv[:, 1].max() < cam.height / 2:
            return (f"camera {name}: every point lies in the top-left quarter of the {cam.width} x {cam.height} "
                    f"image its intrinsics are for (u < {uv[:, 0].max():.0f}, v < {uv[:, 1].max():.0f}): intrinsics "
                    f"of a larger resolution? give the camera's at the images' size, or scale fx fy cx cy by it")
    return ""


@dataclass(frozen=True)
class Linearised:
    """A pixel fit's weighted least squares at its solution, what diagnose screens candidate effects
    in: rows (u, v) of every image point in the data's order, each scaled by the root of its robust
    weight. A (2R, n) the residual's derivative in the fitted poses and the kept coefficients; r (2R,)
    the residual (px); J (2R, ne) its derivative in the generalized errors, from which a new term t
    on error e adds the column J[:, e] t(pose); mm_per_px what a pixel means at the points (the
    median over them of depth over focal length, `at_target_mm`)."""

    A: np.ndarray
    r: np.ndarray
    J: np.ndarray
    mm_per_px: float


def linearised(cm: CompiledModel, robot: Robot, data: Pixels, cameras: dict[str, Camera], board: Board | None,
               fit: PixelFit) -> Linearised:
    """The `Linearised` system of `fit` (fit_pixels of cm's model on data with `cameras`, its columns
    the refined intrinsics' too when it refined them); cm: the compiled model of `frame_robot(robot)`
    and that model."""
    problem = _Problem(cm, robot, data, cameras, board, fit.cameras is not None)
    cols = np.array(fit.kept, int)
    g, c = fit.g, fit.c
    r, A = problem.jacobian(g, c, cols)
    q, w, aux = problem.inputs
    _, Je = cm.J_e(q, cm.eps(q, w, aux, c))
    o, R, _ = problem.frames(c)
    _, P = problem.project(problem.camera_points(g, o, R), g, jacobian=True)
    D = Je.reshape(len(q), problem.n_branches, 4, 3, -1)[problem.at]
    J = -np.einsum("rij,rjc->ric", P, problem.point_derivative(g, o, R, D)).reshape(2 * len(r), -1)
    root = np.repeat(np.sqrt(fit.weights), 2)
    return Linearised(A * root[:, None], r.ravel() * root, J * root[:, None],
                      float(np.median(at_target_mm(problem, g, c, np.ones(len(r)))[0])))


def _system(problem: _Problem, g: np.ndarray, c: np.ndarray, cols: np.ndarray, wr: np.ndarray, free_g: bool):
    """The weighted least squares at poses g and coefficients c: its Jacobian A (2R, n) in the poses
    (when free_g) and c[cols], each column scaled to unit norm, the residual b (2R,) px and the
    scales (n,); wr (R,) the image points' robust weights."""
    r, J = problem.jacobian(g, c, cols)
    if not free_g:
        J = J[:, problem.n_geom:]
    root = np.repeat(np.sqrt(wr), 2)
    A, b = J * root[:, None], r.ravel() * root
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    return A / scale, b, scale


def _px_per_unit(cam: Camera, name: str) -> float:
    """How far (px) a unit change of intrinsic `name` moves a point at the image's corner, to first
    order: the corner's normalised x or y for a focal length, 1 for the principal point, f r^(2i+1)
    for the radial coefficients, about 3 f r^2 for the tangential ones (r the corner's normalised
    radius)."""
    r = float(np.hypot(cam.width / 2, cam.height / 2)) / cam.fx
    return {"fx": cam.width / 2 / cam.fx, "fy": cam.height / 2 / cam.fy, "cx": 1.0, "cy": 1.0,
            "k1": cam.fx * r ** 3, "k2": cam.fx * r ** 5,
            "k3": cam.fx * r ** 7, "p1": 3 * cam.fx * r ** 2, "p2": 3 * cam.fx * r ** 2}[name]


def _hold_weak(problem: _Problem, g: np.ndarray, c: np.ndarray, kept: list[int], wr: np.ndarray, free_g: bool,
               noise_px: float | None) -> tuple[list[int], tuple[weak.Held, ...]]:
    """The coefficients of kept the images determine against the noise and those held (`weak.hold`),
    with the poses' columns projected out: the R factor's block below them is that of the
    coefficients' columns after the poses have taken what they can."""
    A, b, scale = _system(problem, g, c, np.array(kept, int), wr, free_g)
    k0 = A.shape[1] - len(kept)
    R = np.linalg.qr(np.column_stack([A, b]), mode="r")[k0:, k0:]
    stay, held = weak.hold(problem.cm, problem.data, kept, R, scale[k0:], 2 * float(wr.sum()) - k0, noise_px,
                           NOISE_CAP_PX)
    return [kept[i] for i in stay], held


def _scale(problem: _Problem, c: np.ndarray, cols: np.ndarray, cov: np.ndarray,
           ungated: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> dict:
    """How well the fit fixes the scale of the robot it calibrates: the 1-sigma of the relative scale of
    the tool origins it predicts at the training poses (`std_ppm`; the scale of a similarity fit of them
    onto the truth's, the rest rigid) and what that moves them by, RMS about their centre (`std_mm`),
    from the covariance cov of c[cols]. Pixels fix a length only through a known one (the markers'
    spacing, the board's square), seen from afar only weakly; a similarity fit's scale of small
    perturbations dp (P, 3) is sum(r . dp) / sum(|r|^2), r the positions about their centre, so its
    variance is a^T cov a with a that sum's gradient in the coefficients.
    ungated: (c, cols, cov) of the fit before the significance gate held coefficients at zero. Holding
    them moves the scale by what they truly are, which the gated covariance (given their zeros) leaves
    out and the ungated one does not know: the 1-sigma is then the ungated one and the move the gate
    made (`gate_ppm`) in quadrature. For a linear fit holding a set chosen in advance, its mean square
    exceeds the gated error's by twice the variance the gate removed; the ungated 1-sigma alone falls
    short of the gated error by what the held coefficients truly carry (tests/test_camera.py).
    Without the gate `gate_ppm` is 0."""
    c0, cols, cov = (c, cols, cov) if ungated is None else ungated
    o, _, H = problem.frames(c, with_H=True)
    o, H = o.reshape(-1, 3), H[:, :, 0].reshape(len(o) * problem.n_branches, 3, -1)  # every branch's tool
    r = o - o.mean(axis=0)
    a = np.einsum("pi,pik->k", r, H[..., cols]) / float(np.sum(r ** 2))
    moved = float(a @ (c - c0)[cols])
    with np.errstate(invalid="ignore"):
        std = float(np.sqrt(a @ cov @ a + moved ** 2)) if len(cols) else 0.0
    return {"std_ppm": 1e6 * std, "std_mm": 1e3 * std * float(np.sqrt(np.mean(np.sum(r ** 2, axis=1)))),
            "gate_ppm": 1e6 * moved}


def _uncertainty(problem: _Problem, g: np.ndarray, c: np.ndarray, cols: np.ndarray, wr: np.ndarray, free_g: bool):
    """std (nc,) of the coefficients (NaN where not fitted), their covariance (k, k) with the poses'
    uncertainty carried in, the residual sigma (px per coordinate, points counted by weight) and the
    std of the geometric unknowns (n_geom,) in their units (empty when they are given)."""
    A, b, scale = _system(problem, g, c, cols, wr, free_g)
    dof = max(2 * float(wr.sum()) - A.shape[1], 1.0)
    sigma = float(np.sqrt(b @ b / dof))
    with np.errstate(all="ignore"):
        try:
            full = sigma ** 2 * np.linalg.inv(A.T @ A) / np.outer(scale, scale)
        except np.linalg.LinAlgError:
            full = np.full((A.shape[1],) * 2, np.inf)
    k0 = A.shape[1] - len(cols)
    cov = full[k0:, k0:]
    std = np.full(problem.cm.dims.nc, np.nan)
    std[cols] = np.sqrt(np.abs(np.diag(cov)))
    return std, cov, sigma, np.sqrt(np.abs(np.diag(full)[:k0]))


def calibration_of(robot: Robot, model: ErrorModel, fit: PixelFit, cameras: dict[str, Camera], board: Board | None):
    """The calibration of a pixel fit (`fit.calibration.Calibration`): coefficients in the robot's
    world (the cameras' or the board's poses are in it, in `report`, with the board's geometry and each
    camera's intrinsics as the fit used them: `cameras` and `board`, the files given to it, or the
    intrinsics as refined). Targets the robot file leaves to estimate are placed where the fit put
    them; on a carried camera, at its optical centre."""
    from gecgen.fit.calibration import Calibration
    from gecgen.fit.placement import with_targets
    from gecgen.fit.registration import IDENTITY

    placed = {n: tuple(map(float, t)) for n, t in fit.targets.items()}
    if fit.board is not None:
        centre = tuple(map(float, fit.tool_camera()[1]))
        placed |= {n: centre for n in robot.estimated}
    robot = with_targets(robot, placed)
    report = {"n_params": len(fit.c), "n_identifiable": len(fit.kept), "n_carried": len(fit.kept),
              "eliminated": [e.to_dict() for e in fit.eliminated], "before": fit.before, "train": fit.train,
              "sigma_px": fit.sigma_px, "iterations": fit.iterations, "converged": fit.converged,
              "loss": fit.loss, "outliers": [o.to_dict() for o in fit.outliers], "measurement": "pixels",
              "training_ranges": fit.ranges, "held": [h.to_dict() for h in fit.held], "scale": fit.scale,
              "cameras": {n: {"rotation": R.tolist(), "translation": t.tolist()} for n, (R, t) in fit.poses.items()},
              **({"intrinsics": intrinsics_report(fit)} if fit.cameras else {}),
              **({"board": {"rotation": fit.board[0].tolist(), "translation": fit.board[1].tolist()}}
                 if fit.board is not None else {}),
              "camera_intrinsics": {n: _intrinsics((fit.cameras or {}).get(n, cameras[n])) for n in fit.poses},
              **({"board_geometry": _geometry(board)} if board is not None else {})}
    return Calibration(robot, model, fit.c, fit.std, fit.kept, fit.cov, IDENTITY, report)


#: the keys of a board's geometry a pixel calibration records, with their unit, as the board file names them
BOARD_KEYS = {"type": "", "columns": "", "rows": "", "square": " m", "marker": " m", "dictionary": ""}
#: the keys of a camera's intrinsics a pixel calibration records, with their unit, as the camera file names them
CAMERA_KEYS = {"fx": " px", "fy": " px", "cx": " px", "cy": " px", "distortion": "", "width": " px", "height": " px"}
#: the intrinsics --refine-intrinsics fits (a camera file may differ from the calibration in these)
REFINED_KEYS = ("fx", "fy", "cx", "cy", "distortion")
#: a number in a board or camera file is the calibration's when within this relative difference (or 1e-9
#: absolute, for distortion near zero): what a value copied with fewer digits differs by
SAME = 1e-6


def _geometry(board: Board) -> dict:
    """The board's geometry as its file gives it (`BOARD_KEYS`; marker and dictionary on a ChArUco board)."""
    out = {"type": board.kind, "columns": board.columns, "rows": board.rows, "square": board.square}
    return out | ({"marker": board.marker, "dictionary": board.dictionary} if board.kind == "charuco" else {})


def _intrinsics(cam: Camera) -> dict:
    """The camera's intrinsics and image size as its file gives them (`CAMERA_KEYS`)."""
    return {"fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "distortion": list(cam.distortion),
            "width": cam.width, "height": cam.height}


def _differing(given: dict, recorded, where: str, keys: dict) -> str | None:
    """The first key of `recorded` (a calibration's record, read from `where`, of some of `keys`) whose
    value `given` lacks or differs from beyond `SAME`, None when none does; a record that is not a
    mapping of `keys` to numbers, strings or lists of numbers is refused."""
    ok = isinstance(recorded, dict) and set(recorded) <= set(keys)
    require(ok and all(isinstance(v, (str, int, float)) or isinstance(v, list) and all(isinstance(x, (int, float))
                                                                                     for x in v)
                       for v in recorded.values()),
            f"{where}: the board's or cameras' record is not one gecgen writes ({', '.join(keys)}); identify again")
    for key in (k for k in keys if k in recorded):
        value, mine = recorded[key], given.get(key)
        if isinstance(value, str) or not isinstance(mine, (int, float, list)):
            if value != mine:
                return key
            continue
        a, b = np.asarray(mine, float), np.asarray(value, float)
        if a.shape != b.shape or not np.allclose(a, b, rtol=SAME, atol=1e-9):
            return key
    return None


def _shown(value, unit: str) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(f"{v:g}" for v in value) + "]"
    return f"{value:g}{unit}" if isinstance(value, (int, float)) else str(value)


def refuse_another_rig(calibration, where: str, cameras: dict[str, Camera], cameras_file: str, board: Board | None):
    """Refuse (one line naming the file, the key and the fix) a board file or a camera file whose values
    differ from those the pixel calibration (read from `where`) recorded: its board's geometry, and each
    camera's intrinsics and image size, but for the intrinsics it refined (it scores with those). A
    calibration written before these were recorded is not checked."""
    report = calibration.report
    recorded = report.get("board_geometry")
    if board is not None and recorded is not None:
        given = _geometry(board)
        key = _differing(given, recorded, f"{where}: board_geometry", BOARD_KEYS)
        unit = BOARD_KEYS.get(key, "")
        require(key is None, f"{board.source}, key '{key}': {_shown(given.get(key, 'none'), unit)} against the "
                             f"calibration's {_shown(recorded.get(key), unit)} ({where}); give the board file the "
                             f"calibration was made with, or identify again with this board")
    recorded = report.get("camera_intrinsics") or {}
    require(isinstance(recorded, dict), f"{where}: camera_intrinsics is not one gecgen writes; identify again")
    refined = report.get("intrinsics") or {}
    for name in sorted(set(recorded) & set(cameras)):
        given, record = _intrinsics(cameras[name]), recorded[name]
        if name in refined and isinstance(record, dict):  # scored with the refined values: the image size counts
            record = {k: v for k, v in record.items() if k not in REFINED_KEYS}
        key = _differing(given, record, f"{where}: camera_intrinsics.{name}", CAMERA_KEYS)
        unit = CAMERA_KEYS.get(key, "")
        require(key is None, f"{cameras_file}, camera '{name}', key '{key}': {_shown(given.get(key), unit)} against "
                             f"the calibration's {_shown(record.get(key), unit)} ({where}); give the camera file the "
                             f"calibration was made with, or identify again with this one")


def score_pixels(calibration, where: str, data: Pixels, cameras: dict[str, Camera],
                 board: Board | None = None) -> dict:
    """Held-out image points scored by a pixel calibration (`calibration_of`, read from `where`), with
    the cameras' (and board's) poses and refined intrinsics it fitted, none fitted again (the cameras
    must not have moved): `before` (the nominal model) and `after` (the calibrated one), each as identify's
    `_summary` states a residual (px, and mm at the target)."""
    problem, g = recorded_problem(calibration, where, data, cameras, board)
    return {stage: summary_of(problem, g, c) for stage, c in (("before", np.zeros(problem.cm.dims.nc)),
                                                              ("after", calibration.c))}


def recorded_problem(calibration, where: str, data: Pixels, cameras: dict[str, Camera], board: Board | None):
    """The residual problem of `data` seen through a pixel calibration (read from `where`) as it recorded
    its set-up, and its cameras' (and board's) fitted poses g (`PixelFit.g`'s order): its refined
    intrinsics where it refined them, the camera files' otherwise. A tracker calibration, a camera it did
    not fit or another mount is refused in one line."""
    report = calibration.report
    require(report.get("measurement") == "pixels", f"{where}: a calibration from tracker points; "
                                                   f"score tracker measurements with it (leave out --cameras)")
    fitted = report["cameras"]
    unknown = [n for n in data.cameras if n not in fitted]
    require(not unknown, f"{data.source}: camera {unknown[0] if unknown else ''} is not one the calibration fitted "
                         f"({', '.join(fitted)}); score the images of its cameras only")
    require((data.mount == "tool") == ("board" in report),
            f"{data.source}: the calibration's camera was {'on the tool' if 'board' in report else 'fixed'}, these "
            f"images' are not; score images of the same set-up")
    refined = report.get("intrinsics") or {}
    cams = {n: replace(cam, fx=refined[n]["fx"], fy=refined[n]["fy"], cx=refined[n]["cx"], cy=refined[n]["cy"],
                       distortion=tuple(refined[n]["distortion"])) if n in refined else cam
            for n, cam in cameras.items()}
    cm = CompiledModel(frame_robot(calibration.robot), calibration.model)
    poses = [fitted[n] for n in data.cameras] + ([report["board"]] if data.mount == "tool" else [])
    g = np.concatenate([[*Rotation.from_matrix(np.array(p["rotation"])).as_rotvec(), *p["translation"]]
                        for p in poses])
    return _Problem(cm, calibration.robot, data, cams, board), g


def refit_pose(problem: _Problem, g: np.ndarray, c: np.ndarray, block: int, rows: np.ndarray) -> np.ndarray:
    """g with its pose `block` (6 unknowns from 6 * block: a camera's, in data.cameras' order, or the
    board's after them) refitted to the image points `rows` (R,) by least squares, the coefficients c
    and every other pose held: where a camera (or board) is now if it moved and the robot did not."""
    from scipy.optimize import least_squares

    o, R, _ = problem.frames(c)

    def residual(x):
        h = g.copy()
        h[6 * block:6 * block + 6] = x
        return (problem.data.uv - problem.project(problem.camera_points(h, o, R), h))[rows].ravel()

    out = g.copy()
    out[6 * block:6 * block + 6] = least_squares(residual, g[6 * block:6 * block + 6], method="lm", x_scale="jac").x
    return out


def summary_at(cm: CompiledModel, robot: Robot, data: Pixels, cameras: dict[str, Camera], board: Board | None,
               g: np.ndarray, c: np.ndarray, intrinsics: bool = False) -> dict:
    """The residual of image points at the poses g (`PixelFit.g`, none fitted) and coefficients c (nc,),
    as `_summary` states it (px, and mm at the target); cm: the compiled model of `frame_robot(robot)`;
    intrinsics: g holds the cameras' refined intrinsics too (`cameras` those the fit was given)."""
    return summary_of(_Problem(cm, robot, data, cameras, board, intrinsics), g, c)


def summary_of(problem: _Problem, g: np.ndarray, c: np.ndarray) -> dict:
    """The residual of the problem's image points at poses g and coefficients c, as `_summary` states it."""
    return _summary(problem, g, c, np.linalg.norm(problem.residual(g, c), axis=1))


def intrinsics_report(fit: PixelFit) -> dict:
    """Per camera its refined intrinsics (fx, fy, cx, cy px; distortion [k1, k2, p1, p2, k3]) and their
    1-sigma (`std`), as the camera file and OpenCV write them."""
    return {n: {**{k: v for k, v in _intrinsics(c).items() if k in REFINED_KEYS},
                **({"std": fit.intrinsics_std[n]} if fit.intrinsics_std else {})} for n, c in fit.cameras.items()}


def refuse_untrustworthy(fit: PixelFit, where: str):
    """A fit with failures is refused with the first one."""
    if fit.failures:
        raise ModelError(f"{where}: {fit.failures[0]}")


def fitted_tools(robot: Robot, model: ErrorModel, c: np.ndarray, q: np.ndarray, w: np.ndarray | None = None,
                 aux: np.ndarray | None = None, backend: str = "auto", branch: int = 0) -> np.ndarray:
    """(N, 4, 4) the tool poses the model with coefficients c (nc,) gives at joints q (N, n); on a tree,
    the tool's of branch `branch`."""
    cm = CompiledModel(frame_robot(robot), model, backend)
    p = cm.model_targets(q, w, aux, c)[:, 4 * branch:4 * branch + 4]
    T = np.zeros((len(p), 4, 4))
    T[:, :3, :3] = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], -1) / FRAME_ARM
    T[:, :3, 3], T[:, 3, 3] = p[:, 0], 1.0
    return T


def image_covariance(problem: _Problem, g: np.ndarray, c: np.ndarray, cols: np.ndarray, loss: str,
                     with_poses: bool = False) -> np.ndarray:
    """The covariance (k, k) of c[cols] fitted with the poses g to the problem's image points, taken image
    by image (the sandwich A^-1 (sum_p a_p a_p^T) A^-1, a_p the gradient of image p's rows, scaled by
    P / (P - n) for P images and n unknowns: `fit.significance.clustered_covariance`, as
    `verify.volume.pose_covariance` takes a tracker's: the points of one image share the robot's misfit at
    its pose and are not independent. with_poses: the covariance (len(g) + k, len(g) + k) of g and c[cols]
    together, in that order."""
    e = np.linalg.norm(problem.residual(g, c), axis=1)
    A, b, scale = _system(problem, g, c, cols, robust.weights(e, _limit(e, loss), loss), True)
    n = A.shape[1]
    full = clustered_covariance(A, b, np.repeat(problem.data.pose, 2), problem.data.n_poses) / np.outer(scale, scale)
    return full if with_poses else full[n - len(cols):, n - len(cols):]


def pose_uncertainty(robot: Robot, model: ErrorModel, data: Pixels, cameras: dict[str, Camera], board: Board | None,
                     fit: PixelFit) -> dict:
    """How well the images fix the cameras' poses, 1 sigma, from the covariance of the fit taken image by image
    (`image_covariance`: the points of one image share its pose's misfit, and taking them for independent
    understates the spread), linearised at the fit (central differences). A camera on the tool: its pose in the
    tool frame as the calibration carries it, the mean over the training poses of where the calibrated model
    and the fitted board put the camera, seen from the fitted tool frame (the camera's own pose unknowns trade
    with the coefficients of the frames before it, which move the tool frame alike; what a user of the
    camera-to-flange transform gets is the two together). Fixed cameras: each after the first, its pose in the
    first camera's frame (their poses against the robot's base carry what the images leave of the base's
    errors). Per camera: `relative_to` (`tool` or the first camera), the translation's and rotation's RMS
    length (`translation_mm`, `rotation_mrad`: the root of the covariance's trace, the distance and angle the
    pose is expected to be off by) and per axis of that frame (`axes_mm`, `axes_mrad`)."""
    problem = _Problem(CompiledModel(frame_robot(robot), model), robot, data, cameras, board, fit.cameras is not None)
    cols = np.array(fit.kept, int)
    cov = image_covariance(problem, fit.g, fit.c, cols, fit.loss, with_poses=True)
    names = list(data.cameras)
    o0, R0, _ = problem.frames(fit.c)

    def placed(g: np.ndarray, c: np.ndarray, k: int) -> np.ndarray:
        """Camera k's orientation (P, 3, 3) and centre (P, 3, 1), per training pose, in its reference frame."""
        (R, t), (R1, t1) = (problem.unpack(g)[0][i] for i in (k, 0))
        if not problem.tool:
            return np.concatenate([R1 @ R.T, (t1 - R1 @ R.T @ t)[:, None]], axis=1)[None]
        o, Rt, _ = problem.frames(c)
        (Rb, tb), (Rb0, tb0) = problem.unpack(g)[1], problem.unpack(fit.g)[1]
        # the camera in the world of g's board, then in the fit's world and the fit's tool frame, pose by pose
        Rw = Rb0 @ Rb.T @ Rt[:, 0] @ R.T
        pw = (Rt[:, 0] @ (-R.T @ t) + o[:, 0] - tb) @ Rb @ Rb0.T + tb0
        into = np.swapaxes(R0[:, 0], 1, 2)
        return np.concatenate([into @ Rw, (into @ (pw - o0[:, 0])[..., None])], axis=2)

    # the unknowns that move a camera: the poses (and the board's), and on a camera on the tool the coefficients
    moving = list(range(6 * len(names) + 6)) if problem.tool else list(range(6 * len(names)))
    out = {}
    for k in range(len(names)) if problem.tool else range(1, len(names)):
        P0 = placed(fit.g, fit.c, k)
        J = np.zeros((6, len(cov)))
        for j in [*moving, *(range(len(fit.g), len(cov)) if problem.tool else ())]:
            dg, dc = np.zeros(len(fit.g)), np.zeros(len(fit.c))
            if j < len(fit.g):
                dg[j] = STEP
            else:
                dc[cols[j - len(fit.g)]] = STEP
            dP = (placed(fit.g + dg, fit.c + dc, k) - placed(fit.g - dg, fit.c - dc, k)) / (2 * STEP)
            W = np.mean(dP[..., :3] @ np.swapaxes(P0[..., :3], 1, 2), axis=0)  # skew: the turn in that frame
            J[:3, j] = [W[2, 1], W[0, 2], W[1, 0]]
            J[3:, j] = np.mean(dP[..., 3], axis=0)
        spread = J @ cov @ J.T
        axes = np.sqrt(np.abs(np.diag(spread)))
        out[names[k]] = {"relative_to": "tool" if problem.tool else names[0],
                         "translation_mm": 1e3 * float(np.sqrt(abs(np.trace(spread[3:, 3:])))),
                         "rotation_mrad": 1e3 * float(np.sqrt(abs(np.trace(spread[:3, :3])))),
                         "axes_mm": (1e3 * axes[3:]).tolist(), "axes_mrad": (1e3 * axes[:3]).tolist()}
    return {"covariance": "image by image", "cameras": out}
