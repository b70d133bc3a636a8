"""Image points on a tree: two fixed cameras see markers on both hands of the simulated humanoid (a torso
carrying two arms). simulate --cameras writes them, identify --cameras fits every branch with the
cameras' poses, and the held-out hands land within 1.2x a fit that is told the true cameras."""
import json
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


@pytest.fixture(scope="module")
def identified(tree):
    """identify --cameras's JSON on the tree's training images, its calibration written to cal.json."""
    return run_json("identify", tree / "humanoid.yaml", tree / "train.csv", "--errors", ROBOTS / "constant.errors.yaml",
                    "--cameras", tree / "cams.yaml", "--noise-px", "0.1", "-o", tree / "cal.json")


def test_fixed_cameras_calibrate_both_hands_of_a_tree_to_the_oracles_floor(tree, identified):
    d, fit = tree, identified
    robot = load_robot(d / "humanoid.yaml")
    assert [b.name for b in robot.branches] == ["left", "right"]
    assert fit["converged"] and fit["train"]["rms_px"] < 0.3
    # compensate refuses a tree's calibration without --branch: the next step names each branch
    assert f"gecgen compensate {d / 'cal.json'} POSES.csv -o OUT.csv --branch left, gecgen compensate " \
           f"{d / 'cal.json'} POSES.csv -o OUT.csv --branch right" in fit["next"], fit["next"]
    scored = run_json("evaluate", d / "cal.json", d / "val.csv", "--cameras", d / "cams.yaml")
    assert scored["after"]["rms_px"] < 1.5 * fit["train"]["rms_px"] < 0.2 * scored["before"]["rms_px"]
    # each hand's held-out points apart (four markers a hand, every one seen by both cameras: the two
    # hands' mean square is the whole's)
    for stage in ("before", "after"):
        hands = scored[stage]["branches"]
        assert set(hands) == {"left", "right"}
        assert np.isclose(np.mean([h["rms_px"] ** 2 for h in hands.values()]), scored[stage]["rms_px"] ** 2)
    assert all(scored["after"]["branches"][h]["rms_px"] < 0.2 * scored["before"]["branches"][h]["rms_px"]
               for h in ("left", "right"))
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


# Every command a pixel calibration of the tree goes through, as a user runs it (gecgen.cli.main)


def _refused(*args) -> str:
    """The one line a command prints when it refuses (it must exit non-zero with exactly one line)."""
    import contextlib
    import io

    from gecgen.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main([*map(str, args)]) != 0
    lines = err.getvalue().strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


@pytest.fixture(scope="module")
def checked(tree):
    """Ten new poses' images of the same tree and cameras (new.csv), and the same images with the right
    arm's second joint read 1 mrad off (off.csv)."""
    d = tree
    run_json("simulate", d / "humanoid.yaml", "--truth", ROBOTS / "humanoid.truth.yaml", "--cameras", d / "cams.yaml",
             "--eye", "cam1=2.6,-0.7,1.2", "--eye", "cam2=2.6,0.7,1.2", "--look-at", "0.28,0,0.81", "--home", HOME,
             "--span", SPAN, "--poses", "10", "--noise-px", "0.1", "--seed", "5", "-o", d / "new.csv")
    lines = (d / "new.csv").read_text().splitlines()
    col = lines[0].split(",").index("q10")
    rows = [r.split(",") for r in lines[1:]]
    for r in rows:
        r[col] = repr(float(r[col]) + 1e-3)
    (d / "off.csv").write_text("\n".join([lines[0], *(",".join(r) for r in rows)]) + "\n")
    return d


def test_diagnose_on_a_tree_from_pixels(tree):
    d = tree
    out = run_json("diagnose", d / "humanoid.yaml", d / "train.csv", "--val", d / "val.csv", "--cameras",
                   d / "cams.yaml", "--noise-px", "0.1", "--max-rounds", "1", "-o", d / "diag" / "tree.errors.yaml")
    assert out["measurement"] == "pixels" and (d / "diag" / "tree.errors.yaml").is_file()
    before, after = out["before"], out["after"]
    # the held-out images: what the declared model leaves is near the 0.1 px noise, and diagnose's model
    # does not do worse there than the declared one
    assert before["val_rms_px"] < 0.3 and after["val_rms_px"] <= before["val_rms_px"] + 1e-9, out
    # each hand apart, as for tracker points (four markers a hand seen by both cameras: the mean square of
    # the two hands' is the whole's)
    for key, whole in (("train_branches", "train_rms_px"), ("val_branches", "val_rms_px")):
        hands = out[key]
        assert set(hands) == {"left", "right"}
        for stage, figures in (("before", before), ("after", after)):
            assert np.isclose(np.mean([h[stage]["rms_px"] ** 2 for h in hands.values()]), figures[whole] ** 2)
    # the next step fits the diagnosed model as diagnose did: the same cameras and stated noise
    assert out["next"].endswith(f"--errors {d / 'diag' / 'tree.errors.yaml'} --cameras {d / 'cams.yaml'} --noise-px 0.1 "
                                f"-o humanoid.calib.json"), out["next"]


def test_calibrate_on_a_tree_from_pixels(tree):
    d = tree
    out = run_json("calibrate", d / "humanoid.yaml", d / "train.csv", "--val", d / "val.csv", "--cameras",
                   d / "cams.yaml", "--noise-px", "0.1", "--models", "geometric", "-o", d / "calib")
    assert out["model"] == "geometric" and out["measurement"] == "pixels"
    assert (d / "calib" / "calibration.json").is_file() and (d / "calib" / "generated" / "humanoid.c").is_file()
    # held out, the calibration's images against the nominal model's through the same cameras
    assert out["val"]["rms_px"] < 0.2 * out["val_before"]["rms_px"] and out["val"]["rms_px"] < 0.3, out
    assert set(out["val"]["cameras"]) == {"cam1", "cam2"} and set(out["val"]["branches"]) == {"left", "right"}
    assert out["camera_uncertainty"]["cameras"]["cam2"]["relative_to"] == "cam1"
    assert "--branch left" in out["next"] and "--branch right" in out["next"]
    # the report scores the validation images, and says so (it said "Training data only")
    text = (d / "calib" / "report.md").read_text()
    assert "Validation images (" in text and "Training data only" not in text
    assert "The held-out images are scored in the first sections" in text
    train = json.loads((d / "calib" / "calibration.json").read_text())["train"]["branches"]
    for hand in ("left", "right"):  # each hand's row (60 poses, 4 markers, 2 cameras), as the calibration records it
        assert f"| `{hand}` | 480 | " in text and f"| {train[hand]['rms_px']:.3g} |" in text


def test_compensate_places_each_hand_of_a_tree_calibrated_from_pixels(tree, identified, tmp_path):
    d = tree
    calib = load_calibration(d / "cal.json")
    lines = (d / "val.csv").read_text().splitlines()
    n = calib.robot.n
    seen, poses = set(), ["pose," + ",".join(f"q{i + 1}" for i in range(n))]
    for line in lines[1:]:
        cells = line.split(",")
        if cells[0] not in seen and len(seen) < 6:
            seen.add(cells[0])
            poses.append(",".join(cells[:n + 1]))
    (tmp_path / "poses.csv").write_text("\n".join(poses) + "\n")
    assert "--branch" in _refused("compensate", d / "cal.json", tmp_path / "poses.csv", "-o", tmp_path / "out.csv")
    commanded = np.loadtxt(tmp_path / "poses.csv", delimiter=",", skiprows=1)[:, 1:]
    robot = load_robot(d / "humanoid.yaml")
    for b, name in enumerate(("left", "right")):
        out = run_json("compensate", d / "cal.json", tmp_path / "poses.csv", "-o", tmp_path / f"{name}.csv",
                       "--branch", name)
        assert out["status_counts"] == {"ok": 6}
        q = np.loadtxt(tmp_path / f"{name}.csv", delimiter=",", skiprows=1, usecols=range(1, n + 1))
        moved = np.abs(q - commanded).max(axis=0) > 0
        other = [j for j, joint in enumerate(robot.joints) if "arm_" in joint.name and f"_{name}_" not in joint.name]
        assert moved.any() and not moved[other].any()  # the other hand's joints are left as commanded
        # independently of compensate: the calibrated model at the corrected joints puts this hand's tool
        # origin where the nominal model puts it at the commanded ones (five joints of its own place the
        # position, not every angle besides)
        placed = fitted_tools(robot, calib.model, calib.c, q, branch=b)[:, :3, 3]
        wanted = fitted_tools(robot, calib.model, np.zeros(len(calib.c)), commanded, branch=b)[:, :3, 3]
        assert np.abs(placed - wanted).max() < 1e-9


def test_export_a_tree_calibrated_from_pixels(tree, identified, tmp_path):
    d = tree
    out = run_json("export", d / "cal.json", "--urdf", tmp_path / "out.urdf", "--table", "--c", tmp_path / "c",
                   "--data", d / "train.csv", "--val", d / "val.csv", "--cameras", d / "cams.yaml")
    urdf = (tmp_path / "out.urdf").read_text()
    for marker in ("l1", "l2", "l3", "l4", "r1", "r2", "r3", "r4"):  # each marker a link of its own, on its hand
        side = "left" if marker[0] == "l" else "right"
        assert f'<link name="arm_{side}_5_link_{marker}"/>' in urdf
    assert "humanoid_calibration.h" in out["c"]["files"] and out["table"]
    # what the URDF leaves out (the coupled torso joint's term), scored on the images as evaluate scores them
    # (it refused the pixel files before)
    assert out["urdf"]["not_carried"]
    cost = out["urdf"]["cost"]
    scored = run_json("evaluate", d / "cal.json", d / "val.csv", "--cameras", d / "cams.yaml")
    assert abs(cost["held_out"]["calibration_rms_px"] - scored["after"]["rms_px"]) < 1e-9
    assert abs(cost["training"]["calibration_rms_px"] - identified["train"]["rms_px"]) < 1e-9
    for c in cost.values():
        assert 0 < c["gap_rms_mm"] <= c["gap_max_mm"] and c["exported_rms_px"] != c["calibration_rms_px"]


def test_check_a_tree_calibrated_from_pixels(tree, identified, checked):
    d = tree
    same = run_json("check", d / "cal.json", d / "new.csv", "--cameras", d / "cams.yaml", "--val", d / "val.csv",
                    "--tolerance-mm", "1")
    assert same["looks_like"]["kind"] == "as calibrated" and same["verdict"] == "pass" and not same["beyond_noise"]
    off = run_json("check", d / "cal.json", d / "off.csv", "--cameras", d / "cams.yaml", "--val", d / "val.csv")
    looks = off["looks_like"]
    assert off["beyond_noise"] and looks["kind"] == "joint" and looks["joint"] == "q10", looks
    assert abs(looks["offset"] + 1e-3) < 0.15e-3  # the reading is 1 mrad beyond the joint


def test_accuracy_over_a_volume_refuses_a_tree_in_one_line(tree, identified, tmp_path):
    d = tree
    (tmp_path / "volume.yaml").write_text("angle_unit: rad\njoints: {torso_1_joint: [-0.1, 0.1]}\n")
    line = _refused("accuracy", d / "cal.json", tmp_path / "volume.yaml", d / "train.csv", "--val", d / "val.csv",
                    "--cameras", d / "cams.yaml")
    assert "branched" in line and "evaluate" in line
