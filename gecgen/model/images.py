"""Images of a chessboard to image points: OpenCV's corner detection, and the readings that go with them.

A readings file is a CSV with one row per image: `image` (its file name in the image folder),
`camera` (a name from the camera file; may be left out with one camera), `q1..qn` and the optional
wrench and auxiliary columns of a measurement file. Each image is one pose. The board's corners are
found by `findChessboardCorners` and refined by `cornerSubPix`; OpenCV may number them from either
end of the board, so corner r0c0 is taken as the end nearer the image's top-left (a camera turning
more than 90 degrees about its axis between images would swap them: keep it within that, or use a
ChArUco board, whose markers name every corner and which may be partly out of view). An image
where the board is not found gives no rows and is named, never dropped silently.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gecgen.model.cameras import Board, Camera
from gecgen.model.measurements import MAX_AUX, MAX_WRENCH, within_limits
from gecgen.model.pixels import Pixels
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.table import at, read_table
from gecgen.model.validation import excerpt, require

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: cornerSubPix's half window (px) and stopping rule
SUBPIX_WINDOW = 5
SUBPIX_CRITERIA = (3, 50, 1e-4)  # cv2.TERM_CRITERIA_EPS + MAX_ITER, iterations, px


def _cv2():
    try:
        import cv2
    except ImportError:
        raise ValueError("reading images needs OpenCV: pip install 'gecgen[camera]' (opencv-python-headless)") from None
    return cv2


#: a ChArUco board with fewer corners found than this in an image counts as not found
MIN_CHARUCO_CORNERS = 6


def charuco_board(board: Board):
    """OpenCV's ChArUco board for a board file's (its squares one more than the inner corners)."""
    cv2 = _cv2()
    return cv2.aruco.CharucoBoard((board.columns + 1, board.rows + 1), board.square, board.marker,
                                  cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary)))


def find_corners(gray: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray] | None:
    """The board's inner corners in a grayscale image (H, W) uint8: their indices in `Board.names`
    (K,) and pixels (K, 2), or None when the board is not found. A chessboard gives all its corners
    or none; a ChArUco board those its markers identify (at least MIN_CHARUCO_CORNERS)."""
    cv2 = _cv2()
    if board.kind == "charuco":
        corners, ids, _, _ = cv2.aruco.CharucoDetector(charuco_board(board)).detectBoard(gray)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        return ids.ravel().astype(np.int64), corners.reshape(-1, 2).astype(float)
    size = (board.columns, board.rows)
    found, corners = cv2.findChessboardCorners(gray, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH |
                                               cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        return None
    corners = cv2.cornerSubPix(gray, corners, (SUBPIX_WINDOW, SUBPIX_WINDOW), (-1, -1), SUBPIX_CRITERIA)
    corners = corners.reshape(-1, 2).astype(float)
    if corners[-1].sum() < corners[0].sum():  # numbered from the far end: r0c0 nearer the top-left
        corners = corners[::-1].copy()
    return np.arange(len(corners)), corners


@dataclass(frozen=True)
class Detected:
    """Image points found in a folder: `pixels`, and the images where the board was not found."""

    pixels: Pixels
    not_found: tuple[str, ...]


def detect(readings, folder: str | Path, robot: Robot, cameras: dict[str, Camera], board: Board) -> Detected:
    """The image points of every image a readings file names (see the module docstring)."""
    cv2 = _cv2()
    folder = Path(folder)
    require(folder.is_dir(), f"{folder}: no such folder of images")
    require(all(c.mount == "tool" for c in cameras.values()), f"{folder}: board images come from a camera on the "
                                                              f"tool (mount: tool); fixed cameras that see markers "
                                                              f"on the robot need their points as a pixel file")
    qcols = [f"q{i + 1}" for i in range(robot.n)]
    table = read_table(readings, "readings file", ", ".join(["image", *qcols]), text=("image", "camera"))
    where, header = table.where, table.header
    for col in ["image", *qcols]:
        require(col in header, f"{where}: row 1: missing column '{col}' (a readings file needs: image, "
                               f"{', '.join(qcols)})")
    names = [c.strip() for c in table.cells("image")]
    seen = {}
    for r, n in enumerate(names):
        require(n not in seen, f"{where}: rows {seen.get(n, 0) + 2} and {r + 2}: image {excerpt(n)} twice; "
                               f"one row per image")
        seen[n] = r
    if "camera" in header:
        cams = [c.strip() for c in table.cells("camera")]
    else:
        require(len(cameras) == 1, f"{where}: row 1: no column 'camera' and {len(cameras)} cameras in the camera "
                                   f"file; say which camera took each image")
        cams = [next(iter(cameras))] * len(names)
    for r, c in enumerate(cams):
        require(c in cameras, f"{at(where, r + 2, 'camera')}: unknown camera {excerpt(c)}; the camera file has "
                              f"{', '.join(cameras)}")
    files = sorted(p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    unread = [f for f in files if f not in seen]
    require(not unread, f"{folder / unread[0] if unread else folder}: an image without readings; add its row to "
                        f"{where} or move it out of the folder")
    wcols = [c for c in WRENCH if c in header]
    aux_names = tuple(h for h in header if h not in ("image", "camera", *qcols, *WRENCH))
    state = np.column_stack([table.numbers(c) if c in qcols else
                             table.numbers(c, limit=MAX_WRENCH) if c in WRENCH else
                             table.numbers(c, "fix it or remove the column (auxiliary columns must be numeric)",
                                           MAX_AUX) for c in [*qcols, *wcols, *aux_names]])
    within_limits(state[:, :robot.n], robot, where)
    cam_names = tuple(cameras)
    sizes: dict[str, tuple[int, int, str]] = {}
    pose, cam, point, uv, not_found = [], [], [], [], []
    for r, (name, c) in enumerate(zip(names, cams)):
        path = folder / name
        require(path.is_file(), f"{at(where, r + 2, 'image')}: {path} does not exist; fix the name or add the image")
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        require(gray is not None, f"{path}: not an image OpenCV can read; convert it to PNG")
        h, w = gray.shape
        first = sizes.setdefault(c, (w, h, name))
        require(first[:2] == (w, h), f"{path}: {w} x {h} px, but {first[2]} of camera {c} is {first[0]} x "
                                     f"{first[1]}; one camera's images share one size")
        camera = cameras[c]
        require((w, h) == (camera.width, camera.height),
                f"{path}: {w} x {h} px, but camera {c}'s intrinsics are for {camera.width} x {camera.height}: "
                f"intrinsics of another resolution; calibrate the camera at this size or scale fx fy cx cy")
        found = find_corners(gray, board)
        if found is None:
            not_found.append(name)
            continue
        index, corners = found
        pose.append(np.full(len(corners), r)), cam.append(np.full(len(corners), cam_names.index(c)))
        point.append(index), uv.append(corners)
    require(pose, f"{folder}: the {board.columns} x {board.rows} inner corners of the board were found in none "
                  f"of the {len(names)} images; check the board file's columns and rows (inner corners, not squares)"
                  + (", its marker and dictionary" if board.kind == "charuco" else ""))
    pose, cam, point, uv = (np.concatenate(a) for a in (pose, cam, point, uv))
    used = np.unique(pose)
    remap = -np.ones(len(names), int)
    remap[used] = np.arange(len(used))
    w = np.zeros((len(used), 6))
    for k, c in enumerate(wcols):
        w[:, WRENCH.index(c)] = state[used, robot.n + k]
    pixels = Pixels(state[used, :robot.n], w, state[used, robot.n + len(wcols):], aux_names, used.astype(np.int64),
                    remap[pose], cam, point, uv, pose + 2, cam_names, tuple(board.names),
                    "tool", where)
    return Detected(pixels, tuple(not_found))
