"""diagnose on image points (`gecgen diagnose --cameras`): a gravity-compliant joint in a simulated truth is
traced from pixels, and the held-out images are then as well explained as by a fit with the truth's model;
what the pixel path does not take is refused in one line."""
import contextlib
import io
import json
import re
from pathlib import Path

import pytest

from conftest import FIXED_CAMERAS as CAMERAS, ROBOTS, run_json

pytest.importorskip("cv2")

#: robots/industrial6r.truth.yaml with one gravity-compliant joint: the shoulder, 3e-6 rad per N m
TRUTH = """seed: 7
gravity: [0, 0, -9.81]
constant: {translation_std: 5.0e-4, rotation_std: 3.0e-4}
joint_offsets: {std: 3.0e-4}
masses:
  - {frame: 2, mass: 250, at: [-0.575, 0, 0]}
  - {frame: 4, mass: 180, at: [0, 0, 0]}
sources:
  - {type: compliance, joint: 2, compliance: 3.0e-6}
"""
#: the truth's structure: constant errors and joint 2's angle error linear in its gravity torque
ORACLE = "default: ['1']\nframes:\n  2: {er: ['1', " + ", ".join(f"'gravity(q2,{k})'" for k in range(1, 11)) + "]}\n"


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """Two fixed cameras seeing four markers on the tool of the elastic truth: training and held-out pixel
    files, the shoulder and elbow swept by +-25 deg (their gravity torque must vary to be seen)."""
    d = tmp_path_factory.mktemp("elastic")
    robot = (ROBOTS / "industrial6r.yaml").read_text()
    markers = "  m1: [0.15, 0.15, 0.1]\n  m2: [-0.15, 0.15, 0.1]\n  m3: [-0.15, -0.15, 0.1]\n  m4: [0.15, -0.15, 0.1]"
    (d / "arm.yaml").write_text(re.sub(r"(?m)^  smr: .*$", markers, robot))
    (d / "cams.yaml").write_text(CAMERAS)
    (d / "truth.yaml").write_text(TRUTH)
    (d / "oracle.errors.yaml").write_text(ORACLE)
    (d / "board.yaml").write_text("type: chessboard\ncolumns: 9\nrows: 6\nsquare: 0.04\n")
    run_json("simulate", d / "arm.yaml", "--truth", d / "truth.yaml", "--cameras", d / "cams.yaml", "--eye",
             "cam1=1.9,-2.4,1.7", "--eye", "cam2=1.9,2.4,1.7", "--look-at", "2,0,1", "--home",
             "0,-1.396,-1.745,0,0.524,0", "--span", "0.21,0.44,0.44,1.05,0.7,1.57", "--poses", "40", "--val-poses",
             "30", "--noise-px", "0.1", "--seed", "2", "-o", d / "train.csv", "--val-out", d / "val.csv")
    return d


@pytest.fixture(scope="module")
def floor(rig):
    """The held-out images' residual (`evaluate`'s after: px and mm at the target) of a fit of the training
    images with the truth's structure."""
    d = rig
    run_json("identify", d / "arm.yaml", d / "train.csv", "--errors", d / "oracle.errors.yaml", "--cameras",
             d / "cams.yaml", "--noise-px", "0.1", "-o", d / "oracle.json")
    return run_json("evaluate", d / "oracle.json", d / "val.csv", "--cameras", d / "cams.yaml")["after"]


def test_diagnose_traces_a_gravity_compliant_joint_from_pixels_to_the_oracles_floor(rig, floor):
    d = rig
    pixels = ["--cameras", d / "cams.yaml"]
    out = run_json("diagnose", d / "arm.yaml", d / "train.csv", "--val", d / "val.csv", "--errors",
                   ROBOTS / "constant.errors.yaml", *pixels, "--noise-px", "0.1", "-o", d / "found.errors.yaml",
                   "--report", d / "report")
    assert out["measurement"] == "pixels" and out["effects"], out["rounds"]
    # joint 2's angle error in joint 2's gravity load (its torque's terms, or its frame's moment about the axis)
    assert any(e["error"] == "2.er" and all(re.fullmatch(r"gravity\((q2|2,mz),\d+\)", t) for t in e["terms"])
               for e in out["effects"]), [(e["error"], e["terms"]) for e in out["effects"]]
    assert out["remaining"]["covered"]
    before, after = out["before"], out["after"]
    # the declared model is well above the floor, the diagnosed one within 1.2x of it, in mm at the target and px
    assert before["val_rms_mm"] > 1.3 * floor["rms_mm_at_target"] and before["val_rms_px"] > 1.3 * floor["rms_px"]
    assert after["val_rms_mm"] < 1.2 * floor["rms_mm_at_target"] and after["val_rms_px"] < 1.2 * floor["rms_px"]
    assert "--cameras" in out["next"] and Path(out["errors_out"]).exists()
    text = Path(out["report"]).read_text()
    assert "# gecgen diagnose: industrial6r from image points" in text and "## What diagnose added" in text
    assert "`2.er` <- `gravity(" in text


def test_calibrate_with_cameras_chooses_the_diagnosed_model_and_delivers_it(rig, floor):
    """calibrate on the same images: the diagnosed candidate (joint 2's gravity load added) wins the
    cross-validation over the constant errors, scores the validation images within 1.2x the floor, and the
    folder holds what calibrate writes for a tracker (calibration, error model, code, report)."""
    d = rig
    out = run_json("calibrate", d / "arm.yaml", d / "train.csv", "--val", d / "val.csv", "--models",
                   "geometric,diagnosed", "--cameras", d / "cams.yaml", "--noise-px", "0.1", "-o", d / "cal")
    assert out["model"] == "diagnosed" and out["measurement"] == "pixels", out["candidates"]
    cv = {r["model"]: r["cv_rms_mm"] for r in out["candidates"]}
    assert cv["diagnosed"] < 0.9 * cv["geometric"]
    assert any(e["error"] == "2.er" for e in out["effects"])
    assert out["val"]["rms_mm_at_target"] < 1.2 * floor["rms_mm_at_target"] < out["val_before"]["rms_mm_at_target"]
    assert all(Path(f).exists() for f in out["files"].values())
    # the second camera's pose against the first's, 1 sigma, as the calibration records it
    stated = out["camera_uncertainty"]
    assert list(stated["cameras"]) == ["cam2"] and stated["cameras"]["cam2"]["relative_to"] == "cam1"
    assert 0 < stated["cameras"]["cam2"]["translation_mm"] < 10 and 0 < stated["cameras"]["cam2"]["rotation_mrad"] < 10
    assert json.loads(Path(out["files"]["calibration"]).read_text())["camera_uncertainty"] == stated
    text = Path(out["files"]["report"]).read_text()
    assert "# gecgen calibrate: industrial6r from image points" in text and "Chosen: `diagnosed`." in text
    scored = run_json("evaluate", out["files"]["calibration"], d / "val.csv", "--cameras", d / "cams.yaml")
    assert scored["after"]["rms_px"] == pytest.approx(out["val"]["rms_px"], rel=1e-6)
    # the calibration records its validation images' residual, which check --cameras judges new images against
    checked = run_json("check", out["files"]["calibration"], d / "train.csv", "--cameras", d / "cams.yaml")
    assert checked["judged_against"] == f"the calibration's validation images ({d / 'val.csv'})"
    assert checked["reference_sigma_px"] == pytest.approx(out["val"]["rms_px"] / 2 ** 0.5, rel=1e-9)
    assert checked["looks_like"] == {"kind": "as calibrated"}


@pytest.mark.parametrize("extra, message", [
    (["--noise-mm", "0.1"], "--noise-mm is not supported with --cameras"),
    (["--register", "val", "--val", "V"], "--register is not supported with --cameras"),
    (["--board", "board.yaml"], "the cameras are fixed (mount: world) and see the robot's targets: a board goes "
                                "with a camera on the tool; leave out --board"),
])
def test_diagnose_with_cameras_refuses_what_it_does_not_take_in_one_line(rig, extra, message):
    from gecgen.cli import main

    d = rig
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["diagnose", str(d / "arm.yaml"), str(d / "train.csv"), "--cameras", str(d / "cams.yaml"),
                     *(str(d / a) if a.endswith(".yaml") else a for a in extra), "-o", str(d / "x.errors.yaml")]) != 0
    assert message in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1


def test_a_board_without_cameras_and_a_pixel_file_without_them_are_refused_in_one_line(rig):
    """diagnose with a board and no cameras, a pixel file without cameras, and a pixel calibration given to
    check and accuracy: one line each, naming what to give or use."""
    from gecgen.cli import main

    d = rig
    for args, message in ((["--board", str(d / "b.yaml")], "give --cameras too"),
                          (["--refine-intrinsics"], "--refine-intrinsics refines the intrinsics of the cameras of "
                                                    "image points: give --cameras too"),
                          ([], "which identify, diagnose, calibrate, redundancy, evaluate, check, accuracy and export --data read")):
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            assert main(["diagnose", str(d / "arm.yaml"), str(d / "train.csv"), *args]) != 0
        assert message in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1
    # a pixel calibration given to the commands that compare tracker points with a tracker calibration
    run_json("identify", d / "arm.yaml", d / "train.csv", "--errors", ROBOTS / "constant.errors.yaml", "--cameras",
             d / "cams.yaml", "-o", d / "plain.json")
    run_json("simulate", d / "arm.yaml", "--truth", d / "truth.yaml", "--poses", "10", "-o", d / "tracker.csv")
    for command in (["check", d / "plain.json", d / "tracker.csv"],
                    ["accuracy", d / "plain.json", ROBOTS / "pps.volume.yaml", d / "tracker.csv"]):
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            assert main(list(map(str, command))) != 0
        assert f"a calibration from image points; {command[0]} takes a calibration from tracker points with " \
               f"tracker data, or this one with images: gecgen {command[0]} " in err.getvalue()
        assert len(err.getvalue().strip().splitlines()) == 1


def test_the_loop_refines_the_intrinsics_when_asked_and_scores_held_out_images_through_them(rig, floor):
    """diagnose's and calibrate's fits with --refine-intrinsics (`ImagePoints(intrinsics=True)`): from a camera
    file 1 % off in fx (and fy, cx) the held-out images come back to the true intrinsics' residual, where the
    file's intrinsics leave them well above it; the screening's system has the intrinsics' columns."""
    import numpy as np

    from gecgen.loop.pixels import ImagePoints
    from gecgen.model import load_robot
    from gecgen.model.cameras import read_cameras
    from gecgen.model.pixels import read_pixels
    from gecgen.symbolic.terms import load_error_model

    d = rig
    (d / "off.yaml").write_text(CAMERAS.replace("fx: 1800, fy: 1800, cx: 640", "fx: 1818, fy: 1791, cx: 646", 1))
    robot = load_robot(d / "arm.yaml")
    model = load_error_model(d / "oracle.errors.yaml", robot)
    off = read_cameras(d / "off.yaml")
    train, val = (read_pixels(d / f, robot, off) for f in ("train.csv", "val.csv"))
    scored = {}
    for refine in (False, True):
        measure = ImagePoints(robot, off, None, 0.1, intrinsics=refine)
        rnd = measure.fit(robot, model, train)
        scored[refine] = measure.scores(rnd, val)["val_rms_px"]
    assert scored[True] < 1.1 * floor["rms_px"] < 2 * 1.1 * floor["rms_px"] < scored[False], scored
    A = measure.system(rnd, train)[0]
    assert A.shape[1] == len(rnd.fit.g) + len(rnd.fit.kept) and len(rnd.fit.g) == 2 * (6 + 9)
    assert np.isfinite(A).all()


#: a volume about the training poses of `rig` (the wrist kept away from a5 = 0, where it is singular)
VOLUME = """angle_unit: deg
targets: [m1, m2, m3, m4]
joints: {a1: [-9, 9], a2: [-100, -75], a3: [-115, -80], a4: [-45, 45], a5: [15, 60], a6: [-80, 80]}
samples: 100
"""


def test_accuracy_with_cameras_states_the_markers_accuracy_from_triangulated_held_out_images(rig, floor):
    """accuracy --cameras: the held-out markers, seen by both fixed cameras, are triangulated through the
    cameras as the calibration placed them (the same points as OpenCV's triangulatePoints from the two
    cameras' projection matrices and undistorted points), and the statement is read from them, saying
    what its mm mean; one camera alone, a tracker option and no held-out images are refused in one line."""
    import cv2
    import numpy as np

    from gecgen.cli import main
    from gecgen.fit.calibration import load
    from gecgen.fit.camera import recorded_problem
    from gecgen.model.cameras import read_cameras
    from gecgen.model.pixels import read_pixels, write_pixels
    from gecgen.verify.images import triangulate

    d = rig
    (d / "vol.yaml").write_text(VOLUME)
    out = run_json("accuracy", d / "oracle.json", d / "vol.yaml", d / "train.csv", "--val", d / "val.csv",
                   "--cameras", d / "cams.yaml", "--tolerance-mm", "2", "--draws", "400", "--report", d / "acc")
    by = out["measured_by"]
    assert f"From images: {out['meaning']}." in (d / "acc" / "report.md").read_text()
    assert out["measurement"] == "pixels" and "not what one camera alone sees" in out["meaning"]
    assert by["points"] == 4 * 30 and by["single_camera_points"] == 0 and 0 < by["std_mm_median"] < 1
    assert out["verdict"] in ("meets", "cannot tell", "does not meet") and out["bound_mm"] > out["unmodelled_rms_mm"]
    assert any("triangulated from the calibration's cameras" in r for r in out["reasons"])
    assert "--noise-mm" not in out["next_step"] and "--cameras" in out["next_step"]
    # the triangulated points against OpenCV's, pose by pose
    cal, cams = load(d / "oracle.json"), read_cameras(d / "cams.yaml")
    val = read_pixels(d / "val.csv", cal.robot, cams)
    data, y, _ = triangulate(cal, "cal", val, cams, None, cal.report["sigma_px"])
    problem, g = recorded_problem(cal, "cal", val, cams, None)
    (R1, t1), (R2, t2) = problem.unpack(g)[0]
    k = 7  # a row: its pose and marker, seen by each camera
    rows = [np.flatnonzero((val.pose == data.pose[k]) & (val.point == val.points.index(list(cal.robot.targets)[
        data.target[k]])) & (val.camera == c))[0] for c in (0, 1)]
    und = [cv2.undistortPoints(val.uv[r].reshape(1, 1, 2), problem.cams[c].K, np.array(problem.cams[c].distortion))
           .reshape(2, 1) for c, r in enumerate(rows)]
    X = cv2.triangulatePoints(np.column_stack([R1, t1]), np.column_stack([R2, t2]), *und).ravel()
    X = X[:3] / X[3]
    # OpenCV's is the algebraic least squares, ours the reprojection error's: the same point to a small share of
    # its noise, and ours reprojects at least as close to the pixels
    assert 1e3 * np.linalg.norm(X - y[k]) < 0.1 * by["std_mm_median"]
    reprojected = [sum(np.sum((val.uv[r] - problem.cams[c].project((R @ P + t)[None])[0]) ** 2)
                       for c, (r, (R, t)) in enumerate(zip(rows, ((R1, t1), (R2, t2))))) for P in (X, y[k])]
    assert reprojected[1] <= reprojected[0]
    # one camera's images: no position in mm
    one = val.subset(np.arange(val.n_poses))
    keep = one.camera == 0
    from dataclasses import replace
    write_pixels(d / "one.csv", cal.robot, replace(one, pose=one.pose[keep], camera=one.camera[keep],
                                                   point=one.point[keep], uv=one.uv[keep], row=one.row[keep]))
    for extra, message in (([d / "one.csv", "--cameras", d / "cams.yaml"], "no marker is seen by two cameras"),
                           ([d / "val.csv", "--cameras", d / "cams.yaml", "--noise-mm", "0.1"],
                            "--noise-mm is not supported with --cameras"),
                           ([d / "val.csv", "--cameras", d / "cams.yaml", "--board", d / "board.yaml", "--noise-mm",
                             "0.1"], "--noise-mm is not supported with --cameras")):
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            assert main(["accuracy", str(d / "oracle.json"), str(d / "vol.yaml"), str(d / "train.csv"), "--val",
                         *map(str, extra)]) != 0
        assert message in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1, err.getvalue()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert main(["accuracy", str(d / "oracle.json"), str(d / "vol.yaml"), str(d / "train.csv"), "--cameras",
                     str(d / "cams.yaml")]) != 0
    assert "give them as --val PIXELS.csv" in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1
