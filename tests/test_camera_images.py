"""Images -> corners -> calibration: boards rendered by the simulator (distortion, blur, noise), found by
`gecgen import --images`, fitted; and the refusals of the images' import."""
import contextlib
import io
import shutil

import numpy as np
import pytest

from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.cameras import Board, Camera
from gecgen.model.pixels import read_pixels
from gecgen.model.validation import read_yaml
from gecgen.fit.camera import fit_pixels
from gecgen.simulate import load_truth
from gecgen.simulate.camera import board_in_camera, camera_frame_points, eye_in_hand, render_board, true_tools

from conftest import ROBOTS, ROOT, run_json
from gecgen.cli import main

cv2 = pytest.importorskip("cv2")

CAMERA = Camera("cam", 700.0, 700.0, 320.0, 240.0, (-0.1, 0.05, 0.0005, -0.0004, 0.0), 640, 480, "tool")
BOARD = Board(9, 6, 0.04)


def camera_yaml(cam: Camera, width=None, height=None) -> str:
    return (f"cameras:\n  cam: {{mount: tool, fx: {cam.fx}, fy: {cam.fy}, cx: {cam.cx}, cy: {cam.cy}, "
            f"distortion: {list(cam.distortion)}, width: {width or cam.width}, height: {height or cam.height}}}\n")


def _render(robot, truth, board: Board, n: int, images, name: str, rng) -> tuple[np.ndarray, list]:
    """n images of `board` seen by the wrist camera (named `name`.format(k) in the new folder
    `images`): the joint readings (n, 6) and the true corners of each (px)."""
    rig, q = eye_in_hand(robot, truth, CAMERA, board, np.radians([0, -90, -90, 0, 60, 0]),
                         np.radians([8, 6, 6, 25, 20, 30]), n, rng)
    images.mkdir()
    T = true_tools(robot, truth, q)
    truth_px = []
    for k in range(len(q)):
        image = render_board(CAMERA, *board_in_camera(rig, T[k]), board, rng)
        cv2.imwrite(str(images / name.format(k)), image)
        truth_px.append(CAMERA.project(camera_frame_points(robot, rig, T[k:k + 1], "cam")[1][0]))
    return q, truth_px


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    """Ten rendered images of the board, a blank one, their readings and the true corners (px)."""
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    truth = load_truth(read_yaml(ROBOTS / "industrial6r.truth.yaml", "truth file"), robot)
    rng = np.random.default_rng(8)
    folder = tmp_path_factory.mktemp("shots")
    images = folder / "images"
    q, truth_px = _render(robot, truth, BOARD, 10, images, "img{:02d}.png", rng)
    cv2.imwrite(str(images / "blank.png"), np.full((480, 640), 200, np.uint8))
    lines = ["image,q1,q2,q3,q4,q5,q6"] + [f"img{k:02d}.png," + ",".join(map(repr, q[k].tolist()))
                                          for k in range(len(q))]
    lines.append("blank.png," + ",".join(map(repr, q[0].tolist())))
    (folder / "readings.csv").write_text("\n".join(lines) + "\n")
    (folder / "cams.yaml").write_text(camera_yaml(CAMERA))
    (folder / "board.yaml").write_text("type: chessboard\ncolumns: 9\nrows: 6\nsquare: 0.04\n")
    return robot, folder, np.array(truth_px)


def test_images_to_corners_to_a_calibration(shots, tmp_path):
    robot, folder, truth_px = shots
    out = run_json("import", ROBOTS / "industrial6r.yaml", folder / "readings.csv", "--images", folder / "images",
                   "--board", folder / "board.yaml", "--cameras", folder / "cams.yaml", "-o", tmp_path / "px.csv")
    assert out["not_found"] == ["blank.png"] and out["poses"] == 10 and out["rows"] == 10 * 54
    cams = {"cam": CAMERA}
    data = read_pixels(tmp_path / "px.csv", robot, cams, BOARD)
    found = data.uv.reshape(10, 54, 2)
    error = np.linalg.norm(found - truth_px, axis=2)
    assert np.sqrt(np.mean(error ** 2)) < 0.15 and error.max() < 0.6  # px: sub-pixel corners, every one labelled alike
    fit = fit_pixels(robot, load_error_model(ROBOTS / "constant.errors.yaml", robot), data, cams, BOARD)
    assert fit.converged and not fit.failures and fit.train["rms_px"] < 0.3


def _refused(args, capsys) -> str:
    assert main([*map(str, args), "--json"]) != 0
    return capsys.readouterr().err


def test_image_import_refusals(shots, tmp_path, capsys):
    robot, folder, _ = shots
    base = ["import", ROBOTS / "industrial6r.yaml", folder / "readings.csv", "--images", folder / "images",
            "--board", folder / "board.yaml", "--cameras", folder / "cams.yaml", "-o", tmp_path / "px.csv"]
    (tmp_path / "b8.yaml").write_text("type: chessboard\ncolumns: 8\nrows: 6\nsquare: 0.04\n")
    assert "check the board file's columns and rows" in _refused([*base[:6], tmp_path / "b8.yaml", *base[7:]], capsys)
    (tmp_path / "big.yaml").write_text(camera_yaml(CAMERA, 1280, 960))
    assert "intrinsics of another resolution" in _refused([*base[:8], tmp_path / "big.yaml", *base[9:]], capsys)
    extra = tmp_path / "extra"
    shutil.copytree(folder / "images", extra)
    cv2.imwrite(str(extra / "stray.png"), np.zeros((480, 640), np.uint8))
    assert "stray.png: an image without readings" in _refused([*base[:4], extra, *base[5:]], capsys)
    mixed = tmp_path / "mixed"
    shutil.copytree(folder / "images", mixed)
    cv2.imwrite(str(mixed / "img03.png"), cv2.resize(cv2.imread(str(mixed / "img03.png")), (320, 240)))
    assert "one camera's images share one size" in _refused([*base[:4], mixed, *base[5:]], capsys)
    assert "--images, --board and --cameras go together" in _refused(base[:7] + base[-2:], capsys)
    charuco = "type: charuco\ncolumns: 9\nrows: 6\nsquare: 0.04\nmarker: 0.03\ndictionary: {}\n"
    (tmp_path / "april.yaml").write_text(charuco.format("DICT_APRILTAG_36h11"))
    err = _refused([*base[:6], tmp_path / "april.yaml", *base[7:]], capsys)
    assert "april.yaml, key 'dictionary': 'DICT_APRILTAG_36h11' is not one of the ArUco dictionaries" in err
    (tmp_path / "aruco.yaml").write_text(charuco.format("DICT_4X4_50"))  # a chessboard has no markers to find
    assert "check the board file's columns and rows (inner corners, not squares), its marker and dictionary" in \
        _refused([*base[:6], tmp_path / "aruco.yaml", *base[7:]], capsys)
    rows = (folder / "readings.csv").read_text().splitlines()
    (tmp_path / "gone.csv").write_text("\n".join([*rows, "gone.png" + rows[1][rows[1].index(","):]]) + "\n")
    err = _refused([*base[:2], tmp_path / "gone.csv", *base[3:]], capsys)
    assert "gone.csv: row 13, column 'image'" in err and "gone.png does not exist; fix the name or add the image" in err


def test_a_charuco_board_names_its_corners(tmp_path):
    """ChArUco: rendered from OpenCV's own drawing, every corner found is where the truth projects the
    corner its id names, and the images calibrate."""
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    truth = load_truth(read_yaml(ROBOTS / "industrial6r.truth.yaml", "truth file"), robot)
    board = Board(9, 6, 0.04, kind="charuco", marker=0.03, dictionary="DICT_5X5_100")
    rng = np.random.default_rng(9)
    images = tmp_path / "images"
    q, truth_px = _render(robot, truth, board, 8, images, "img{}.png", rng)
    (tmp_path / "readings.csv").write_text("image,q1,q2,q3,q4,q5,q6\n" + "".join(
        f"img{k}.png," + ",".join(map(repr, q[k].tolist())) + "\n" for k in range(len(q))))
    (tmp_path / "cams.yaml").write_text(camera_yaml(CAMERA))
    (tmp_path / "board.yaml").write_text("type: charuco\ncolumns: 9\nrows: 6\nsquare: 0.04\nmarker: 0.03\n"
                                         "dictionary: DICT_5X5_100\n")
    out = run_json("import", ROBOTS / "industrial6r.yaml", tmp_path / "readings.csv", "--images", images,
                   "--board", tmp_path / "board.yaml", "--cameras", tmp_path / "cams.yaml", "-o", tmp_path / "px.csv")
    assert out["not_found"] == [] and out["poses"] == 8
    data = read_pixels(tmp_path / "px.csv", robot, {"cam": CAMERA}, board)
    error = np.linalg.norm(data.uv - np.array(truth_px)[data.pose, data.point], axis=1)
    assert len(error) >= 8 * 40 and np.sqrt(np.mean(error ** 2)) < 0.15
    fit = fit_pixels(robot, load_error_model(ROBOTS / "constant.errors.yaml", robot), data, {"cam": CAMERA}, board)
    assert fit.converged and not fit.failures and fit.train["rms_px"] < 0.3


REAL = ROOT / "tests" / "data" / "images" / "opencv"  # OpenCV's samples, Apache-2.0: see its README.md


def test_real_images_match_the_sources_calibration(tmp_path):
    """Thirteen photographs of a printed 9 x 6 chessboard from OpenCV's samples, through `gecgen import
    --images`: every corner lies where OpenCV's own calibration of these images (its intrinsics and each
    view's pose) projects the corner of that name, as closely as OpenCV's own corners did (its per-view
    RMS, stored with the calibration). Same detector family, so this shows gecgen's import keeps OpenCV's
    sub-pixel quality on real images and names every corner consistently with the board's geometry."""
    source = cv2.FileStorage(str(REAL / "left_intrinsics.yml"), cv2.FILE_STORAGE_READ)
    K, dist = source.getNode("camera_matrix").mat(), source.getNode("distortion_coefficients").mat().ravel()
    poses = source.getNode("extrinsic_parameters").mat()
    their_rms = source.getNode("per_view_reprojection_errors").mat().ravel()
    names = [f"left{k:02d}.jpg" for k in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14)]
    assert source.getNode("nframes").real() == len(names) == len(poses)
    board = Board(int(source.getNode("board_width").real()), int(source.getNode("board_height").real()),
                  source.getNode("square_size").real())
    camera = Camera("cam", *K[[0, 1, 0, 1], [0, 1, 2, 2]].tolist(), tuple(dist.tolist()), 640, 480, "tool")
    home = ",".join(map(repr, np.radians([0, -90, -90, 0, 60, 0]).tolist()))  # no robot took them: any pose
    (tmp_path / "readings.csv").write_text("image,q1,q2,q3,q4,q5,q6\n" + "".join(f"{n},{home}\n" for n in names))
    (tmp_path / "cams.yaml").write_text(camera_yaml(camera))
    (tmp_path / "board.yaml").write_text(f"columns: {board.columns}\nrows: {board.rows}\nsquare: {board.square}\n")
    out = run_json("import", ROBOTS / "industrial6r.yaml", tmp_path / "readings.csv", "--images", REAL, "--board",
                   tmp_path / "board.yaml", "--cameras", tmp_path / "cams.yaml", "-o", tmp_path / "px.csv")
    assert out["not_found"] == [] and out["poses"] == len(names) and out["rows"] == len(names) * 54
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    data = read_pixels(tmp_path / "px.csv", robot, {"cam": camera}, board)
    ours = np.full((len(names), len(board.names), 2), np.nan)
    ours[data.pose, data.point] = data.uv
    rms, worst = [], []
    for k, pose in enumerate(poses):
        theirs = cv2.projectPoints(board.corners, pose[:3], pose[3:], K, dist)[0].reshape(-1, 2)
        if theirs[-1].sum() < theirs[0].sum():  # the board's end gecgen calls r0c0 (see gecgen.model.images)
            theirs = theirs[::-1]
        error = np.linalg.norm(ours[k] - theirs, axis=1)
        rms.append(np.sqrt(np.mean(error ** 2))), worst.append(error.max())
    rms, worst = np.array(rms), np.array(worst)
    # px: per view no farther from the source's calibration than the source's own corners (+0.07 px for
    # the JPEG decoder and OpenCV version); a corner named wrongly would be a square (~25 px) off
    assert (rms <= their_rms + 0.07).all(), np.column_stack([rms, their_rms])
    assert (worst < np.where(their_rms < 0.5, 1.0, 2.0)).all(), worst


def test_rendered_images_recover_a_known_truth(tmp_path):
    """`simulate --images` -> `import --images` -> `identify --cameras` on six rendered ChArUco images of
    the nominal robot: the camera's pose on the tool (a few cm and degrees off the tool frame) and the
    board's in the world come out where the simulator put them, and so does the camera on poses no image
    saw."""
    from scipy.spatial.transform import Rotation

    from gecgen.fit.calibration import load
    from gecgen.fit.camera import fitted_tools

    robot_file = ROBOTS / "industrial6r.yaml"
    (tmp_path / "truth.yaml").write_text("description: the nominal robot, exactly as its file describes it\n")
    (tmp_path / "cams.yaml").write_text(camera_yaml(CAMERA))
    (tmp_path / "board.yaml").write_text("type: charuco\ncolumns: 9\nrows: 6\nsquare: 0.04\nmarker: 0.03\n"
                                         "dictionary: DICT_5X5_100\n")
    on = ["--board", tmp_path / "board.yaml", "--cameras", tmp_path / "cams.yaml"]
    home, span = np.radians([0, -90, -90, 0, 60, 0]), np.radians([8, 6, 6, 25, 20, 30])
    run_json("simulate", robot_file, "--truth", tmp_path / "truth.yaml", "--images", tmp_path / "images", "--poses", 6,
             "--home", ",".join(map(repr, home.tolist())), "--span", ",".join(map(repr, span.tolist())),
             "--rig-out", tmp_path / "rig.yaml", "--seed", 3, "-o", tmp_path / "readings.csv", *on)
    found = run_json("import", robot_file, tmp_path / "readings.csv", "--images", tmp_path / "images", *on,
                     "-o", tmp_path / "px.csv")
    assert found["images"] == 6 and found["not_found"] == []
    run_json("identify", robot_file, tmp_path / "px.csv", "--errors", ROBOTS / "constant.errors.yaml",
             "-o", tmp_path / "calib.json", *on)
    robot = load_robot(robot_file)
    rig, calib = read_yaml(tmp_path / "rig.yaml", "rig"), load(tmp_path / "calib.json")
    pose = lambda s: (np.array(s["rotation"]), np.array(s["translation"]))  # noqa: E731
    (R, t), (Rf, tf) = pose(rig["cameras"]["cam"]), pose(calib.report["cameras"]["cam"])
    (Rb, tb), (Rbf, tbf) = pose(rig["board"]), pose(calib.report["board"])
    assert np.linalg.norm(R.T @ t) > 0.03  # the camera sits well off the tool frame: there is something to find
    # m, rad: measured 0.05 mm and 0.11 mrad (the camera), 0.04 mm and 0.59 mrad (the board, 0.7 m away), 0.05 mm
    # (the camera's centre on new poses)
    assert np.linalg.norm(R.T @ t - Rf.T @ tf) < 0.2e-3 and Rotation.from_matrix(Rf @ R.T).magnitude() < 0.5e-3
    assert np.linalg.norm(tb - tbf) < 1e-3 and Rotation.from_matrix(Rbf @ Rb.T).magnitude() < 1e-3
    q = home + np.random.default_rng(4).uniform(-1, 1, (10, 6)) * span  # poses no image saw
    T = true_tools(robot, load_truth({}, robot), q)
    true = np.einsum("nij,j->ni", T[:, :3, :3], -R.T @ t) + T[:, :3, 3]
    T = fitted_tools(robot, calib.model, calib.c, q)
    fitted = np.einsum("nij,j->ni", T[:, :3, :3], -Rf.T @ tf) + T[:, :3, 3]
    assert np.linalg.norm(fitted - true, axis=1).max() < 0.2e-3



def test_rendered_images_to_a_calibration_from_the_command_line(shots, tmp_path):
    """import --images, then calibrate --cameras on what it detected, as a user runs them. These images were
    taken with the elbow within a few degrees of stretched (industrial6r's a3 = -90 deg), where no command of
    the training ranges can be compensated: calibrate says so in one line and leaves no calibration behind;
    identify's fit of the same images scores them as evaluate does."""
    from gecgen.cli import main

    robot, folder, _ = shots
    on = ["--board", folder / "board.yaml", "--cameras", folder / "cams.yaml"]
    run_json("import", ROBOTS / "industrial6r.yaml", folder / "readings.csv", "--images", folder / "images", *on,
             "-o", tmp_path / "px.csv")
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main([*map(str, ["calibrate", ROBOTS / "industrial6r.yaml", tmp_path / "px.csv", *on, "--models",
                                 "geometric", "-o", tmp_path / "calib"])]) != 0
    lines = err.getvalue().strip().splitlines()
    assert len(lines) == 1 and "the training poses lie near a singular posture" in lines[0], lines
    assert not (tmp_path / "calib" / "calibration.json").exists()
    fit = run_json("identify", ROBOTS / "industrial6r.yaml", tmp_path / "px.csv", *on, "-o", tmp_path / "cal.json")
    assert fit["train"]["rms_px"] < 0.3 < fit["before"]["rms_px"]
    assert fit["camera_uncertainty"]["cameras"]["cam"]["relative_to"] == "tool"
    scored = run_json("evaluate", tmp_path / "cal.json", tmp_path / "px.csv", *on)
    assert abs(scored["after"]["rms_px"] - fit["train"]["rms_px"]) < 1e-9  # the same images, the same poses
