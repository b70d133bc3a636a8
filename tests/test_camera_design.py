"""gecgen design --cameras: poses that keep the board or the markers in view, informative for the pixel fit
(gecgen/plan/camera_design.py)."""
import contextlib
import csv
import io
from dataclasses import replace

import numpy as np
import pytest
import yaml
from conftest import ROBOTS, run_json

from gecgen.api import design_images
from gecgen.cli import main
from gecgen.fit.camera import design_rows
from gecgen.model import load_robot
from gecgen.model.cameras import Board, Camera
from gecgen.model.kinematics import tool_poses
from gecgen.model.validation import ModelError, read_yaml
from gecgen.plan import camera_design as CD
from gecgen.plan.design import logdet
from gecgen.simulate import load_truth
from gecgen.simulate.camera import camera_frame_points, eye_in_hand, eye_to_hand, simulate_pixels
from gecgen.symbolic.terms import load_error_model

pytest.importorskip("cv2")

DIST = (-0.12, 0.08, 0.0008, -0.0005, 0.0)
MARKERS = {"m1": (0.15, 0.15, 0.1), "m2": (-0.15, 0.15, 0.1), "m3": (-0.15, -0.15, 0.1), "m4": (0.15, -0.15, 0.1)}
HAND_HOME = np.radians([0, -90, -90, 0, 60, 0])
WORLD_HOME = np.radians([0, -80, -100, 0, 30, 0])


@pytest.fixture(scope="module")
def arm():
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    truth = load_truth(read_yaml(ROBOTS / "industrial6r.truth.yaml", "truth file"), robot)
    return robot, truth, load_error_model(ROBOTS / "constant.errors.yaml", robot)


@pytest.fixture(scope="module")
def hand(arm):
    """A camera on the tool and a 9 x 6 board as the simulator places them, and a design of 15 images."""
    robot, truth, model = arm
    cam = Camera("cam", 1400.0, 1400.0, 640.0, 480.0, DIST, 1280, 960, "tool")
    rig, _ = eye_in_hand(robot, truth, cam, Board(9, 6, 0.04), HAND_HOME, np.radians([8, 6, 6, 25, 20, 30]), 1,
                         np.random.default_rng(1))
    out = design_images(robot, rig.cameras, (rig.poses, rig.board_pose), 15, board=rig.board, errors=model,
                        candidates=6000, home=HAND_HOME, seed=2)
    return rig, out


@pytest.fixture(scope="module")
def world(arm):
    """Two fixed cameras and four markers on the tool; a design of 20 poses, every marker 20 px inside the
    images, the markers' plate (across tool z) seen within 75 deg."""
    robot, truth, model = arm
    robot = replace(robot, targets=MARKERS)
    cams = [Camera(f"cam{k + 1}", 1800.0, 1800.0, 640.0, 480.0, DIST, 1280, 960) for k in range(2)]
    rig, _ = eye_to_hand(robot, truth, cams, np.array([[1.9, -2.4, 1.7], [1.9, 2.4, 1.7]]), np.array([2.0, 0, 1.0]),
                         WORLD_HOME, np.radians([12, 10, 10, 60, 40, 90]), 1, np.random.default_rng(4))
    out = design_images(robot, rig.cameras, (rig.poses, None), 20, errors=model, candidates=3000, home=WORLD_HOME,
                        seed=3, margin_px=20.0, max_angle_deg=75.0, distance_m=(0.5, 4.0))
    return robot, rig, out


def _sight(robot, rig, q):
    """Independently of the design: every point in every camera's frame (the simulator's chain) at q on the
    nominal robot, its pixel, and the cosine of its angle to the line of sight (board: its -z face;
    markers: tool z, either side), per camera."""
    tools = tool_poses(robot, q)
    out = {}
    for name, cam in rig.cameras.items():
        _, X = camera_frame_points(robot, rig, tools, name)
        R, t = rig.poses[name]
        if rig.mount == "tool":  # the camera's centre in the world against the board's centre and face
            Rb, tb = rig.board_pose
            centre = tools[0][:, :3, :3] @ (-R.T @ t) + tools[0][:, :3, 3]
            sight = centre - (rig.board.corners.mean(axis=0) @ Rb.T + tb)
            cos = (sight @ -Rb[:, 2]) / np.linalg.norm(sight, axis=1)
        else:
            eye = -R.T @ t
            p = X @ R - R.T @ t  # back in the world
            sight = eye - p
            face = tools[0][:, None, :3, 2]
            cos = np.abs(np.sum(sight * face, axis=-1) / np.linalg.norm(sight, axis=-1)).min(axis=1)
        out[name] = (X, cam.project(X.reshape(-1, 3)).reshape(*X.shape[:2], 2), cos)
    return out


@pytest.mark.parametrize("setup", ["hand", "world"])
def test_designed_poses_keep_every_point_in_view(setup, arm, request):
    """Projected with the simulator's chain and camera, every designed pose keeps every board corner (or
    marker) inside the image by the margin, at the depths and within the angle asked; and the truth robot,
    whose errors move the points by millimetres, images every point at every designed pose."""
    robot, truth, _ = arm
    if setup == "hand":
        rig, out = request.getfixturevalue("hand")
        npts, cos_max = 54, np.cos(np.radians(CD.MAX_ANGLE_DEG))
        near, far = CD.DISTANCE_M
    else:
        robot, rig, out = request.getfixturevalue("world")
        npts, cos_max, (near, far) = 4, np.cos(np.radians(75.0)), (0.5, 4.0)
    assert len(out.q) == out.design.to_dict()["n_poses"] and out.n_in_view < out.n_sampled  # the view did reject
    m = out.rig.margin_px
    for name, (X, uv, cos) in _sight(robot, rig, out.q).items():
        cam = rig.cameras[name]
        assert np.isfinite(uv).all()
        assert (uv >= m).all() and (uv[..., 0] <= cam.width - 1 - m).all() and (uv[..., 1] <= cam.height - 1 - m).all()
        assert (X[..., 2] >= near).all() and (X[..., 2] <= far).all()
        assert (cos >= cos_max - 1e-9).all()
    data = simulate_pixels(robot, truth, rig, out.q, 0.2, np.random.default_rng(0))
    assert data.n_poses == len(out.q) and len(data.uv) == len(out.q) * npts * len(rig.cameras)


@pytest.mark.parametrize("setup", ["hand", "world"])
def test_designed_set_is_better_conditioned_than_random(setup, arm, request):
    """The designed poses beat as many random in-view ones on every figure of the pixel fit's information;
    and the reported log det gain is that of the fit's own uncompressed Jacobian at both sets."""
    robot, _, model = arm
    if setup == "hand":
        rig, out = request.getfixturevalue("hand")
    else:
        robot, rig, out = request.getfixturevalue("world")
    d = out.design.to_dict()
    obs, std = d["observability"], d["predicted_std"]
    assert d["log_det"] > d["random_log_det"] + 1.0
    assert d["mean_variance"] < d["random_mean_variance"]
    assert obs["O2"] < obs["random_O2"] and obs["O3"] > obs["random_O3"]
    assert std["rms_px"] < std["random_rms_px"]
    g = CD.rig_unknowns(out.rig)
    M = {}
    for name, q in (("design", out.q), ("random", out.random)):
        data = CD.nominal_pixels(robot, out.rig, q)
        J, kept, _ = design_rows(robot, model, data, rig.cameras, rig.board, g, np.arange(len(q)), 100)
        assert list(kept) == [n for n in range(len(model.coefficient_names(robot)))
                              if model.coefficient_names(robot)[n] in d["identifiable"]]
        M[name] = J.T @ J
    assert logdet(M["design"]) - logdet(M["random"]) == pytest.approx(d["log_det"] - d["random_log_det"], abs=1e-4)


def _rig_file(rig, path):
    spec = {"cameras": {c: {"rotation": R.tolist(), "translation": t.tolist()} for c, (R, t) in rig.poses.items()},
            "board": {"rotation": rig.board_pose[0].tolist(), "translation": rig.board_pose[1].tolist()}}
    path.write_text(yaml.safe_dump(spec))


def _files(hand, tmp_path):
    rig, _ = hand
    cam = rig.cameras["cam"]
    (tmp_path / "cams.yaml").write_text(yaml.safe_dump({"cameras": {"cam": {
        "mount": "tool", "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "distortion": list(cam.distortion),
        "width": cam.width, "height": cam.height}}}))
    (tmp_path / "board.yaml").write_text(yaml.safe_dump({"type": "chessboard", "columns": 9, "rows": 6,
                                                         "square": 0.04}))
    _rig_file(rig, tmp_path / "rig.yaml")
    return ["--cameras", tmp_path / "cams.yaml", "--board", tmp_path / "board.yaml", "--rig", tmp_path / "rig.yaml"]


def test_cli_writes_the_design_format(hand, tmp_path):
    """`gecgen design --cameras` writes pose, q1..qn, the contract's keys, and the API's poses."""
    out = tmp_path / "poses.csv"
    result = run_json("design", ROBOTS / "industrial6r.yaml", "--errors", ROBOTS / "constant.errors.yaml", "--poses",
                      15, "--candidates", 6000, "--home", ",".join(map(str, HAND_HOME)), "--seed", 2,
                      *_files(hand, tmp_path), "-o", out)
    assert {"n_poses", "criterion", "value", "random_value"} <= set(result) and result["mount"] == "tool"
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["pose", *(f"q{i}" for i in range(1, 7))] and len(rows) == 15
    q = np.array([[float(r[f"q{i}"]) for i in range(1, 7)] for r in rows])
    np.testing.assert_allclose(q, hand[1].q, atol=1e-12)


def _refused(*args) -> str:
    """A command's one-line refusal (its stderr), run in this process."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(list(map(str, args))) != 0
    return err.getvalue().strip()


def test_no_pose_in_view_is_refused_naming_the_camera_and_the_checks(hand, tmp_path):
    """A board placed 3 m above where the camera can look: one line naming the camera and each check."""
    rig, _ = hand
    args = _files(hand, tmp_path)
    far = replace(rig, board_pose=(rig.board_pose[0], rig.board_pose[1] + [0.0, 0.0, 3.0]))
    _rig_file(far, tmp_path / "rig.yaml")
    message = _refused("design", ROBOTS / "industrial6r.yaml", "--errors", ROBOTS / "constant.errors.yaml", "--poses",
                       15, "--candidates", 2000, "--home", ",".join(map(str, HAND_HOME)), *args,
                       "-o", tmp_path / "p.csv")
    assert len(message.splitlines()) == 1 and "Traceback" not in message
    for word in ("camera cam", "field of view 0", "angle", "distance", "all three 0"):
        assert word in message, message


def test_options_without_cameras_and_tracker_options_with_them_are_refused(hand, tmp_path):
    args = _files(hand, tmp_path)
    base = ["design", ROBOTS / "industrial6r.yaml", "--poses", 15, "-o", tmp_path / "p.csv"]
    assert "--rig goes with --cameras" in _refused(*base, "--rig", tmp_path / "rig.yaml")
    assert "--min-z does not apply to a design for images" in _refused(*base, *args, "--min-z", 0.5)
    with pytest.raises(ModelError, match="give the board"):
        design_images(load_robot(ROBOTS / "industrial6r.yaml"), hand[0].cameras, (hand[0].poses, None), 5)


def test_rig_file_refusals_name_the_file_and_key(hand, tmp_path):
    from gecgen.model.cameras import read_rig

    rig, _ = hand
    path = tmp_path / "rig.yaml"
    _rig_file(rig, path)
    poses, board = read_rig(path, rig.cameras, rig.board)
    np.testing.assert_array_equal(poses["cam"][0], rig.poses["cam"][0])
    np.testing.assert_array_equal(board[1], rig.board_pose[1])
    spec = yaml.safe_load(path.read_text())
    for change, expect in ((lambda s: s.pop("board"), "missing key 'board'"),
                           (lambda s: s["cameras"]["cam"].update(rotation=[[1, 0, 0], [0, 2, 0], [0, 0, 1]]),
                            "camera 'cam', key 'rotation': not a rotation matrix"),
                           (lambda s: s["cameras"].update(other=s["cameras"]["cam"]), "camera 'other' is not in the "
                                                                                      "camera file")):
        bad = yaml.safe_load(yaml.safe_dump(spec))
        change(bad)
        path.write_text(yaml.safe_dump(bad))
        with pytest.raises(ModelError, match=expect):
            read_rig(path, rig.cameras, rig.board)


def test_too_few_images_for_the_model_are_refused_and_every_candidate_may_be_chosen(arm, hand):
    """Eleven images of the board cannot determine the default model's 89 coefficients with the two poses
    (each determines six directions, the camera's pose against the board): refused in one line with the
    count that could (17), where it wrote a design whose information was singular (no log det, O3 0);
    17 images chosen among nearby candidates still share directions, and are refused too; and asked for as
    many poses as there are candidates, design takes them all (it failed with a traceback looking for one
    to exchange)."""
    robot, _, _ = arm
    rig, designed = hand
    default = load_error_model(ROBOTS / "industrial6r.errors.yaml", robot)
    for n, expect in ((11, r"--poses 11: 11 poses determine at most 66 of the 101 unknowns \(12 of the cameras' and "
                           r"board's poses, 89 coefficients; 6 each\); give at least 17 poses"),
                      (17, r"--poses 17: the 17 most informative poses .* determine only \d+ of the 101 unknowns .* "
                           r"give more poses \(each determines 6 at most\)")):
        with pytest.raises(ModelError, match=expect):
            design_images(robot, rig.cameras, (rig.poses, rig.board_pose), n, board=rig.board, errors=default,
                          candidates=2000, home=HAND_HOME, seed=2)
    everything = design_images(robot, rig.cameras, (rig.poses, rig.board_pose), 15, board=rig.board,
                               errors=load_error_model(ROBOTS / "constant.errors.yaml", robot), candidates=designed.q,
                               seed=2)
    assert sorted(map(tuple, everything.q)) == sorted(map(tuple, designed.q))
    assert everything.design.to_dict()["log_det"] is not None


def test_tracker_only_design_options_are_refused_with_cameras(hand, tmp_path):
    """--given (tracker data the design adds to) and --payload-kg (a wrench the images do not weigh) are the
    tracker design's: with --cameras each is refused in one line."""
    args = _files(hand, tmp_path)
    base = ["design", ROBOTS / "industrial6r.yaml", "--poses", 15, "-o", tmp_path / "p.csv", *args]
    (tmp_path / "given.csv").write_text("pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n")
    for option in (["--given", tmp_path / "given.csv"], ["--payload-kg", "0,10"]):
        line = _refused(*base, *option)
        assert line.endswith(f"{option[0]} does not apply to a design for images (--cameras); drop it"), line
        assert len(line.splitlines()) == 1
