"""Pose measurements (position and orientation of a measured frame): the orientation columns, their
refusals, the tetrahedron of virtual targets, identification on a simulated truth (more
coefficients identifiable than from points, orientation residuals checked against scipy on the
exact numpy chain) and figaroh's real UR10 tool poses."""
import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from conftest import ROBOTS
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from gecgen.cli import main
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import tool_pose
from gecgen.model.measurements import read_measurements, write_measurements
from gecgen.model.pose_targets import as_points, with_pose_targets
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import identify, row_errors, summary
from gecgen.simulate import load_truth, random_design, simulate

UR10 = ROBOTS.parent / "tests" / "data" / "ur10"
HEAD = "pose,q1,q2,q3,q4,q5,q6,target,x,y,z"
ROW = "0,0,0,0,0,0,0,t1,0.1,0.2,0.3"


def read(tmp_path, header, *rows):
    path = tmp_path / "m.csv"
    path.write_text("\n".join([f"{HEAD},{header}", *(f"{ROW.replace('0,', f'{k},', 1)},{r}" for k, r in
                                                      enumerate(rows))]) + "\n")
    return read_measurements(path, load_robot(ROBOTS / "puma560.yaml"))


def test_the_three_conventions_give_scipy_s_rotations_and_round_trip(tmp_path):
    angles = np.array([10.0, -20.0, 30.0])
    R = Rotation.from_euler("xyz", angles, degrees=True)
    w, x, y, z = R.as_quat()[[3, 0, 1, 2]].tolist()
    cases = {"euler_xyz_deg_1,euler_xyz_deg_2,euler_xyz_deg_3": ",".join(map(str, angles)),
             "euler_ZYX_rad_1,euler_ZYX_rad_2,euler_ZYX_rad_3": ",".join(map(repr, np.radians(angles[::-1]).tolist())),
             "quat_w,quat_x,quat_y,quat_z": f"{w!r},{x!r},{y!r},{z!r}",
             ",".join(f"rot_{i}{j}" for i in "123" for j in "123"): ",".join(map(repr, R.as_matrix().ravel().tolist()))}
    for header, cells in cases.items():
        data = read(tmp_path, header, cells, ",".join([""] * len(cells.split(","))))
        assert np.abs(data.orientation[0] - R.as_matrix()).max() < 1e-12, header
        assert np.isnan(data.orientation[1]).all() and data.aux_names == ()  # a position-only row; not aux
    write_measurements(tmp_path / "out.csv", load_robot(ROBOTS / "puma560.yaml"), data)
    again = read_measurements(tmp_path / "out.csv", load_robot(ROBOTS / "puma560.yaml"))
    assert np.abs(again.orientation[0] - R.as_matrix()).max() < 1e-15 and np.isnan(again.orientation[1]).all()


@pytest.mark.parametrize("header, cells, expect", [
    ("quat_w,quat_x,quat_y,quat_z", "1,0,0,", "row 2, column 'quat_z': empty"),
    ("quat_w,quat_x,quat_y,quat_z", "1.01,0,0,0", "row 2, columns quat_w..quat_z: quaternion of norm 1.01"),
    ("quat_w,quat_x,quat_y,quat_z", "nan,0,0,0", "row 2, column 'quat_w': 'nan' is not finite"),
    (",".join(f"rot_{i}{j}" for i in "123" for j in "123"), "1,0,0,0,1,0,0,0,-1", "row 2, columns rot_11..rot_33: "
                                                                                  "not a rotation matrix"),
    (",".join(f"rot_{i}{j}" for i in "123" for j in "123"), "1,0.1,0,0,1,0,0,0,1", "not a rotation matrix"),
    ("euler_xyz_deg_1,euler_xyz_deg_2", "1,2", "missing column 'euler_xyz_deg_3'"),
    ("euler_xxy_deg_1,euler_xxy_deg_2,euler_xxy_deg_3", "1,2,3", "not an Euler sequence"),
    ("quat_w,quat_x,quat_y,quat_z,euler_xyz_deg_1,euler_xyz_deg_2,euler_xyz_deg_3", "1,0,0,0,0,0,0", "two conventions"),
    ("rot_speed", "3", "column 'rot_speed' starts like an orientation column"),
])
def test_bad_orientations_are_refused_in_one_line(tmp_path, header, cells, expect):
    with pytest.raises(ModelError) as err:
        read(tmp_path, header, cells)
    assert expect in str(err.value) and "\n" not in str(err.value), str(err.value)


QUATERNION_CELLS = st.one_of(st.floats(-1.2, 1.2).map(repr), st.sampled_from(["", " ", "nan", "inf", "1e308", "x"]))


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(*[QUATERNION_CELLS] * 4), min_size=1, max_size=4), st.booleans())
def test_any_quaternion_cells_read_as_rotations_or_are_refused_in_one_line(tmp_path, rows, unit):
    """Whatever the cells (unit-normalised quaternions half the time, so that both outcomes are
    common): every orientation read is a rotation or NaN, or the file is refused in one line."""
    cells = []
    for row in rows:
        q = np.array([float(c) if c.strip() not in ("", "x") else np.nan for c in row])
        if unit and np.isfinite(q).all() and 0 < np.abs(q).max() < 2:
            row = tuple(map(repr, (q / np.linalg.norm(q)).tolist()))
        cells.append(",".join(row))
    try:
        data = read(tmp_path, "quat_w,quat_x,quat_y,quat_z", *cells)
    except ModelError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(str(tmp_path)), str(exc)
        return
    if data.orientation is not None:
        R = data.orientation[~np.isnan(data.orientation[:, 0, 0])]
        assert np.abs(np.einsum("nki,nkj->nij", R, R) - np.eye(3)).max() < 1e-12 and (np.linalg.det(R) > 0).all()


def test_a_frame_s_vertices_weigh_position_and_orientation_apart(rng):
    """Four vertices at r = L sqrt(3/2): their weighted squared residuals add up to exactly
    |e|^2 + L^2 (2 sin(theta/2))^2, and position and angle come back exactly (against scipy)."""
    robot = with_pose_targets(load_robot(ROBOTS / "puma560.yaml"), 0.2)
    from gecgen.model.measurements import Measurements

    n = 50
    Rm, Rp = Rotation.random(n, random_state=1), Rotation.random(n, random_state=2)
    pm, pp = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    data = Measurements(np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((n, 0)), (), np.arange(n), np.arange(n),
                        np.zeros(n, int), pm, "x", orientation=Rm.as_matrix())
    model = Measurements(np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((n, 0)), (), np.arange(n), np.arange(n),
                         np.zeros(n, int), pp, "x", orientation=Rp.as_matrix())
    y, p = as_points(robot, data), as_points(robot, model)
    assert len(y.xyz) == 4 * n and np.array_equal(y.row, np.repeat(np.arange(n) + 2, 4))
    rows = y.rows
    position, angle, length = rows.errors(y.xyz, p.xyz)
    theta = (Rm * Rp.inv()).magnitude()
    assert np.allclose(position, np.linalg.norm(pm - pp, axis=1), rtol=0, atol=1e-12)
    assert np.allclose(angle, theta, rtol=0, atol=1e-9)
    assert np.allclose(length ** 2, np.sum((pm - pp) ** 2, 1) + (0.2 * 2 * np.sin(theta / 2)) ** 2, rtol=1e-12)
    assert np.array_equal(rows.row_dof, np.full(n, 6.0))


def test_the_rows_of_pose_data_follow_its_subsets(rng):
    """The measured rows are part of the data: pose data turned into points and then cut to some
    poses or points group exactly as the same cut turned into points (a frame's four vertices stay
    one row; a position-only row stays a row of its own)."""
    robot = with_pose_targets(load_robot(ROBOTS / "puma560.yaml"))
    from gecgen.model.measurements import Measurements

    n = 12
    orientation = Rotation.random(2 * n, random_state=3).as_matrix()
    orientation[::3] = np.nan  # every third row measures its position only
    data = Measurements(np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((n, 0)), (), np.arange(n),
                        np.repeat(np.arange(n), 2), np.tile([0, 1], n),
                        rng.normal(size=(2 * n, 3)), "x", orientation=orientation)
    poses = np.array([1, 4, 5, 9])
    cut, whole = as_points(robot, data.subset(poses)), as_points(robot, data).subset(poses)
    assert np.array_equal(whole.rows.group, cut.rows.group) and np.array_equal(whole.rows.vertex, cut.rows.vertex)
    assert np.array_equal(whole.rows.row_dof, np.where(np.isnan(data.subset(poses).orientation[:, 0, 0]), 3.0, 6.0))
    keep = whole.target == 0  # a branch's points: the rows of the plain points of target 0 only
    assert np.array_equal(whole.rows_of(keep).rows.vertex, np.full(keep.sum(), -1))


def test_robots_that_differ_only_in_their_targets_compile_apart():
    """The compiled code is cached by content, and the targets are content beyond the robot file: a
    derived robot (virtual targets) or placed targets once loaded the library of the robot file's
    targets, and with it their positions. The run's cache serves: the robot file's library is
    the one the other tests built, and a key that left the targets out would load it here too."""
    from gecgen.fit.placement import with_targets

    robot = load_robot(UR10 / "ur10.yaml")
    model = load_error_model(None, robot)
    q = np.zeros((1, 6))
    flange = CompiledModel(robot, model).nominal_targets(q)[0, 0]
    moved = CompiledModel(with_targets(robot, {"flange": (0.1, 0.0, 0.0)}), model).nominal_targets(q)[0, 0]
    turned = tool_pose(robot, q)[0, :3, 0]  # the tool's x axis in the world
    assert np.allclose(moved - flange, 0.1 * turned, rtol=0, atol=1e-12)
    fitted = with_pose_targets(robot, 0.2)
    vertices = CompiledModel(fitted, model).nominal_targets(q)[0]
    assert np.allclose(vertices[0], flange)
    assert np.allclose(np.linalg.norm(vertices[1:] - flange, axis=1), 0.2 * np.sqrt(1.5))


@pytest.fixture(scope="module")
def ur10_sim():
    """UR10 measured at the flange centre, on joint 6's axis, with a constant-error truth: 40
    training and 40 validation poses with orientations (30 um, 0.3 mrad noise)."""
    robot = load_robot(UR10 / "ur10.yaml")
    truth = load_truth({"seed": 4, "constant": {"translation_std": 1e-3, "rotation_std": 1e-3},
                        "joint_offsets": {"std": 1e-3}, "noise": {"tracker": 3e-5, "orientation": 3e-4}}, robot)
    rng = np.random.default_rng(7)
    train = simulate(robot, truth, random_design(robot, 40, rng), rng, orientation=True)
    val = simulate(robot, load_truth({**truth.spec, "noise": {}}, robot), random_design(robot, 40, rng), rng,
                   orientation=True)
    return robot, load_error_model(None, robot), truth, train, val


def test_orientations_identify_what_a_point_on_the_last_axis_cannot(ur10_sim):
    """Points alone: 25 identifiable (the rotation about joint 6's axis is invisible); with
    orientations 30 (4 x 6 + 6, full pose). The fit then predicts new poses' positions and
    orientations to the noise, and its orientation residuals are those of the exact numpy chain
    (scipy Rotation), not of the generated code's vertices."""
    robot, model, truth, train, val = ur10_sim
    fitted = with_pose_targets(robot)
    cm = CompiledModel(fitted, model)
    fit = identify(cm, as_points(fitted, train))
    assert fit.trustworthy and fit.redundancy.n_identifiable == 30, fit.failures
    points = identify(CompiledModel(robot, model), train)
    assert points.redundancy.n_identifiable == 25
    gained = {e.param for e in points.redundancy.eliminated} - {e.param for e in fit.redundancy.eliminated}
    assert len(gained) == 5 and {"6.es:1", "6.er:1", "6.ep:1"} <= gained  # the last frame's rotations
    # the sigma per degree of freedom is the noise when L * orientation noise = position noise (0.1 m x 0.3 mrad)
    assert 0.8 < fit.sigma_m / 3e-5 < 1.2
    assert abs(fit.train["rot_rms_mrad"] - 0.3 * np.sqrt(3)) < 0.1 and fit.before["rot_rms_mrad"] > 1.5

    # independent: the exact chain in numpy at the fitted generalized errors, turned into the tracker frame
    y = as_points(fitted, val)
    frame = fit.registration
    position, angle, _ = row_errors(cm, y, frame.to_world(y.xyz), fit.c)
    eps = cm.eps(val.q, val.w, np.zeros((val.n_poses, 0)), fit.c)
    T = tool_pose(robot, val.q, eps)
    R_model = (frame.R if frame.applied else np.eye(3)) @ T[val.pose, :3, :3]
    theta = (Rotation.from_matrix(val.orientation) * Rotation.from_matrix(R_model).inv()).magnitude()
    assert np.abs(angle - theta).max() < 1e-9
    p_model = T[val.pose, :3, 3] @ (frame.R.T if frame.applied else np.eye(3)) + (frame.t if frame.applied else 0)
    assert np.abs(position - np.linalg.norm(val.xyz - p_model, axis=1)).max() < 1e-9
    # noise-free validation poses: predicted better than one measurement resolves (0.052 mm, 0.52 mrad rms)
    assert 1e3 * np.sqrt(np.mean(position ** 2)) < 0.04 and 1e3 * np.sqrt(np.mean(angle ** 2)) < 0.2
    # and from noise-free training data the truth comes back exactly
    exact = identify(cm, as_points(fitted, simulate(robot, load_truth({**truth.spec, "noise": {}}, robot),
                                                    random_design(robot, 40, np.random.default_rng(3)),
                                                    np.random.default_rng(3), orientation=True)))
    position, angle, _ = row_errors(cm, y, exact.to_world(y), exact.c)
    assert position.max() < 1e-12 and angle.max() < 1e-12


def test_a_frame_off_by_30_mrad_is_one_outlier_and_position_only_rows_mix_in(ur10_sim):
    """One row's orientation turned by 30 mrad (100 robust sigmas) is listed once, by its file row,
    with its orientation error, and barely moves the fit; rows without an orientation in the same
    data count as points."""
    robot, model, _, train, val = ur10_sim
    fitted = with_pose_targets(robot)
    cm = CompiledModel(fitted, model)
    orientation = train.orientation.copy()
    orientation[11] = Rotation.from_rotvec([0.03, 0, 0]).as_matrix() @ orientation[11]
    orientation[20:30] = np.nan  # position only
    data = as_points(fitted, dataclasses.replace(train, orientation=orientation, row=np.arange(40) + 2))
    fit = identify(cm, data)
    assert fit.trustworthy and fit.redundancy.n_identifiable == 30
    assert [(o.row, o.pose, o.target) for o in fit.outliers] == [(13, 11, "flange")]
    assert abs(fit.outliers[0].rotation_mrad - 30) < 1 and fit.outliers[0].weight < 0.02
    # 30 frames and 10 points, the outlier's six counted by its weight
    assert fit.measured_dof == pytest.approx(30 * 6 + 10 * 3 - 6 * (1 - fit.outliers[0].weight), rel=1e-12)
    y = as_points(fitted, val)
    assert summary(*row_errors(cm, y, fit.to_world(y), fit.c)[:2])["rot_rms_mrad"] < 0.2


def test_the_command_line_reads_writes_and_reports_orientations(ur10_sim, tmp_path, capsys):
    """simulate --orientation writes quaternions; identify, evaluate and redundancy read them and
    report position (mm) and orientation (mrad) apart, keeping the contract's keys."""
    robot, _, truth, train, val = ur10_sim
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(json.dumps({**truth.spec, "noise": {"tracker": 3e-5, "orientation": 3e-4}}))
    csv = tmp_path / "sim.csv"
    assert main(["simulate", str(UR10 / "ur10.yaml"), "--truth", str(truth_file), "--poses", "30", "--orientation",
                 "-o", str(csv), "--json"]) == 0
    assert open(csv).readline().strip().endswith("quat_w,quat_x,quat_y,quat_z")
    calib = tmp_path / "c.json"
    capsys.readouterr()
    assert main(["identify", str(UR10 / "ur10.yaml"), str(csv), "-o", str(calib), "--orientation-length", "0.1",
                 "--report", str(tmp_path / "report"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    # the report shows the orientation errors' distribution beside the points'
    report = (tmp_path / "report" / "report.md").read_text()
    assert "(errors_training.png)" in report and "![Orientation errors on the training data, each model]" in report
    assert (tmp_path / "report" / "rotation_errors_training.png").read_bytes()[:4] == b"\x89PNG"
    assert out["n_points"] == 30 and out["n_orientations"] == 30 and out["n_identifiable"] == 30
    assert set(out["train"]) == {"rms_mm", "max_mm", "rot_rms_mrad", "rot_max_mrad"}
    assert out["orientation_length_m"] == 0.1
    assert out["train"]["rot_rms_mrad"] < 0.25 * out["before"]["rot_rms_mrad"]
    write_measurements(tmp_path / "val.csv", robot, val)
    assert main(["evaluate", str(calib), str(tmp_path / "val.csv"), "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["after"]["rms_mm"] < 0.1 and ev["after"]["rot_rms_mrad"] < 0.2 < ev["before"]["rot_rms_mrad"]
    assert main(["redundancy", str(UR10 / "ur10.yaml"), str(csv), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["n_identifiable"] == 30


def test_diagnose_fits_and_scores_orientations(ur10_sim, tmp_path, capsys):
    robot, _, _, train, val = ur10_sim
    write_measurements(tmp_path / "train.csv", robot, train)
    write_measurements(tmp_path / "val.csv", robot, val)
    assert main(["diagnose", str(UR10 / "ur10.yaml"), str(tmp_path / "train.csv"), "--val", str(tmp_path / "val.csv"),
                 "-o", str(tmp_path / "d.errors.yaml"), "--noise-mm", "0.03", "--max-rounds", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for side in ("before", "after"):
        assert {"train_rms_mm", "val_rms_mm", "val_max_mm", "val_rot_rms_mrad", "train_rot_rms_mrad"} <= set(out[side])
    assert out["after"]["val_rot_rms_mrad"] < 0.2 and out["effects"] == []  # constant truth: nothing to add
    assert out["remaining"]["covered"], out["verdict"]  # sigma per degree of freedom against the given noise


#: figaroh 1.0.2 on the same 23 poses (BaseCalibration, full_params, tool frame wrist_3_link, unknown
#: base and tool frames, its default weighting: 1 mm against 0.01 rad, i.e. L = 0.1 m; run here, training
#: residuals, no held-out data): position RMS 2.71 mm (max 5.35), orientation 0.5182 deg (max 1.0242)
FIGAROH_MM, FIGAROH_DEG = (2.71, 5.35), (0.5182, 1.0242)


def test_figaroh_s_ur10_tool_poses_import_and_calibrate(tmp_path, capsys):
    """The real UR10 data imports through its mapping (joints by name, pinocchio's RPY) and
    calibrates: 30 identifiable against 27 from its positions alone, and the training residual of
    figaroh's own full-parameter fit with the same weighting."""
    robot_file = UR10 / "ur10_probe.yaml"
    csv = tmp_path / "poses.csv"
    assert main(["import", str(robot_file), str(UR10 / "calibration.csv"), "--mapping",
                 str(UR10 / "calibration.mapping.yaml"), "-o", str(csv), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["orientations"] == 23
    data = read_measurements(csv, load_robot(robot_file))
    raw = np.loadtxt(UR10 / "calibration.csv", delimiter=",", skiprows=1)
    expect = Rotation.from_euler("xyz", raw[:, 3:6]).as_matrix()  # R = Rz(phiz) Ry(phiy) Rx(phix)
    assert np.abs(data.orientation - expect).max() < 1e-12
    # figaroh's is a full-parameter fit: every identifiable coefficient carried
    assert main(["identify", str(robot_file), str(csv), "-o", str(tmp_path / "c.json"), "--json",
                 "--keep-insignificant"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_identifiable"] == 30 and out["outliers"] == [] and out["suspect_poses"] == []
    before, train = out["before"], out["train"]
    assert before["rms_mm"] > 6 and before["rot_rms_mrad"] > 18  # the rounded tool guess, registered
    assert abs(train["rms_mm"] - FIGAROH_MM[0]) < 0.01 and abs(train["max_mm"] - FIGAROH_MM[1]) < 0.01
    assert abs(train["rot_rms_mrad"] - 1e3 * np.radians(FIGAROH_DEG[0])) < 0.05
    assert abs(train["rot_max_mrad"] - 1e3 * np.radians(FIGAROH_DEG[1])) < 0.05
    positions = tmp_path / "positions.csv"
    positions.write_text("\n".join(",".join(line.split(",")[:11]) for line in csv.read_text().splitlines()) + "\n")
    assert main(["redundancy", str(robot_file), str(positions), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["n_identifiable"] == 27


@pytest.mark.parametrize("glitch_rad, fails", [(0.02, False), (0.1, True)])
def test_a_joint_reading_glitch_in_one_real_pose_is_named(tmp_path, capsys, glitch_rad, fails):
    """q2 of one of the 23 real UR10 poses read off by 0.02 rad: its residual (14 mm) stays under
    the outlier limit, yet the pose is named with the reading that explains it; at 0.1 rad the fit
    is refused, and the refusal names the pose (the refused fit is too far off for its joint
    columns to say which reading)."""
    robot_file = UR10 / "ur10_probe.yaml"
    csv = tmp_path / "poses.csv"
    assert main(["import", str(robot_file), str(UR10 / "calibration.csv"), "--mapping",
                 str(UR10 / "calibration.mapping.yaml"), "-o", str(csv)]) == 0
    table = pd.read_csv(csv)
    table.loc[7, "q2"] += glitch_rad
    table.to_csv(csv, index=False)
    capsys.readouterr()
    code = main(["identify", str(robot_file), str(csv), "-o", str(tmp_path / "c.json"), "--json"])
    err = capsys.readouterr().err
    assert "pose 7 (line 9) does not fit the others" in err
    if fails:
        assert code != 0 and "not trustworthy" in err
        return
    assert code == 0
    fit = json.loads((tmp_path / "c.json").read_text())
    assert fit["outliers"] == []  # the robust limit alone does not see it
    [suspect] = fit["suspect_poses"]
    assert suspect["pose"] == 7 and suspect["reading"] == "q2" and suspect["explained"] > 0.9
    assert -1.5 * glitch_rad < suspect["change"] < -0.5 * glitch_rad  # the reading must come back down


def test_a_measured_frame_turned_any_way_on_the_tool_is_placed_from_the_orientations(tmp_path, capsys):
    """The UR10's probe frame is turned 0.515 rad about x on the flange; a robot file that says it
    is parallel to the tool frame, or turned 1.5 rad elsewhere, gets the same fit: the measured
    orientations give the frame's rotation in the tool frame (R = R_tracker R_tool X) before the
    fit, the calibration carries it, and evaluate repeats the fit."""
    csv = tmp_path / "poses.csv"
    assert main(["import", str(UR10 / "ur10_probe.yaml"), str(UR10 / "calibration.csv"), "--mapping",
                 str(UR10 / "calibration.mapping.yaml"), "-o", str(csv)]) == 0
    capsys.readouterr()
    text = (UR10 / "ur10_probe.yaml").read_text().replace("urdf: ur10_robot.urdf", f"urdf: {UR10 / 'ur10_robot.urdf'}")
    for rpy, turned in (("[0.0, 0.0, 0.0]", 515), ("[1.0, 0.0, 1.5]", None)):
        robot_file = tmp_path / "probe.yaml"
        robot_file.write_text(text.replace("rpy: [-0.5, 0.0, 0.0]", f"rpy: {rpy}"))
        assert main(["identify", str(robot_file), str(csv), "-o", str(tmp_path / "c.json"), "--json",
                     "--keep-insignificant"]) == 0
        out, err = capsys.readouterr()
        fit = json.loads(out)
        assert "probe's measured frame turned" in err
        if turned:
            assert abs(fit["placement"]["turned_mrad"]["probe"] - turned) < 2
        assert abs(fit["train"]["rms_mm"] - FIGAROH_MM[0]) < 0.01
        assert abs(fit["train"]["rot_rms_mrad"] - 1e3 * np.radians(FIGAROH_DEG[0])) < 0.05
        assert main(["evaluate", str(tmp_path / "c.json"), str(csv), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["after"]["rot_rms_mrad"] == pytest.approx(
            fit["train"]["rot_rms_mrad"], rel=1e-9)
