"""check and accuracy on images: new images of a calibrated robot against simulated truths (as calibrated,
a bumped camera, a robot whose joint reading drifted), through the cameras the calibration recorded."""
import contextlib
import io
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gecgen.fit.camera import calibration_of, fit_pixels
from gecgen.model.pixels import write_pixels
from gecgen.simulate.camera import simulate_pixels
from gecgen.verify.drift import check_pixels, pixel_reference

from test_camera import arm, hand_rig, world_rig  # noqa: F401 (arm is a fixture)

pytest.importorskip("cv2")


def _bumped(rig, name, rotvec=(0.002, -0.001, 0.0005), shift=(0.001, 0.0, 0.0005)):
    """The rig with camera `name` turned by rotvec (rad) and its frame shifted by `shift` (m)."""
    R, t = rig.poses[name]
    dR = Rotation.from_rotvec(rotvec).as_matrix()
    return replace(rig, poses={**rig.poses, name: (dR @ R, dR @ t + np.array(shift))})


@pytest.fixture(scope="module")
def world(arm):
    """Two fixed cameras, four markers: a calibration from 40 images, 10 held-out images for its
    reference and 10 poses to check at."""
    robot, rig, q, data = world_rig(arm, n=60)
    _, truth, model = arm
    train = data.subset(np.arange(40))
    fit = fit_pixels(robot, model, train, rig.cameras)
    cal = calibration_of(robot, model, fit, rig.cameras, None)
    rng = np.random.default_rng(11)
    ref = pixel_reference(cal, "cal", simulate_pixels(robot, truth, rig, q[40:50], 0.2, rng), rig.cameras, None)
    return robot, truth, rig, q[50:], cal, ref


def _check(world, rig=None, offset=None, reference=True, seed=0):
    """check_pixels of new images (noise drawn with `seed`: each test its own, whatever ran before)."""
    robot, truth, rig0, q, cal, ref = world
    rng = np.random.default_rng(seed)
    seen = simulate_pixels(robot, truth, rig or rig0, q if offset is None else q + offset, 0.2, rng)
    data = replace(seen, q=q)  # what the robot reads: offset is how far its joints are from the readings
    return check_pixels(cal, "cal", data, rig0.cameras, rig0.board, 1.0, ref if reference else None).to_dict()


def test_new_images_of_the_calibrated_robot_are_as_calibrated(world):
    out = [_check(world, seed=seed) for seed in range(3)]
    assert all(o["looks_like"] == {"kind": "as calibrated"} and not o["beyond_noise"] for o in out), out
    assert all(0.2 < o["rms_px"] < 0.4 and o["verdict"] == ("pass" if o["max_mm"] <= 1.0 else "fail") for o in out), out


def test_a_bumped_camera_is_named_and_where_it_went(world):
    out = _check(world, rig=_bumped(world[2], "cam1"))
    assert out["beyond_noise"] and out["looks_like"]["kind"] == "camera moved"
    assert out["looks_like"]["moved"] == ["cam1"]
    cam1, cam2 = out["poses_refitted"]
    # turned by |(2, -1, 0.5)| mrad = 0.131 deg: the refit finds it within the noise's reach
    assert abs(cam1["rotation_deg"] - 0.131) < 0.02 and cam1["rms_px_after"] < 0.4 < 3 < cam1["rms_px_before"]
    assert not cam2["moved"]


def test_a_drifted_joint_is_named_with_its_offset(world):
    out = _check(world, offset=5e-4 * np.eye(6)[1])
    looks = out["looks_like"]
    assert out["beyond_noise"] and looks["kind"] == "joint" and looks["joint"] == "q2"
    assert abs(looks["offset"] - 5e-4) < 0.5e-4
    # every camera refitted alone would explain it too: given as the other reading, not hidden
    assert "every camera moved" in looks["or"]


def test_the_base_joint_and_a_fixed_camera_cannot_be_told_apart_by_one_camera(world):
    """A base joint's offset turns the arm about the base axis: one camera's images see the same as the
    camera turning about that axis, and the check says both."""
    robot, truth, rig, q, cal, ref = world
    seen = simulate_pixels(robot, truth, rig, q + 5e-4 * np.eye(6)[0], 0.2, np.random.default_rng(0))
    one = replace(seen.subset(np.arange(seen.n_poses)), q=q)
    keep = one.camera == 0
    one = replace(one, camera=one.camera[keep], point=one.point[keep], uv=one.uv[keep], row=one.row[keep],
                  pose=one.pose[keep], cameras=("cam1",))
    out = check_pixels(cal, "cal", one, rig.cameras, None, None, ref).to_dict()
    assert out["looks_like"]["kind"] == "moved or joint" and out["looks_like"]["moved"] == ["cam1"]
    assert out["looks_like"]["joint"]["joint"] == "q1"


def test_a_camera_seen_at_too_few_points_is_not_refitted(world):
    """A camera with two image points in the check: its pose is not refitted (six unknowns), the others are."""
    robot, truth, rig, q, cal, ref = world
    seen = replace(simulate_pixels(robot, truth, rig, q, 0.2, np.random.default_rng(0)), q=q)
    keep = seen.camera == 0
    keep[np.flatnonzero(~keep)[:2]] = True
    seen = replace(seen, camera=seen.camera[keep], point=seen.point[keep], uv=seen.uv[keep], row=seen.row[keep],
                   pose=seen.pose[keep])
    out = check_pixels(cal, "cal", seen, rig.cameras, None, None, ref).to_dict()
    assert [p["name"] for p in out["poses_refitted"]] == ["cam1"] and out["looks_like"] == {"kind": "as calibrated"}


@pytest.fixture(scope="module")
def hand(arm):
    """A camera on the tool: a calibration from 30 images, 10 held-out images for its reference, 10 poses."""
    robot, truth, model = arm
    rig, train, new, data = hand_rig(arm, n=30)
    cal = calibration_of(robot, model, fit_pixels(robot, model, data, rig.cameras, rig.board), rig.cameras, rig.board)
    rng = np.random.default_rng(5)
    held = simulate_pixels(robot, truth, rig, new[:10], 0.2, rng)
    return robot, truth, rig, new[10:], cal, held, data


def data_of(hand):
    """The training images of the `hand` fixture."""
    return hand[-1]


def test_a_camera_on_the_tool_tells_itself_from_the_board(hand):
    robot, truth, rig, q, cal, held, _ = hand
    rng = np.random.default_rng(0)
    ref = pixel_reference(cal, "cal", held, rig.cameras, rig.board)
    out = {name: check_pixels(cal, "cal", simulate_pixels(robot, truth, r, q, 0.2, rng), rig.cameras,
                              rig.board, None, ref).to_dict()
           for name, r in (("same", rig), ("bumped", _bumped(rig, "cam")))}
    assert out["same"]["looks_like"]["kind"] == "as calibrated"
    assert out["bumped"]["looks_like"] == {**out["bumped"]["looks_like"], "kind": "camera moved", "moved": ["cam"]}
    # joint 2 read 0.5 mrad off: over these poses the board's refit explains the images as well as the joint's
    # offset does, and the check says both rather than choosing
    drift = replace(simulate_pixels(robot, truth, rig, q + 5e-4 * np.eye(6)[1], 0.2, rng), q=q)
    looks = check_pixels(cal, "cal", drift, rig.cameras, rig.board, None, ref).to_dict()["looks_like"]
    assert looks["kind"] == "moved or joint" and looks["moved"] == ["board"] and looks["joint"]["joint"] == "q2"
    assert abs(looks["joint"]["offset"] - 5e-4) < 0.5e-4


def test_check_with_cameras_from_the_command_line(hand, tmp_path):
    from conftest import run_json
    from gecgen.cli import main
    from gecgen.fit.calibration import save

    robot, truth, rig, q, cal, held, _ = hand
    rng = np.random.default_rng(0)
    save(cal, tmp_path / "cal.json")
    c = rig.cameras["cam"]
    (tmp_path / "cam.yaml").write_text(f"cameras:\n  cam: {{mount: tool, fx: {c.fx}, fy: {c.fy}, cx: {c.cx}, cy: "
                                       f"{c.cy}, distortion: {list(c.distortion)}, width: {c.width}, height: "
                                       f"{c.height}}}\n")
    (tmp_path / "board.yaml").write_text("type: chessboard\ncolumns: 9\nrows: 6\nsquare: 0.04\n")
    (tmp_path / "board30.yaml").write_text("type: chessboard\ncolumns: 9\nrows: 6\nsquare: 0.03\n")
    write_pixels(tmp_path / "val.csv", robot, held)
    write_pixels(tmp_path / "new.csv", robot, simulate_pixels(robot, truth, _bumped(rig, "cam"), q, 0.2, rng))
    rig_files = ["--cameras", tmp_path / "cam.yaml", "--board", tmp_path / "board.yaml"]
    out = run_json("check", tmp_path / "cal.json", tmp_path / "new.csv", *rig_files, "--val", tmp_path / "val.csv",
                   "--history", tmp_path / "h.csv")
    assert out["looks_like"]["kind"] == "camera moved" and out["looks_like"]["moved"] == ["cam"]
    assert out["next_step"].startswith("cam moved") and out["history"]["checks"] == 1
    assert out["judged_against"] == f"the held-out images {tmp_path / 'val.csv'}"
    for extra, message in ((["--baseline", tmp_path / "val.csv"], "--baseline is not supported with --cameras"),
                           (["--board", tmp_path / "board30.yaml"], "key 'square': 0.03 m against the calibration's")):
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            code = main(["check", str(tmp_path / "cal.json"), str(tmp_path / "new.csv"), *map(str, rig_files),
                         *map(str, extra)])
        assert code != 0 and message in err.getvalue(), err.getvalue()
        assert len(err.getvalue().strip().splitlines()) == 1, err.getvalue()
    # accuracy from a carried camera's images: its pose from the board places the targets at the held-out poses
    (tmp_path / "vol.yaml").write_text("angle_unit: deg\njoints: {a1: [-4, 4], a2: [-93, -87], a3: [-93, -87], "
                                       "a4: [-12, 12], a5: [50, 70], a6: [-15, 15]}\nsamples: 50\n")
    write_pixels(tmp_path / "train.csv", robot, data_of(hand))
    out = run_json("accuracy", tmp_path / "cal.json", tmp_path / "vol.yaml", tmp_path / "train.csv", "--val",
                   tmp_path / "val.csv", *rig_files, "--tolerance-mm", "1", "--draws", "400")
    by = out["measured_by"]
    assert by["points"] == 10 and by["images_left_out"] == 0 and by["method"].startswith("the carried camera's pose")
    assert 0 < by["std_mm_median"] <= by["std_mm_max"] < 2 and "not seen" in out["meaning"]
    assert out["measured"]["n"] + out["measured"]["outside"] == 10 and out["bound_mm"] > 0


@pytest.mark.parametrize("mount", ["world", "tool"])
def test_image_positions_of_the_calibrations_own_model_are_where_it_puts_the_targets(mount, world, hand):
    """Noise-free images of what the calibration predicts (its model, its recorded cameras and board): the
    positions triangulated from two fixed cameras, or placed by the carried camera's PnP pose through the
    board and the camera's pose on the tool, are where the calibrated model puts the targets."""
    from gecgen.fit.camera import fitted_tools, recorded_problem
    from gecgen.verify.images import from_carried_camera, triangulate

    robot, truth, rig, q, cal, *_ = world if mount == "world" else hand
    seen = simulate_pixels(robot, truth, rig, q, 0.2, np.random.default_rng(1))
    problem, g = recorded_problem(cal, "cal", seen, rig.cameras, rig.board)
    exact = replace(seen, uv=seen.uv - problem.residual(g, cal.c))
    measure = triangulate if mount == "world" else from_carried_camera
    data, y, info = measure(cal, "cal", exact, rig.cameras, rig.board, 0.2)
    T = fitted_tools(cal.robot, cal.model, cal.c, data.q)[data.pose]
    points = np.array(list(cal.robot.targets.values()), float)[data.target]
    model = np.einsum("rij,rj->ri", T[:, :3, :3], points) + T[:, :3, 3]
    assert info.points == len(y) > 0 and np.abs(y - model).max() < 1e-7


def test_accuracy_from_images_counts_samples_not_compensated_and_bounds_against_the_cameras(arm, world, tmp_path):
    """A statement from images: over a volume through the stretched elbow it says at how many samples
    compensation fails; over one away from it, the coefficients' draws taken with the first camera's pose
    (the error against the cameras, where the images measure it) are well below the same draws in the
    robot's own frame, which hold where the base sits against the cameras (docs/camera.md measures both
    against truths); a wrong sign of the camera's rows would add to them instead."""
    from gecgen.fit.camera import image_covariance, recorded_problem
    from gecgen.model.volume import load_volume
    from gecgen.runtime.compiled import FAILED
    from gecgen.verify.images import accuracy_from_images
    from gecgen.verify.volume import held_columns, point_rows, worst_over_draws

    from test_camera import world_rig

    robot, truth, rig, q, _, _ = world
    rng = np.random.default_rng(0)
    train = world_rig(arm, n=60)[3]  # the fixture's images, all 60: twice as many poses as coefficients
    cal = calibration_of(robot, arm[2], fit_pixels(robot, arm[2], train, rig.cameras), rig.cameras, None)
    val = simulate_pixels(robot, truth, rig, q, 0.2, rng)
    said = {}
    for name, a3 in (("away", "[-110, -100]"), ("through", "[-95, -85]")):
        (tmp_path / f"{name}.yaml").write_text(f"angle_unit: deg\ntargets: [m1, m2, m3, m4]\njoints: {{a1: [-8, 8], "
                                               f"a2: [-88, -72], a3: {a3}, a4: [-40, 40], a5: [30, 60], "
                                               f"a6: [-60, 60]}}\nsamples: 40\n")
        volume = load_volume(tmp_path / f"{name}.yaml", cal.robot)
        samples, st, cm, _ = accuracy_from_images(cal, "cal", volume, train, val, rig.cameras, None, 1.0, 0.95, 400,
                                                  np.random.default_rng(0))
        failed = int(np.isin(cm.compensate(samples.q, samples.w, None, cal.c)[1], FAILED).sum())
        said[name] = (failed, samples, st, cm)
    failed, samples, st, _ = said["through"]
    n = len(samples.q)
    assert failed > 0 and any(f"does not converge at {failed} of {n} samples" in r for r in st.reasons), st.reasons
    failed, samples, st, cm = said["away"]
    columns = held_columns(cal)
    problem, g = recorded_problem(cal, "cal", train, rig.cameras, None)
    cov = image_covariance(problem, g, cal.c, np.array(columns), cal.report.get("loss", "cauchy"))
    G = point_rows(cm, samples, cal.c, columns)
    robot_frame = 1e3 * np.quantile(worst_over_draws(G, cov, np.zeros((n, 3, 1)), 400, rng)[1], 0.95)
    assert failed == 0 and 0 < st.parametric_mm < 0.5 * robot_frame, (st.parametric_mm, robot_frame)


@pytest.mark.parametrize("command", [["evaluate", "cal.json", "new.csv"],
                                     ["check", "cal.json", "new.csv", "--noise-mm", "0.1"],
                                     ["accuracy", "cal.json", "volume.yaml", "new.csv", "--noise-mm", "0.1"]])
def test_a_board_without_cameras_is_refused_before_anything_else(command, tmp_path, capsys):
    """--board alone, with an option the image path would refuse too and files that do not exist: the one
    line names the missing --cameras, not the option nor the files."""
    from gecgen.cli import main

    (tmp_path / "board.yaml").write_text("type: chessboard\ncolumns: 9\nrows: 6\nsquare: 0.04\n")
    argv = [command[0], *(str(tmp_path / a) if "." in a and not a[0].isdigit() else a for a in command[1:])]
    assert main([*argv, "--board", str(tmp_path / "board.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"gecgen {command[0]}: --board names the board a carried camera sees: give --cameras too"], err
