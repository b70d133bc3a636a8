"""Designs for calibration from a camera: which poses to take images at (`gecgen design --cameras`).

A pose is worth an image only if the camera sees what it must: eye-in-hand (a camera on the tool),
every corner of the board fixed in the world; eye-to-hand (fixed cameras), every marker on the
robot, in every camera. So the candidates (poses drawn about a home posture, or the rows of a
file) are first kept to those where, on the nominal robot and the rig's poses of the cameras (and
board), every point of every camera

* projects inside its image at least `margin_px` from the edge (field of view),
* lies at a depth along the optical axis within `distance_m` (in focus), and
* faces the camera: the angle between the line of sight and the board's printed face (its -z in the
  board frame, OpenCV's) is at most `max_angle_deg`; markers are taken to lie on a plate across their
  tool's z axis, their angle the line of sight's to that axis on either side, checked only when a
  limit is given (which way a marker faces is not in the robot file).

Among those, the design is D- (or I-) optimal for the pixel fit (`fit.camera`): its Jacobian in the
cameras' (and board's) poses and in the coefficients the images determine, at the nominal model
(`fit.camera.design_rows`). The fit estimates both together, so the information is that of all
of them, M = sum_p J_p^T J_p, which adds up over poses as the tracker design's does and is searched by
the same code (`design.choose`: greedy start, Fedorov exchange, whitened coordinates). A pose's block
J_p has 2 rows per point but its rank is at most six per camera (the pixels move only with the
camera's pose relative to the board or the tool): each block is replaced by its leading singular rows,
which carry the same information at a fraction of the search's cost.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.cameras import Board, Camera
from gecgen.model.errors import ErrorModel
from gecgen.model.kinematics import tool_poses
from gecgen.model.pixels import Pixels
from gecgen.model.robot import Robot
from gecgen.model.validation import ModelError, require
from gecgen.plan.design import CRITERIA, MAX_PASSES, N_VALIDATION, RIDGE, _Basis, _finite, choose, predicted_std, \
    reported_history, scores
from gecgen.runtime.threads import one_blas_thread

#: px: every point at least this far inside the image: a corner detector needs the pattern around it, and
#: the rig is known roughly (0.5 deg and 10 mm move a corner about 30 px at 0.7 m for a 1400 px focal length)
MARGIN_PX = 40.0
#: deg: the largest angle between the line of sight and the board's face (corners blur and bunch beyond)
MAX_ANGLE_DEG = 60.0
#: m: the depths along the optical axis a camera is taken to focus on
DISTANCE_M = (0.2, 3.0)
#: px: the corners' noise per coordinate the predicted figures assume
NOISE_PX = 0.2
#: rad (m for a prismatic joint): the half-span about --home the candidate poses are drawn in
SPAN = 0.5
#: candidates the Jacobian is computed for at most (a seeded sample of more)
MAX_CANDIDATES = 2000
#: poses drawn about --home by default: the view keeps a few per cent of them for a camera on the tool
SAMPLED = 20_000
#: poses of the candidates whose Jacobian is computed at once, and of the sample whose rank decides
#: the coefficients the images determine
BLOCK = 200
#: a block's singular values below this share of the largest of all are rounding: the fit's pose columns are
#: central differences, good to about 1e-9 relative, and a block's rank (6 per camera) stands out by far more
RANK_TOL = 1e-6


@dataclass(frozen=True)
class Rig:
    """The set-up a design plans for: the cameras, each with its pose (R, t), X_cam = R X + t (X in the
    world for a fixed camera, in the tool frame for the carried one); eye-in-hand, the board and its
    pose in the world (X_world = R x_board + t). Limits: margin_px, max_angle_deg (None: markers'
    angle unchecked), distance_m (near, far)."""

    cameras: dict[str, Camera]
    poses: dict[str, tuple[np.ndarray, np.ndarray]]
    board: Board | None = None
    board_pose: tuple[np.ndarray, np.ndarray] | None = None
    margin_px: float = MARGIN_PX
    max_angle_deg: float | None = MAX_ANGLE_DEG
    distance_m: tuple[float, float] = DISTANCE_M

    @property
    def tool(self) -> bool:
        return self.board is not None

    @property
    def what(self) -> str:
        return "board corner" if self.tool else "marker"


def in_camera(robot: Robot, rig: Rig, q: np.ndarray, camera: str) -> tuple[np.ndarray, np.ndarray]:
    """Every point (the board's corners, or the robot's targets) in `camera`'s frame at the joints q
    (K, n) of the nominal robot, (K, npts, 3) m, and the direction (K, npts, 3) each faces, in that frame
    (the board's printed face, -z of its frame; a marker's tool z axis, its plate's normal)."""
    R, t = rig.poses[camera]
    tools = tool_poses(robot, q)
    if rig.tool:
        Rb, tb = rig.board_pose
        Rt, ot = tools[0][:, :3, :3], tools[0][:, :3, 3]
        # world -> camera: x_cam = R Rt^T (x_w - o) + t
        A = np.einsum("ij,klj->kil", R, Rt)  # (K, 3, 3): R Rt^T
        Xw = rig.board.corners @ Rb.T + tb
        X = np.einsum("kij,kpj->kpi", A, Xw[None] - ot[:, None]) + t
        face = np.broadcast_to(np.einsum("kij,j->ki", A, -Rb[:, 2])[:, None], X.shape)
        return X, face
    names = list(robot.targets)
    T = np.stack([tools[robot.branch_of(n)] for n in names], axis=1)  # (K, npts, 4, 4)
    local = np.array([robot.targets[n] for n in names], float)
    Xw = np.einsum("kpij,pj->kpi", T[..., :3, :3], local) + T[..., :3, 3]
    return Xw @ R.T + t, T[..., :3, 2] @ R.T


def view_checks(robot: Robot, rig: Rig, q: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """Per camera, which of the candidates q (K, n) pass each check (K,) bool: `field of view` (every
    point inside the image by the margin), `angle` (every point seen within the largest angle), `distance`
    (every point's depth within the range)."""
    out = {}
    for name, cam in rig.cameras.items():
        X, face = in_camera(robot, rig, q, name)
        K, npts = X.shape[:2]
        uv = cam.project(X.reshape(-1, 3)).reshape(K, npts, 2)
        m = rig.margin_px
        inside = (np.isfinite(uv).all(-1) & (uv[..., 0] >= m) & (uv[..., 0] <= cam.width - 1 - m)
                  & (uv[..., 1] >= m) & (uv[..., 1] <= cam.height - 1 - m)).all(axis=1)
        depth = X[..., 2]
        near, far = rig.distance_m
        distance = ((depth >= near) & (depth <= far)).all(axis=1)
        if rig.max_angle_deg is None:
            angle = np.ones(K, bool)
        else:  # the line of sight from the point to the camera (the origin) against the way it faces
            cos = np.einsum("kpi,kpi->kp", -X, face) / np.maximum(np.linalg.norm(X, axis=-1), 1e-12)
            cos = cos if rig.tool else np.abs(cos)  # a marker plate across the tool's axis: either side
            angle = (cos >= np.cos(np.radians(rig.max_angle_deg))).all(axis=1)
        out[name] = {"field of view": inside, "angle": angle, "distance": distance}
    return out


def in_view(robot: Robot, rig: Rig, q: np.ndarray) -> np.ndarray:
    """(K,) the candidates q (K, n) at which every camera sees every point (`view_checks`); refused,
    naming each camera's checks, when none does."""
    checks = view_checks(robot, rig, q)
    ok = np.all([c[k] for c in checks.values() for k in c], axis=0)
    if ok.any():
        return ok
    K = len(q)
    what = "the board" if rig.tool else "the markers"
    angle = f"within {rig.max_angle_deg:g} deg" if rig.max_angle_deg is not None else "at any angle"
    near, far = rig.distance_m
    said = [f"camera {name}: field of view {int(c['field of view'].sum())} (every {rig.what} {rig.margin_px:g} px "
            f"inside the image), angle {int(c['angle'].sum())} ({what} {angle}), distance {int(c['distance'].sum())} "
            f"({near:g}-{far:g} m deep), all three {int(np.all(list(c.values()), axis=0).sum())}"
            for name, c in checks.items()]
    raise ModelError(f"no candidate pose keeps {what} in view of every camera; of {K} candidates, how many pass each "
                     f"check: {'; '.join(said)}; check the rig file, or relax --margin-px, --max-angle-deg, "
                     f"--distance-m, or give other candidates (--home, --span, --from)")


def nominal_pixels(robot: Robot, rig: Rig, q: np.ndarray) -> Pixels:
    """Image points of the nominal robot at q (K, n): every point in every camera, pose by pose (so a
    pose's rows are contiguous, cameras then points), as a pixel file of these poses would hold them."""
    names = list(rig.cameras)
    X = np.stack([in_camera(robot, rig, q, n)[0] for n in names], axis=1)  # (K, C, npts, 3)
    K, C, npts = X.shape[:3]
    uv = np.stack([rig.cameras[n].project(X[:, k].reshape(-1, 3)).reshape(K, npts, 2) for k, n in enumerate(names)],
                  axis=1)
    pose, cam, point = (a.ravel() for a in np.meshgrid(np.arange(K), np.arange(C), np.arange(npts), indexing="ij"))
    points = tuple(rig.board.names) if rig.tool else tuple(robot.targets)
    return Pixels(q, np.zeros((K, 6)), np.zeros((K, 0)), (), np.arange(K), pose, cam, point, uv.reshape(-1, 2),
                  np.arange(len(pose)) + 2, tuple(names), points, "tool" if rig.tool else "world", "candidates")


def rig_unknowns(rig: Rig) -> np.ndarray:
    """The fit's pose unknowns at the rig's poses: per camera a rotation vector and translation, then the board's."""
    from scipy.spatial.transform import Rotation

    poses = [rig.poses[n] for n in rig.cameras] + ([rig.board_pose] if rig.tool else [])
    return np.concatenate([[*Rotation.from_matrix(R).as_rotvec(), *t] for R, t in poses])


@dataclass(frozen=True)
class CameraDesign:
    """A design for images: `chosen` (N,) candidate indices in the order chosen, `random` (N,) the
    seeded random comparison from the same in-view candidates; `values`, `observability` as the
    tracker design's (`design.PoseDesign`), over the cameras' poses and the coefficients together;
    `predicted_std` {design, random}: {rms_px, max_px} of the image points' predicted position std
    over the validation candidates at noise_px per coordinate (the covariance of the coefficients and
    the cameras' poses carried to each point's u, v), and {rms_mm, max_mm} the same across the ray at
    each point's depth; `n_geometry` the pose unknowns, `identifiable` and `eliminated` the
    coefficients the images determine and those they do not (with why); `rank` the rows a pose adds."""

    chosen: np.ndarray
    random: np.ndarray
    criterion: str
    values: dict
    observability: dict
    predicted_std: dict
    noise_px: float
    n_validation: int
    n_candidates: int
    n_geometry: int
    identifiable: tuple[str, ...]
    eliminated: tuple
    rank: int
    swaps: int
    passes: int
    history: list

    def to_dict(self) -> dict:
        both = {f"{prefix}{key}": _finite(self.values[name][c])
                for name, prefix in (("design", ""), ("random", "random_"))
                for c, key in (("D", "log_det"), ("I", "mean_variance"))}
        obs = {**self.observability["design"], **{f"random_{k}": v for k, v in self.observability["random"].items()}}
        std = {**self.predicted_std["design"],
               **{f"random_{k}": v for k, v in self.predicted_std["random"].items()}}
        return {"n_poses": len(self.chosen), "criterion": self.criterion,
                "value": _finite(self.values["design"][self.criterion]),
                "random_value": _finite(self.values["random"][self.criterion]), **both, "observability": obs,
                "predicted_std": {"noise_px": self.noise_px, "n_validation_poses": self.n_validation, **std},
                "n_candidates": self.n_candidates, "n_pose_unknowns": self.n_geometry,
                "n_identifiable": len(self.identifiable), "identifiable": list(self.identifiable),
                "eliminated": [e.to_dict() for e in self.eliminated], "rows_per_pose": self.rank,
                "swaps": self.swaps, "passes": self.passes, "history": [_finite(v) for v in self.history]}


def _blocks(J: np.ndarray, K: int) -> np.ndarray:
    """Each pose's rows of J (2R, m), pose by pose, as (K, rows, m)."""
    return J.reshape(K, -1, J.shape[-1])


def _mm_per_px(robot: Robot, rig: Rig, q: np.ndarray) -> np.ndarray:
    """(V, C npts) what a pixel means across the ray at every point of every camera at the joints q (V, n),
    in `nominal_pixels`' order: 1e3 times its depth over the camera's mean focal length (mm per px, as the
    fit's reports put pixels in mm at the target)."""
    return np.concatenate([1e3 * in_camera(robot, rig, q, n)[0][..., 2] / ((c.fx + c.fy) / 2)
                           for n, c in rig.cameras.items()], axis=1)


@one_blas_thread
def design_images(robot: Robot, model: ErrorModel, rig: Rig, q: np.ndarray, n_poses: int, seed: int = 0,
                  noise_px: float = NOISE_PX, criterion: str = "D", n_validation: int = N_VALIDATION,
                  max_passes: int = MAX_PASSES) -> CameraDesign:
    """Choose n_poses of the candidate joints q (K, n) (all in view: `in_view`) for the pixel fit of
    `model`, by `criterion` (the tracker design's, `design.CRITERIA`). The random comparison and the
    validation poses are drawn (seeded) from the same candidates."""
    # here, not at the top: the pixel fit's module loads scipy's rotations, which the tracker design
    # and every `design --help` (they read this module's defaults) do not need (start-up time)
    from gecgen.fit.camera import design_rows

    require(criterion in CRITERIA, f"--criterion {criterion}: expected one of {', '.join(CRITERIA)}")
    crit = CRITERIA[criterion]
    K = len(q)
    require(1 <= n_poses <= K, f"--poses {n_poses}: {K} candidate poses keep everything in view; give between 1 and "
                               f"{K}, or more candidates (--candidates, --span)")
    rng, rng_random, rng_val = (np.random.default_rng([seed, s]) for s in range(3))
    data = nominal_pixels(robot, rig, q)
    sample = np.sort(rng.choice(K, min(K, BLOCK), replace=False))
    J, kept, eliminated = design_rows(robot, model, data, rig.cameras, rig.board, rig_unknowns(rig), sample, BLOCK)
    ng = J.shape[1] - len(kept)
    blocks = _blocks(J, K)
    # whitened: the mean candidate informs every unknown alike (`design._Basis`), poses first
    R = np.linalg.qr(J, mode="r") / np.sqrt(K)
    R *= np.sign(np.diag(R))[:, None]
    require((np.abs(np.diag(R)) > RANK_TOL * np.linalg.norm(R, axis=0)).all(),
            "the candidate poses do not determine the cameras' poses: draw them over a wider span (--span)")
    basis = _Basis(np.arange(blocks.shape[1]), np.arange(J.shape[1]), R, np.linalg.norm(R, axis=0), np.linalg.inv(R))
    _, s, Vt = np.linalg.svd(basis.whiten(blocks), full_matrices=False)
    rank = int((s > RANK_TOL * s.max()).sum(axis=1).max())
    Hw = s[:, :rank, None] * Vt[:, :rank]  # (K, rank, m): each pose's information, H_w^T H_w
    m = J.shape[1]
    # a direction is determined when its std is within 1000 times the best-informed one's (whitened against
    # the mean candidate; eigenvalues of the information above RANK_TOL of the largest): an image informs
    # weaker directions too, but so weakly that they do not count; so counted, an image of a board gives
    # six, as the camera's pose against the board allows
    strong = int((s > np.sqrt(RANK_TOL) * s.max()).sum(axis=1).max())
    posed = "cameras' and board's" if rig.board is not None else "cameras'"
    unknowns = f"{ng} of the {posed} poses, {len(kept)} coefficients"
    require(n_poses * strong >= m, f"--poses {n_poses}: {n_poses} poses determine at most {n_poses * strong} of the "
                                   f"{m} unknowns ({unknowns}; {strong} each); give at least "
                                   f"{int(np.ceil(m / strong))} poses")
    chosen, swaps, passes, history, _ = choose(Hw, RIDGE * np.eye(m), n_poses, rng, crit, max_passes)
    # images of nearby poses share directions: the count above passes designs whose information is still
    # singular, whose poses would not determine the fit
    eig = np.linalg.eigvalsh(np.einsum("pik,pil->kl", Hw[chosen], Hw[chosen]))
    determined = int((eig > RANK_TOL * eig.max()).sum())
    require(determined == m, f"--poses {n_poses}: the {n_poses} most informative poses among the candidates still "
                             f"determine only {determined} of the {m} unknowns ({unknowns}): give more poses (each "
                             f"determines {strong} at most), candidates over a wider span (--span), or a smaller "
                             f"error model (--errors)")
    random_pick = rng_random.choice(K, n_poses, replace=False)
    val = rng_val.choice(K, min(n_validation, K), replace=False)
    H_val = basis.whiten(blocks[val])
    mm_per_px = _mm_per_px(robot, rig, q[val])
    out = {}
    for name, idx in (("design", chosen), ("random", random_pick)):
        M = np.einsum("pik,pil->kl", Hw[idx], Hw[idx])
        std = predicted_std(M, H_val, noise_px, H_val.shape[1] // 2)  # px, (V, points)
        mm = std * mm_per_px
        out[name] = (*scores(basis, M, len(idx) * blocks.shape[1]),
                     {"rms_px": _finite(np.sqrt(np.mean(std ** 2))), "max_px": _finite(std.max()),
                      "rms_mm": _finite(np.sqrt(np.mean(mm ** 2))), "max_mm": _finite(mm.max())})
    names = model.coefficient_names(robot)
    return CameraDesign(chosen, random_pick, criterion, {n: o[0] for n, o in out.items()},
                        {n: o[1] for n, o in out.items()}, {n: o[2] for n, o in out.items()}, noise_px, len(val), K,
                        ng, tuple(names[j] for j in kept), eliminated, strong,
                        swaps, passes, reported_history(basis, history, crit))
