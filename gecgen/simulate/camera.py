"""Simulated image points of a truth robot: what a camera with known intrinsics records.

Eye-to-hand: cameras fixed in the world at true poses see the robot's targets; eye-in-hand: a camera
on the tool at a true pose sees a board's corners at a true pose in the world. The true chain
(`truth.true_state`, every joint approached from below, no payload) places the tool; each point is
projected with the camera's distortion (`Camera.project`) and gets Gaussian pixel noise. A point
outside the image or behind the camera is not recorded, as a real camera records nothing there.
Eye-in-hand, the board can also be rendered as the camera would photograph it (`render_images`), for
the whole chain from images through OpenCV's corners to a calibration.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.cameras import Board, Camera
from gecgen.model.kinematics import tool_poses
from gecgen.model.pixels import Pixels
from gecgen.model.robot import Robot
from gecgen.simulate.truth import Truth, true_state


def look_at(eye: np.ndarray, at: np.ndarray, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of a camera at `eye` looking at `at` (world, m): X_cam = R X_w + t, z along the view,
    y pointing down in the image (against `up`)."""
    z = np.asarray(at, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    return R, -R @ np.asarray(eye, float)


@dataclass(frozen=True)
class CameraRig:
    """The true set-up: per camera its (R, t) (X_cam = R X + t; X in the world for a fixed camera, in
    the tool frame for the carried one) and, eye-in-hand, the board and its (R, t) in the world."""

    cameras: dict[str, Camera]
    poses: dict[str, tuple[np.ndarray, np.ndarray]]
    board: Board | None = None
    board_pose: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def mount(self) -> str:
        return "tool" if self.board is not None else "world"


def true_tools(robot: Robot, truth: Truth, q: np.ndarray, branch: int | None = 0):
    """(N, 4, 4) the truth robot's tool poses at joint readings q (N, n); on a tree the tool's of branch
    `branch`, or (branch None) the list of every branch's."""
    robot = truth.robot or robot
    N = len(q)
    q_true, eps = true_state(robot, truth, q, np.zeros(N), np.zeros(3), {}, np.ones_like(q))
    tools = tool_poses(robot, q_true, eps)
    return tools if branch is None else tools[branch]


def camera_frame_points(robot: Robot, rig: CameraRig, tools: np.ndarray | list[np.ndarray],
                        camera: str) -> tuple[list[str], np.ndarray]:
    """The point names and their positions (N, K, 3) in `camera`'s frame for the tool poses (N, 4, 4) of
    a chain, or every branch's of a tree (a list, `true_tools` with branch None; a carried camera rides
    on the first)."""
    tools = [tools] if isinstance(tools, np.ndarray) else tools
    R, t = rig.poses[camera]
    if rig.mount == "tool":
        Rb, tb = rig.board_pose
        Xw = rig.board.corners @ Rb.T + tb
        Xt = np.einsum("nji,nkj->nki", tools[0][:, :3, :3], Xw[None] - tools[0][:, None, :3, 3])
        return rig.board.names, Xt @ R.T + t
    names = list(robot.targets)
    x = np.array([robot.targets[n] for n in names])
    T = np.stack([tools[robot.branch_of(n)] for n in names], axis=1)  # (N, K, 4, 4) each point's tool
    Xw = np.einsum("nkij,kj->nki", T[..., :3, :3], x) + T[..., :3, 3]
    return names, Xw @ R.T + t


def simulate_pixels(robot: Robot, truth: Truth, rig: CameraRig, q: np.ndarray, noise_px: float,
                    rng: np.random.Generator) -> Pixels:
    """Image points of the truth robot at joint readings q (N, n): every point each camera sees inside
    its image, with Gaussian noise of noise_px per coordinate."""
    tools = true_tools(robot, truth, q, None)
    pose, cam, point, uv = [], [], [], []
    names = list(rig.cameras)
    for k, name in enumerate(names):
        camera = rig.cameras[name]
        points, X = camera_frame_points(robot, rig, tools, name)
        N, K = X.shape[:2]
        px = camera.project(X.reshape(-1, 3)).reshape(N, K, 2)
        px = px + rng.normal(0.0, noise_px, px.shape)
        seen = (np.isfinite(px).all(-1) & (px[..., 0] >= 0) & (px[..., 0] <= camera.width - 1)
                & (px[..., 1] >= 0) & (px[..., 1] <= camera.height - 1))
        n, j = np.nonzero(seen)
        pose.append(n), cam.append(np.full(len(n), k)), point.append(j), uv.append(px[n, j])
    pose, cam, point, uv = (np.concatenate(a) for a in (pose, cam, point, uv))
    order = np.lexsort((point, cam, pose))
    used = np.unique(pose)
    remap = -np.ones(len(q), int)
    remap[used] = np.arange(len(used))
    points = tuple(rig.board.names) if rig.mount == "tool" else tuple(robot.targets)
    return Pixels(q[used], np.zeros((len(used), 6)), np.zeros((len(used), 0)), (), used.astype(np.int64),
                  remap[pose[order]], cam[order], point[order], uv[order], np.arange(len(order)) + 2, tuple(names),
                  points, rig.mount, "simulated")


def visible_share(robot: Robot, truth: Truth, rig: CameraRig, q: np.ndarray) -> np.ndarray:
    """(N,) the smallest share, over the cameras, of the points each sees inside its image at q (N, n):
    for choosing poses a camera can see."""
    tools = true_tools(robot, truth, q, None)
    share = np.ones(len(q))
    for name, camera in rig.cameras.items():
        _, X = camera_frame_points(robot, rig, tools, name)
        N, K = X.shape[:2]
        px = camera.project(X.reshape(-1, 3)).reshape(N, K, 2)
        seen = (np.isfinite(px).all(-1) & (px[..., 0] >= 0) & (px[..., 0] <= camera.width - 1)
                & (px[..., 1] >= 0) & (px[..., 1] <= camera.height - 1))
        share = np.minimum(share, seen.mean(axis=1))
    return share


def in_view(robot: Robot, truth: Truth, rig: CameraRig, q0: np.ndarray, span: np.ndarray, n: int,
             rng: np.random.Generator) -> np.ndarray:
    """n joint readings (n, 6) drawn uniformly in q0 +- span (rad) at which every camera sees every point."""
    lo = np.array([j.lower for j in robot.joints])
    hi = np.array([j.upper for j in robot.joints])
    found = np.zeros((0, len(q0)))
    for _ in range(50):
        q = np.clip(q0 + rng.uniform(-1, 1, (20 * n, len(q0))) * span, lo, hi)
        found = np.vstack([found, q[visible_share(robot, truth, rig, q) == 1.0]])
        if len(found) >= n:
            return found[:n]
    raise ValueError(f"only {len(found)} of {n} poses keep every point in view; widen the view or the span")


def eye_in_hand(robot: Robot, truth: Truth, camera: Camera, board: Board, q0: np.ndarray, span: np.ndarray,
                n_poses: int, rng: np.random.Generator, distance: float = 0.7) -> tuple[CameraRig, np.ndarray]:
    """A carried camera at a random pose near the tool frame (a few cm, a few degrees off its axes,
    looking along tool z) and a board `distance` m in front of it at joints q0; and n_poses joint
    readings in q0 +- span (rad) at which the camera sees the whole board."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(rng.normal(0, 0.05, 3)).as_matrix()  # tool -> camera
    t = rng.normal(0, 0.05, 3)
    T0 = true_tools(robot, truth, q0[None])[0]
    R_wc = T0[:3, :3] @ R.T  # the camera's axes in the world at q0
    centre = T0[:3, 3] - R_wc @ t + distance * R_wc[:, 2]
    Rb = R_wc  # the board's rows and columns along the image's: its r0c0 at the image's top-left
    size = np.array([(board.columns - 1) * board.square / 2, (board.rows - 1) * board.square / 2, 0.0])
    rig = CameraRig({camera.name: camera}, {camera.name: (R, t)}, board, (Rb, centre - Rb @ size))
    return rig, in_view(robot, truth, rig, q0, span, n_poses, rng)


def eye_to_hand(robot: Robot, truth: Truth, cameras: list[Camera], eyes: np.ndarray, at: np.ndarray,
                q0: np.ndarray, span: np.ndarray, n_poses: int,
                rng: np.random.Generator) -> tuple[CameraRig, np.ndarray]:
    """Fixed cameras at `eyes` (k, 3) looking at `at` (3,) (world, m); and n_poses joint readings in
    q0 +- span (rad) at which every camera sees every target of the robot."""
    rig = CameraRig({c.name: c for c in cameras}, {c.name: look_at(e, at) for c, e in zip(cameras, eyes)})
    return rig, in_view(robot, truth, rig, q0, span, n_poses, rng)


#: px between the pixels whose rays `render_board` computes exactly
GRID = 8
#: texture pixels per square of a rendered ChArUco board
TEXTURE_PX = 120


def render_board(camera: Camera, R: np.ndarray, t: np.ndarray, board: Board, rng: np.random.Generator,
                 blur_px: float = 0.7, noise: float = 2.0, supersample: int = 2, lighting: float = 0.0) -> np.ndarray:
    """A grayscale image (height, width) uint8 of the chessboard as `camera` sees it with the board at
    (R, t) in the camera frame (X_cam = R x_b + t): every pixel's ray, with the lens distortion undone
    (OpenCV's undistortPoints), meets the board's plane, whose squares are black and white with a white
    margin of one square; averaged over supersample^2 rays a pixel, lit (`lighting`, see `_lit`),
    blurred (Gaussian, blur_px) and with Gaussian noise (grey levels)."""
    import cv2
    from scipy.ndimage import map_coordinates

    s = supersample
    # the rays of a coarse grid of pixels, undone to convergence; between them interpolated: the
    # distortion is smooth over GRID px, and undoing it at every sample costs minutes an image
    gu, gv = np.meshgrid(np.arange(-GRID, camera.width + 2 * GRID, GRID, dtype=float),
                         np.arange(-GRID, camera.height + 2 * GRID, GRID, dtype=float))
    coarse = cv2.undistortPointsIter(np.column_stack([gu.ravel(), gv.ravel()])[:, None], camera.K,
                                     np.array(camera.distortion), None, None,
                                     (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14))
    coarse = coarse.reshape(*gu.shape, 2)
    u = (np.arange(camera.width * s) + 0.5) / s - 0.5
    v = (np.arange(camera.height * s) + 0.5) / s - 0.5
    mu, mv = np.meshgrid((u + GRID) / GRID, (v + GRID) / GRID)  # coordinates in the coarse grid
    # scipy's cubic spline, not cv2.remap, whose map coordinates are quantised to 1/32 of a cell
    rays = np.stack([map_coordinates(coarse[..., k], [mv.ravel(), mu.ravel()], order=3) for k in range(2)], -1)
    d = np.column_stack([rays, np.ones(len(rays))]) @ R  # the rays in the board frame, from its origin at -R^T t
    origin = -R.T @ t
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = -origin[2] / d[:, 2]
    xy = origin[:2] + lam[:, None] * d[:, :2]
    cell = np.floor(xy / board.square).astype(np.int64)
    inside = ((cell[:, 0] >= -1) & (cell[:, 0] < board.columns) & (cell[:, 1] >= -1) & (cell[:, 1] < board.rows)
              & (lam > 0))
    if board.kind == "charuco":  # OpenCV's drawing of the board, its corner id 0 at our r0c0
        from gecgen.model.images import charuco_board

        texture = charuco_board(board).generateImage(((board.columns + 1) * TEXTURE_PX,
                                                      (board.rows + 1) * TEXTURE_PX), marginSize=0) > 127
        at = np.floor((xy + board.square) / board.square * TEXTURE_PX).astype(np.int64)
        at = np.clip(at, 0, [texture.shape[1] - 1, texture.shape[0] - 1])
        white = np.where(inside, texture[at[:, 1], at[:, 0]], True)
    else:
        white = np.where(inside, (cell[:, 0] + cell[:, 1]) % 2 == 1, True)
    image = np.where(white, 230.0, 25.0).reshape(camera.height, s, camera.width, s).mean(axis=(1, 3))
    if lighting > 0:
        image = _lit(image, lighting, rng)
    if blur_px > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_px)
    image = image + rng.normal(0.0, noise, image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def _lit(image: np.ndarray, lighting: float, rng: np.random.Generator) -> np.ndarray:
    """The image (H, W) under another light: its brightness scaled by a random gain in [1 - lighting, 1]
    and by a random linear ramp across the image that changes it by up to +-lighting / 2 at the image's
    edges, as a lamp to one side or a cloud would (lighting 0 to 1)."""
    h, w = image.shape
    gain = rng.uniform(1.0 - lighting, 1.0)
    a, b = rng.uniform(-1.0, 1.0, 2) * lighting / 2
    return image * gain * (1.0 + a * np.linspace(-1, 1, w)[None, :] + b * np.linspace(-1, 1, h)[:, None])


def board_in_camera(rig: CameraRig, tool: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The board's (R, t) in the carried camera's frame (X_cam = R x_b + t) with the tool at `tool` (4, 4)."""
    R, t = next(iter(rig.poses.values()))
    Rb, tb = rig.board_pose
    Rt, pt = tool[:3, :3], tool[:3, 3]
    return R @ Rt.T @ Rb, R @ (Rt.T @ (tb - pt)) + t


def render_images(robot: Robot, truth: Truth, rig: CameraRig, q: np.ndarray, rng: np.random.Generator,
                  blur_px: float = 0.7, noise: float = 2.0, lighting: float = 0.0):
    """One image (`render_board`) per joint reading of q (N, n) of the board the carried camera of `rig`
    sees on the truth robot, as a generator (it takes about a second an image)."""
    camera = next(iter(rig.cameras.values()))
    for tool in true_tools(robot, truth, q):
        yield render_board(camera, *board_in_camera(rig, tool), rig.board, rng, blur_px, noise, lighting=lighting)
