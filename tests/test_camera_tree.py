"""Image points on a tree: two fixed cameras see markers on both hands of the simulated humanoid (a torso
carrying two arms). simulate --cameras writes them, identify --cameras fits every branch with the
cameras' poses, and the held-out hands land within 1.2x a fit that is told the true cameras."""
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import FIXED_CAMERAS as CAMERAS, ROBOTS, run_json
from gecgen.fit.calibration import load as load_calibration
from gecgen.fit.camera import fit_pixels, fitted_tools
from gecgen.fit.registration import kabsch
from gecgen.model import load_robot
from gecgen.model.cameras import read_cameras
from gecgen.model.pixels import read_pixels
from gecgen.model.validation import read_yaml
from gecgen.simulate import load_truth
from gecgen.simulate.camera import true_tools
from gecgen.symbolic.terms import load_error_model

pytest.importorskip("cv2")

HOME = "0,0.2,-0.2,-0.3,0.9,0,-1.2,0,0.3,-0.9,0,-1.2,0"
SPAN = "0.2,0.15,0.15,0.3,0.3,0.5,0.3,0.5,0.3,0.3,0.5,0.3,0.5"


def registered_mm(p: np.ndarray, y: np.ndarray) -> float:
    """RMS (mm) of p - y (N, 3) once y is moved rigidly onto p."""
    R, t = kabsch(y, p)
    return 1e3 * float(np.sqrt(np.mean(np.sum((p - (y @ R.T + t)) ** 2, axis=1))))


@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    """The humanoid with four markers on each hand (a 150 mm square 100 mm beyond the wrist), its pixel
    files (60 training, 40 held-out poses, 0.1 px) and the true cameras' poses."""
    d = tmp_path_factory.mktemp("tree")
    text = (ROBOTS / "humanoid.yaml").read_text().replace("urdf: humanoid/", f"urdf: {ROBOTS}/humanoid/")
    for side, name in (("l", "lh"), ("r", "rh")):
        markers = ", ".join(f"{side}{k + 1}: [{x}, {y}, -0.1]"
                            for k, (x, y) in enumerate([(0.075, 0.075), (-0.075, 0.075), (-0.075, -0.075),
                                                        (0.075, -0.075)]))
        text = re.sub(rf"targets: {{{name}: [^}}]*}}", f"targets: {{{markers}}}", text)
    (d / "humanoid.yaml").write_text(text)
    (d / "cams.yaml").write_text(CAMERAS)
    run_json("simulate", d / "humanoid.yaml", "--truth", ROBOTS / "humanoid.truth.yaml", "--cameras", d / "cams.yaml",
             "--eye", "cam1=2.6,-0.7,1.2", "--eye", "cam2=2.6,0.7,1.2", "--look-at", "0.28,0,0.81", "--home", HOME, "--span", SPAN, "--poses",
             "60", "--val-poses", "40", "--noise-px", "0.1", "--seed", "1", "-o", d / "train.csv", "--val-out",
             d / "val.csv", "--rig-out", d / "rig.yaml")
    return d


def test_fixed_cameras_calibrate_both_hands_of_a_tree_to_the_oracles_floor(tree):
    d = tree
    robot = load_robot(d / "humanoid.yaml")
    assert [b.name for b in robot.branches] == ["left", "right"]
    fit = run_json("identify", d / "humanoid.yaml", d / "train.csv", "--errors", ROBOTS / "constant.errors.yaml",
                   "--cameras", d / "cams.yaml", "--noise-px", "0.1", "-o", d / "cal.json")
    assert fit["converged"] and fit["train"]["rms_px"] < 0.3
    # compensate refuses a tree's calibration without --branch: the next step names each branch
    assert f"gecgen compensate {d / 'cal.json'} POSES.csv -o OUT.csv --branch left, gecgen compensate " \
           f"{d / 'cal.json'} POSES.csv -o OUT.csv --branch right" in fit["next"], fit["next"]
    scored = run_json("evaluate", d / "cal.json", d / "val.csv", "--cameras", d / "cams.yaml")
    assert scored["after"]["rms_px"] < 1.5 * fit["train"]["rms_px"] < 0.2 * scored["before"]["rms_px"]
    # the oracle: the same pixels, the true cameras' poses given
    cameras = read_cameras(d / "cams.yaml")
    model = load_error_model(ROBOTS / "constant.errors.yaml", robot)
    rig = read_yaml(d / "rig.yaml", "rig")
    fixed = np.concatenate([[*Rotation.from_matrix(rig["cameras"][c]["rotation"]).as_rotvec(),
                             *rig["cameras"][c]["translation"]] for c in cameras])
    oracle = fit_pixels(robot, model, read_pixels(d / "train.csv", robot, cameras), cameras, fixed_poses=fixed)
    truth = load_truth(read_yaml(ROBOTS / "humanoid.truth.yaml", "truth file"), robot)
    held = read_pixels(d / "val.csv", robot, cameras).q
    truth_at = np.concatenate([true_tools(robot, truth, held, b)[:, :3, 3] for b in (0, 1)])
    calib = load_calibration(d / "cal.json")
    error = {name: registered_mm(np.concatenate([fitted_tools(robot, model, c, held, branch=b)[:, :3, 3]
                                                 for b in (0, 1)]), truth_at)
             for name, c in (("fit", calib.c), ("oracle", oracle.c), ("nominal", np.zeros(len(calib.c))))}
    # both hands' tool origins on the held-out poses, each fit registered on them as a tracker would be
    assert error["fit"] < 1.2 * error["oracle"] and error["fit"] < 0.5 * error["nominal"], error


def test_a_camera_on_the_tool_of_a_tree_is_refused_in_one_line(tree, tmp_path):
    import contextlib
    import io

    from gecgen.cli import main

    d = tree
    (tmp_path / "hand.yaml").write_text(CAMERAS.replace("mount: world", "mount: tool").split("\n  cam2")[0] + "\n")
    (tmp_path / "board.yaml").write_text("type: chessboard\ncolumns: 9\nrows: 6\nsquare: 0.04\n")
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["identify", str(d / "humanoid.yaml"), str(d / "train.csv"), "--cameras",
                     str(tmp_path / "hand.yaml"), "--board", str(tmp_path / "board.yaml")]) != 0
    assert "a camera on the tool is supported on serial chains only" in err.getvalue()
    assert len(err.getvalue().strip().splitlines()) == 1
