"""Cameras and calibration boards: the files that describe them and the pinhole projection.

A camera file (`--cameras FILE`, YAML) gives each camera's intrinsics, OpenCV's pinhole model with
its five distortion coefficients, and where it is mounted:

    cameras:
      cam1: {mount: world, fx: 1400, fy: 1400, cx: 640, cy: 480,
             distortion: [k1, k2, p1, p2, k3], width: 1280, height: 960}

`mount: world` is a camera fixed in the world that sees points on the robot (eye-to-hand);
`mount: tool` a camera the robot carries that sees a board fixed in the world (eye-in-hand). A board
file (`--board FILE`) gives a chessboard's (or a ChArUco board's) inner corners and square size; its
corners are named `rRcC` (row R, column C, from 0) and sit at (C square, R square, 0) in the board frame.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from gecgen.model.validation import ModelError, require

MOUNTS = ("world", "tool")
BOARD_TYPES = ("chessboard", "charuco")
#: the ArUco dictionaries a ChArUco board may use (OpenCV's predefined ones, by name)
ARUCO_DICTIONARIES = tuple(f"DICT_{b}X{b}_{n}" for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000))


@dataclass(frozen=True)
class Camera:
    """One camera: focal lengths and principal point (px), OpenCV distortion (k1, k2, p1, p2, k3),
    image size (px) and mount ("world" or "tool")."""

    name: str
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float]
    width: int
    height: int
    mount: str = "world"

    @property
    def K(self) -> np.ndarray:
        """(3, 3) the camera matrix, as OpenCV writes it."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def project(self, X: np.ndarray, jacobian: bool = False):
        """Pixels (N, 2) of camera-frame points X (N, 3) (m, z along the optical axis), and with
        `jacobian` also d(u, v)/dX (N, 2, 3) in px per m. Points at or behind the camera give NaN."""
        X = np.asarray(X, float)
        z = np.where(X[:, 2] > 0, X[:, 2], np.nan)
        x, y = X[:, 0] / z, X[:, 1] / z
        k1, k2, p1, p2, k3 = self.distortion
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        uv = np.column_stack([self.fx * xd + self.cx, self.fy * yd + self.cy])
        if not jacobian:
            return uv
        dradial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
        dxd = np.stack([radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x,
                        2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y], -1)
        dyd = np.stack([2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y,
                        radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x], -1)
        D = np.stack([self.fx * dxd, self.fy * dyd], 1)  # (N, 2, 2): d(u, v)/d(x, y)
        dxy = np.zeros((len(X), 2, 3))  # d(x, y)/dX
        dxy[:, 0, 0] = dxy[:, 1, 1] = 1 / z
        dxy[:, 0, 2], dxy[:, 1, 2] = -x / z, -y / z
        return uv, D @ dxy


@dataclass(frozen=True)
class Board:
    """A chessboard: inner corners `columns` x `rows`, squares of `square` m; a ChArUco board
    (kind "charuco") also has ArUco markers of side `marker` m from `dictionary` in its white squares,
    its corner r0c0 OpenCV's corner id 0 (id = R columns + C)."""

    columns: int
    rows: int
    square: float
    source: str = ""
    kind: str = "chessboard"
    marker: float = 0.0
    dictionary: str = ""

    @property
    def names(self) -> list[str]:
        return [f"r{r}c{c}" for r in range(self.rows) for c in range(self.columns)]

    @property
    def corners(self) -> np.ndarray:
        """(rows x columns, 3) the corners in the board frame (m), in `names` order."""
        r, c = np.divmod(np.arange(self.rows * self.columns), self.columns)
        return np.column_stack([c * self.square, r * self.square, np.zeros(len(r))])


def _yaml(path: str | Path, what: str) -> dict:
    try:
        spec = yaml.safe_load(Path(path).read_text())
    except OSError as e:
        raise ModelError(f"{path}: cannot read the {what} ({e.strerror}); give an existing file") from None
    except yaml.YAMLError as e:
        raise ModelError(f"{path}: not valid YAML ({str(e).splitlines()[0]}); fix the {what}") from None
    require(isinstance(spec, dict), f"{path}: the {what} must be a mapping of keys (see docs/reference.md, "
                                    f"\"Cameras\")")
    return spec


def _number(spec: dict, key: str, where: str, positive: bool = True) -> float:
    require(key in spec, f"{where}: missing key '{key}'; add it (px)")
    value = spec[key]
    require(isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
            and (value > 0 or not positive),
            f"{where}, key '{key}': {value!r} is not a {'positive ' if positive else ''}number; fix it")
    return float(value)


def read_cameras(path: str | Path) -> dict[str, Camera]:
    """The cameras of a camera file, by name."""
    spec = _yaml(path, "camera file")
    cams = spec.get("cameras")
    require(isinstance(cams, dict) and cams, f"{path}: key 'cameras' must map each camera's name to its intrinsics")
    out = {}
    for name, c in cams.items():
        where = f"{path}, camera '{name}'"
        require(isinstance(c, dict), f"{where}: give fx, fy, cx, cy, distortion, width, height and mount")
        unknown = sorted(set(c) - {"fx", "fy", "cx", "cy", "distortion", "width", "height", "mount"})
        require(not unknown, f"{where}: unknown key '{unknown[0] if unknown else ''}'; the keys are fx, fy, cx, cy, "
                             f"distortion, width, height, mount")
        mount = c.get("mount", "world")
        require(mount in MOUNTS, f"{where}, key 'mount': {mount!r}; use world (fixed, sees the robot) or tool "
                                 f"(carried by the robot, sees the board)")
        dist = c.get("distortion", [0.0] * 5)
        require(isinstance(dist, list) and len(dist) == 5 and all(isinstance(d, (int, float)) and np.isfinite(d)
                                                                   for d in dist),
                f"{where}, key 'distortion': give the five OpenCV coefficients [k1, k2, p1, p2, k3]")
        width, height = (_number(c, k, where) for k in ("width", "height"))
        require(width == int(width) and height == int(height), f"{where}: width and height are whole pixels")
        cx, cy = _number(c, "cx", where, False), _number(c, "cy", where, False)
        require(0 <= cx <= width and 0 <= cy <= height,
                f"{where}: principal point ({cx:g}, {cy:g}) outside the {width:g} x {height:g} image; "
                f"intrinsics of another resolution?")
        out[str(name)] = Camera(str(name), _number(c, "fx", where), _number(c, "fy", where), cx, cy,
                                tuple(float(d) for d in dist), int(width), int(height), mount)
    carried = [n for n, c in out.items() if c.mount == "tool"]
    require(len(carried) <= 1, f"{path}: cameras {', '.join(carried)} are all mounted on the tool; one carried "
                               f"camera is supported")
    require(not carried or len(out) == 1, f"{path}: a carried camera (mount: tool) with fixed ones; one "
                                          f"set-up per file: eye-in-hand or eye-to-hand")
    return out


def read_board(path: str | Path) -> Board:
    """The board of a board file."""
    spec = _yaml(path, "board file")
    kind = spec.get("type", "chessboard")
    require(kind in BOARD_TYPES, f"{path}, key 'type': {kind!r} is not supported; use chessboard or charuco")
    for key in ("columns", "rows"):
        value = spec.get(key)
        require(isinstance(value, int) and not isinstance(value, bool) and value >= 2,
                f"{path}, key '{key}': {value!r}; give the number of inner corners (at least 2)")
    square = spec.get("square")
    require(isinstance(square, (int, float)) and not isinstance(square, bool) and 0 < square < 1,
            f"{path}, key 'square': {square!r}; give the square's side in m (e.g. 0.025)")
    if kind == "chessboard":
        return Board(spec["columns"], spec["rows"], float(square), str(path))
    marker, dictionary = spec.get("marker"), spec.get("dictionary")
    require(isinstance(marker, (int, float)) and not isinstance(marker, bool) and 0 < marker < square,
            f"{path}, key 'marker': {marker!r}; give the ArUco marker's side in m, smaller than the square")
    require(dictionary in ARUCO_DICTIONARIES, f"{path}, key 'dictionary': {dictionary!r} is not one of the ArUco "
                                              f"dictionaries a board may use ({ARUCO_DICTIONARIES[0]} .. "
                                              f"{ARUCO_DICTIONARIES[-1]}, OpenCV's names); give the one the board "
                                              f"was printed with, e.g. DICT_5X5_100")
    return Board(spec["columns"], spec["rows"], float(square), str(path), kind, float(marker), dictionary)


def _pose(spec, where: str) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of a rig file's entry {rotation: 3 x 3, translation: 3}; R a rotation to 1e-6."""
    require(isinstance(spec, dict) and {"rotation", "translation"} <= set(spec),
            f"{where}: give 'rotation' (3 x 3) and 'translation' (3, m)")
    try:
        R, t = np.array(spec["rotation"], float), np.array(spec["translation"], float)
    except (TypeError, ValueError):
        R, t = np.zeros(0), np.zeros(0)
    require(R.shape == (3, 3) and t.shape == (3,) and np.isfinite(R).all() and np.isfinite(t).all(),
            f"{where}: 'rotation' must be 3 rows of 3 numbers and 'translation' 3 numbers (m)")
    require(np.abs(R @ R.T - np.eye(3)).max() < 1e-6 and np.linalg.det(R) > 0,
            f"{where}, key 'rotation': not a rotation matrix (orthonormal, determinant +1) to 1e-6; fix it")
    return R, t


def read_rig(path: str | Path, cameras: dict[str, Camera], board: Board | None):
    """Where the cameras (and the board) are, from a rig file (YAML, as `gecgen simulate --rig-out`
    writes it): `cameras` maps every camera of the camera file to its `rotation` R and `translation` t,
    X_cam = R X + t (X in the world for a fixed camera, in the tool frame for one on the tool); with a
    camera on the tool, `board` its pose in the world, X_world = R x_board + t. Returns (poses by
    camera, the board's (R, t) or None)."""
    spec = _yaml(path, "rig file")
    poses = spec.get("cameras")
    require(isinstance(poses, dict), f"{path}: key 'cameras' must map each camera's name to its rotation and "
                                     f"translation")
    missing = [c for c in cameras if c not in poses]
    require(not missing, f"{path}: camera '{missing[0] if missing else ''}' of the camera file has no pose; add it "
                         f"under 'cameras'")
    extra = [str(c) for c in poses if c not in cameras]
    require(not extra, f"{path}: camera '{extra[0] if extra else ''}' is not in the camera file; remove it or add "
                       f"it there")
    out = {name: _pose(poses[name], f"{path}, camera '{name}'") for name in cameras}
    if board is None:
        require("board" not in spec, f"{path}: key 'board' goes with a camera on the tool; these cameras are fixed")
        return out, None
    require("board" in spec, f"{path}: missing key 'board': where the board is in the world (rotation, "
                             f"translation; X_world = R x_board + t)")
    return out, _pose(spec["board"], f"{path}, key 'board'")
