"""Trustworthy identification on data with glitches: robust fitting names and survives them, an
absurd or undetermined fit is a failure, and what a measured point cannot see is eliminated.

The robot is the issue's: a 200-pose industrial6r simulation (its truth file: geometric errors
plus shoulder and elbow compliance under gravity) fitted with the default model, validated on 200
other poses."""
import dataclasses
import json
import re

import numpy as np
import pytest
from conftest import ROBOTS, random_q

from gecgen.cli import main
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import Measurements, write_measurements
from gecgen.model.validation import read_yaml
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit import influence
from gecgen.fit.identify import _fit_failures, identify, position_errors, redundancy
from gecgen.fit.registration import Registration, rotation_matrix, rotation_vector
from gecgen.simulate import load_truth, random_design, simulate

DATA = ROBOTS.parent / "tests" / "data"


@pytest.fixture(scope="module")
def arm():
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    truth = load_truth(read_yaml(ROBOTS / "industrial6r.truth.yaml", "truth"), robot)
    train = simulate(robot, truth, random_design(robot, 200, np.random.default_rng(1)), np.random.default_rng(1))
    val = simulate(robot, truth, random_design(robot, 200, np.random.default_rng(2)), np.random.default_rng(2))
    cm = CompiledModel(robot, load_error_model(ROBOTS / "industrial6r.errors.yaml", robot))
    return robot, cm, train, val


def val_rms_mm(cm, fit, val) -> float:
    e = position_errors(cm, val, fit.registration.to_world(val.xyz), fit.c)
    return float(1e3 * np.sqrt(np.mean(e ** 2)))


def with_xyz(data: Measurements, xyz: np.ndarray) -> Measurements:
    return Measurements(data.q, data.w, data.aux, data.aux_names, data.pose_ids, data.pose, data.target, xyz,
                        data.source, data.row)


def one_row_50mm(xyz, rng):
    xyz[17, 0] += 0.05
    return [17]


def two_rows_swapped(xyz, rng):  # the rows of poses 40 and 140: their points are 1.5 m apart
    xyz[[40, 140]] = xyz[[140, 40]]
    return [40, 140]


def one_percent_5mm(xyz, rng):
    rows = rng.choice(len(xyz), len(xyz) // 100, replace=False)
    xyz[rows] += 0.005 * rng.normal(size=(len(rows), 3)) / np.sqrt(3) + [0.005, 0, 0]
    return list(rows)


@pytest.fixture(scope="module")
def clean(arm):
    robot, cm, train, val = arm
    fit = identify(cm, train)
    return fit, val_rms_mm(cm, fit, val)


def test_clean_data_fits_exactly_as_least_squares(arm, clean):
    robot, cm, train, val = arm
    fit, rms = clean
    plain = identify(cm, train, loss="l2")
    assert fit.outliers == () and np.all(fit.weights == 1) and fit.trustworthy
    assert abs(rms - val_rms_mm(cm, plain, val)) <= 0.01 * rms


@pytest.mark.parametrize("corrupt", [one_row_50mm, two_rows_swapped, one_percent_5mm])
def test_glitches_are_named_and_do_not_move_the_fit(arm, clean, corrupt):
    robot, cm, train, val = arm
    xyz = train.xyz.copy()
    rows = corrupt(xyz, np.random.default_rng(3))
    bad = with_xyz(train, xyz)
    fit = identify(cm, bad)
    assert fit.trustworthy, fit.failures
    assert sorted(o.row for o in fit.outliers) == sorted(r + 2 for r in rows)  # file lines, header = 1
    assert all(o.weight < 0.1 and o.residual_mm > 4 for o in fit.outliers)
    assert val_rms_mm(cm, fit, val) <= 1.05 * clean[1]


def test_least_squares_is_moved_by_one_glitch(arm, clean):
    """What the robust loss prevents: the check above can fail."""
    robot, cm, train, val = arm
    xyz = train.xyz.copy()
    one_row_50mm(xyz, None)
    plain = identify(cm, with_xyz(train, xyz), loss="l2")
    assert plain.outliers == () and val_rms_mm(cm, plain, val) > 2 * clean[1]


def test_a_gross_mismatch_does_not_tilt_the_registration(arm):
    """The tracker frame is 30 degrees and 2 m away, and two rows are swapped: the registration
    comes from the other points, and the swapped rows are still the only outliers."""
    robot, cm, train, val = arm
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    R, t = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]), np.array([2.0, -0.5, 0.3])
    xyz = train.xyz @ R.T + t
    rows = two_rows_swapped(xyz, None)
    fit = identify(cm, with_xyz(train, xyz))
    assert fit.registration.applied
    assert np.abs(fit.registration.R - R).max() < 1e-3 and np.abs(fit.registration.t - t).max() < 3e-3
    assert sorted(o.row for o in fit.outliers) == [r + 2 for r in rows]


def test_cli_lists_outliers_in_json_and_for_a_person(arm, tmp_path, capsys):
    robot, cm, train, val = arm
    xyz = train.xyz.copy()
    one_row_50mm(xyz, None)
    write_measurements(tmp_path / "bad.csv", robot, with_xyz(train, xyz))
    args = ["identify", str(ROBOTS / "industrial6r.yaml"), str(tmp_path / "bad.csv"), "-o", str(tmp_path / "c.json")]
    assert main([*args, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [(o["row"], o["pose"], o["target"]) for o in out["outliers"]] == [(19, 17, "smr")]
    assert 49 < out["outliers"][0]["residual_mm"] < 51 and out["loss"] == "cauchy"
    assert main([*args]) == 0
    assert "  row 19: pose 17 smr" in capsys.readouterr().out
    assert main([*args, "--loss", "l2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["outliers"] == []


def test_absurd_or_undetermined_values_are_failures(arm):
    robot, cm, train, val = arm
    kept = np.arange(cm.dims.nc)
    c, std = np.zeros(cm.dims.nc), np.full(cm.dims.nc, 1e-6)
    names = cm.model.coefficient_names(robot)
    assert _fit_failures(cm, train, c, std, kept, True, "") == []
    rotation = names.index("3.ep:1")
    c[rotation] = 0.7  # rad: no robot is that far from its model
    assert "3.ep reaches 0.7 rad" in _fit_failures(cm, train, c, std, kept, True, "")[0]
    c[rotation], std[rotation] = 0.0, np.nan
    assert "3.ep:1 has no finite uncertainty" in _fit_failures(cm, train, c, std, kept, True, "")[0]
    assert _fit_failures(cm, train, c, np.full(cm.dims.nc, 1e-6), kept, False, "did not converge") == ["did not converge"]


def test_an_absurd_error_at_one_pose_of_many_is_found_block_by_block(arm):
    """absurd_error reads the poses in blocks (its memory does not grow with the data): one pose in
    the last block, where a joint term's coefficient makes a 1 m translation error, is enough."""
    from gecgen.fit.identify import BLOCK_POSES, absurd_error

    robot, cm, train, val = arm
    names = cm.model.coefficient_names(robot)
    term = next(n for n in names if re.fullmatch(r"\d+\.e[xyz]:q\d", n))
    c = np.zeros(cm.dims.nc)
    c[names.index(term)] = 0.01  # m per rad
    q = np.zeros((2 * BLOCK_POSES + 10, robot.n))
    assert absurd_error(cm, q, np.zeros(6), np.zeros((len(q), 0)), c) is None
    q[-3, int(term.split(":q")[1]) - 1] = 100.0
    assert f"{term.split(':')[0]} reaches 1 m" in absurd_error(cm, q, np.zeros(6), np.zeros((len(q), 0)), c)


def test_data_of_another_robot_is_a_failure_not_a_fit(arm):
    """Points a metre from anywhere this robot reaches leave metres of residual whatever the
    coefficients: a failure, however small the errors the fit settles on."""
    robot, cm, train, val = arm
    scattered = dataclasses.replace(train, xyz=train.xyz + np.random.default_rng(5).normal(0, 1.0, train.xyz.shape))
    fit = identify(cm, scattered)
    assert any("rms at the measured points (limit 0.5 m)" in f for f in fit.failures), fit.failures
    assert not any("rms at the measured points" in f for f in identify(cm, train).failures)


def test_cli_refuses_an_untrustworthy_fit_with_one_line(arm, tmp_path, capsys):
    """Least squares on the swapped rows gives generalized errors no robot has: identify fails with
    the reason and writes no calibration."""
    robot, cm, train, val = arm
    xyz = train.xyz.copy()
    two_rows_swapped(xyz, None)
    write_measurements(tmp_path / "swap.csv", robot, with_xyz(train, xyz))
    out = tmp_path / "c.json"
    assert main(["identify", str(ROBOTS / "industrial6r.yaml"), str(tmp_path / "swap.csv"), "-o", str(out),
                 "--loss", "l2", "--json"]) == 1
    captured = capsys.readouterr()
    assert captured.out == "" and not out.exists()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "not trustworthy" in lines[0] and "reaches" in lines[0], captured.err


def test_a_point_on_the_last_axis_cannot_see_rotations_about_it(rng):
    """UR10 from its URDF, one point at the flange centre, on joint 6's axis: 4 x 6 + 3 = 27 for a
    generic point, less joint 6's angle and the rotation of frame 5 about the same axis, 25. The
    URDF's rounded angles leave that column at 1.5e-10 instead of 0; scaled to unit length it once
    passed for an independent direction and got a value of 1e11 rad."""
    robot = load_robot(DATA / "ur10" / "ur10.yaml")
    cm = CompiledModel(robot, load_error_model(None, robot))
    assert redundancy(cm).n_identifiable == 25
    q = random_q(robot, rng, 60)
    eps = rng.normal(0, 5e-4, robot.n_errors)
    xyz = target_positions(robot, q, eps)[:, 0] + rng.normal(0, 3e-5, (60, 3))
    data = Measurements(q, np.zeros((60, 6)), np.zeros((60, 0)), (), np.arange(60), np.arange(60),
                        np.zeros(60, int), xyz, "sim")
    fit = identify(cm, data)
    assert fit.trustworthy and fit.redundancy.n_identifiable == 25, fit.failures
    assert fit.condition_number < 1e6 and np.nanmax(np.abs(fit.c)) < 0.1
    assert fit.train["rms_mm"] < 0.1


def test_evaluate_and_compensate_say_where_they_extrapolate(arm, tmp_path, capsys):
    robot, cm, train, val = arm
    write_measurements(tmp_path / "train.csv", robot, train)
    calib = tmp_path / "c.json"
    assert main(["identify", str(ROBOTS / "industrial6r.yaml"), str(tmp_path / "train.csv"), "-o", str(calib)]) == 0
    ranges = json.loads(calib.read_text())["training_ranges"]
    assert ranges["q2"] == [float(train.q[:, 1].min()), float(train.q[:, 1].max())]
    capsys.readouterr()
    inside = train.subset(np.arange(20))
    write_measurements(tmp_path / "inside.csv", robot, inside)
    assert main(["evaluate", str(calib), str(tmp_path / "inside.csv"), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["extrapolation"] == {} and captured.err == ""
    q = inside.q.copy()
    q[:3, 1] = train.q[:, 1].max() + 0.01  # three poses beyond the training span of joint 2
    q[0, 2] = train.q[:, 2].min() - 0.01
    moved = Measurements(q, inside.w, inside.aux, (), inside.pose_ids, inside.pose, inside.target, inside.xyz, "m")
    write_measurements(tmp_path / "outside.csv", robot, moved)
    assert main(["evaluate", str(calib), str(tmp_path / "outside.csv"), "--json"]) == 0
    captured = capsys.readouterr()
    scored = json.loads(captured.out)
    assert scored["extrapolation"] == {"q2": 3, "q3": 1}
    assert "q2 (a2) 3, q3 (a3) 1 (of 20)" in captured.err
    # the 17 poses inside every range are scored apart: as evaluating them alone
    write_measurements(tmp_path / "within.csv", robot, moved.subset(np.arange(3, 20)))
    assert main(["evaluate", str(calib), str(tmp_path / "within.csv"), "--json"]) == 0
    assert scored["after_inside"] == json.loads(capsys.readouterr().out)["after"]
    (tmp_path / "cmds.csv").write_text("q1,q2,q3,q4,q5,q6\n" + ",".join(map(repr, q[0].tolist())) + "\n")
    assert main(["compensate", str(calib), str(tmp_path / "cmds.csv"), "-o", str(tmp_path / "out.csv"),
                 "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["extrapolation"] == {"q2": 1, "q3": 1} and "extrapolation" in captured.err


def test_registration_maps_back(arm):
    """The robust closed form is still exact on exact data (a guard on the weighted Kabsch)."""
    robot, cm, train, val = arm
    p = cm.nominal_targets(train.q)[train.pose, train.target]
    R = Registration(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]), np.array([1.0, 2, 3]), True)
    fit = identify(cm, with_xyz(train, p @ R.R.T + R.t), loss="cauchy")
    assert np.allclose(fit.registration.R, R.R, atol=1e-12) and np.allclose(fit.registration.t, R.t, atol=1e-12)


def test_deleted_residuals_are_those_of_the_fit_without_the_pose(rng):
    """influence.deleted_residuals against refitting without each pose (plain least squares on a
    random system of 12 poses with 6 rows each), streamed in two blocks of whole poses."""
    P, k = 12, 9
    A, b = rng.normal(size=(6 * P, k)), rng.normal(size=6 * P)
    row_pose = np.repeat(np.arange(P), 6)
    r = b - A @ np.linalg.lstsq(A, b, rcond=None)[0]
    Rk = np.linalg.qr(A, mode="r")
    drop, d = influence.deleted_residuals([(A[:36], r[:36]), (A[36:], r[36:])], row_pose, Rk, P)
    for p in range(P):
        out = row_pose != p
        x = np.linalg.lstsq(A[out], b[out], rcond=None)[0]
        assert np.allclose(d[~out], b[~out] - A[~out] @ x, atol=1e-10)
        assert drop[p] == pytest.approx(r @ r - np.sum((b[out] - A[out] @ x) ** 2), rel=1e-9)


def test_a_pose_that_stands_alone_is_a_suspect_and_misfit_is_not():
    """A pose whose F is GAP times the next one's and significant is named; the same F among
    others nearly as large (misfit everywhere) or without significance names none."""
    dof = np.full(40, 6.0)
    alone = np.full(40, 1e-6)
    alone[7] = 60e-6
    found, F = influence.suspects(alone, dof, rss=40 * 6e-6 + 54e-6, m=240, k=30)
    assert list(found) == [7] and F[7] > influence.GAP * np.delete(F, 7).max()
    crowd = alone.copy()
    crowd[[3, 11, 20]] = 30e-6
    assert len(influence.suspects(crowd, dof, rss=float(crowd.sum()), m=240, k=30)[0]) == 0
    assert len(influence.suspects(alone, dof, rss=1.0, m=240, k=30)[0]) == 0  # drowned in noise


def test_the_robust_scale_uses_the_chi3_median():
    """robust.MEDIAN_CHI3 (Newton's method on the closed-form law) is scipy's chi-square median."""
    from scipy.stats import chi2

    from gecgen.fit import robust
    assert robust.MEDIAN_CHI3 == pytest.approx(np.sqrt(chi2.ppf(0.5, 3)), rel=1e-14)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-7, 1e-3, 0.5, 2.0, np.pi - 1e-6, np.pi])
def test_rotation_vectors_and_matrices_agree_with_scipy(angle):
    """rotation_matrix / rotation_vector against scipy's Rotation, near zero and near a half turn too."""
    from scipy.spatial.transform import Rotation

    axes = np.random.default_rng(1).normal(size=(50, 3))
    for v in angle * axes / np.linalg.norm(axes, axis=1, keepdims=True):
        R = Rotation.from_rotvec(v).as_matrix()
        assert np.abs(rotation_matrix(v) - R).max() < 1e-14
        back = rotation_vector(R)
        # a half turn is the same rotation about +axis and -axis
        assert min(np.abs(back - v).max(), np.abs(back + v).max() if angle == np.pi else 1.0) < 1e-14 * max(angle, 1)
