"""Identification, redundancy, compensation and evaluation against simulated robots with known truth.

The simulated robots here are the exact nonlinear chain (model.kinematics) with constant
generalized errors and Gaussian tracker noise, which is all these checks need."""
import json

import numpy as np
import pytest
from conftest import ROBOTS, random_q
from scipy import stats

from gecgen.cli import main
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import Measurements, read_measurements, write_measurements
from gecgen.fit import calibration
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import identify, redundancy


def simulate(robot, n_poses, rng, eps, targets=None, noise=0.0, fixed=(), offset=None):
    """Measurements of the truth chain (constant errors eps) at random poses; joints in `fixed` stay 0."""
    q = random_q(robot, rng, n_poses)
    q[:, list(fixed)] = 0.0
    targets = list(range(len(robot.targets))) if targets is None else list(targets)
    y = target_positions(robot, q, eps)
    pose, tgt = np.repeat(np.arange(n_poses), len(targets)), np.tile(targets, n_poses)
    xyz = y[pose, tgt] + rng.normal(0, noise, (len(pose), 3))
    if offset is not None:
        xyz = xyz @ offset[0].T + offset[1]
    return Measurements(q, np.zeros((n_poses, 6)), np.zeros((n_poses, 0)), (), np.arange(n_poses), pose, tgt, xyz, "sim")


def counts(robot):
    n_r = sum(j.kind == "R" for j in robot.joints)
    return 4 * n_r + 2 * (robot.n - n_r)


@pytest.mark.parametrize("name, targets, extra", [
    ("puma560", None, 6), ("puma560", [0], 3), ("industrial6r", None, 3), ("pps", [0, 1, 2], 6), ("pps", [3], 3)])
def test_redundancy_counts_match_the_literature(name, targets, extra, rng):
    robot = load_robot(ROBOTS / f"{name}.yaml")
    cm = CompiledModel(robot, load_error_model(None, robot))
    data = simulate(robot, 60, rng, np.zeros(robot.n_errors), targets)
    red = redundancy(cm, data)
    assert red.n_identifiable == counts(robot) + extra  # 4R + 2P + 6 (full pose) or + 3 (one point)
    assert all(e.reason == "structural" for e in red.eliminated)


def test_paper_design_leaves_roll_and_pitch_unexcited(rng):
    robot = load_robot(ROBOTS / "pps.yaml")
    cm = CompiledModel(robot, load_error_model(None, robot))
    data = simulate(robot, 80, rng, np.zeros(robot.n_errors), [0, 1, 2], fixed=(4, 5))
    red = redundancy(cm, data)
    assert red.n_identifiable == 16  # the seed paper's 16 geometric parameters
    assert sum(e.reason == "unexcited" for e in red.eliminated) == 24 - 16


def test_eliminated_parameters_say_what_they_merge_into():
    robot = load_robot(ROBOTS / "puma560.yaml")
    red = redundancy(CompiledModel(robot, load_error_model(None, robot)))
    by_name = {e.param: e for e in red.eliminated}
    # joint 2 is revolute about z of frame 1: ez and er of frame 1 are eliminated by the rule
    assert {"1.ez:1", "1.er:1"} <= set(by_name)
    assert "revolute joint 2" in by_name["1.er:1"].detail and by_name["1.er:1"].merged_into
    structural_default = redundancy(CompiledModel(robot, load_error_model(ROBOTS / "puma560.errors.yaml", robot)))
    assert structural_default.n_identifiable == 30


def test_noiseless_geometric_fit_below_a_micrometre(shipped, rng):
    robot, _ = shipped
    cm = CompiledModel(robot, load_error_model(None, robot))
    fit = identify(cm, simulate(robot, 80, rng, rng.normal(0, 1e-3, robot.n_errors)))
    assert fit.converged and fit.before["rms_mm"] > 1.0
    assert fit.train["max_mm"] < 1e-3


def test_truth_within_three_sigma_and_chi_square(rng):
    robot = load_robot(ROBOTS / "puma560.yaml")
    model = load_error_model(None, robot)
    cm = CompiledModel(robot, model)
    truth = rng.normal(0, 1e-3, robot.n_errors)
    noise = 5e-5
    data = simulate(robot, 300, rng, truth, noise=noise)
    fit = identify(cm, data)
    kept = np.array(fit.redundancy.kept)
    # compare in an identifiable combination: the predicted point errors at fresh poses
    q = random_q(robot, rng, 50)
    p_true = target_positions(robot, q, truth)
    p_fit = cm.model_targets(q, None, None, fit.c)
    from gecgen.fit.identify import prediction_std

    sd = prediction_std(cm, fit, q)
    err = np.linalg.norm(p_true - p_fit, axis=2)
    assert np.mean(err < 3 * np.sqrt(3) * sd + 1e-9) > 0.95
    # residual sum of squares follows chi-square with m - k degrees of freedom
    m, k = 3 * len(data.xyz), len(kept)
    chi2 = (fit.sigma_m / noise) ** 2 * (m - k)
    assert stats.chi2.ppf(0.001, m - k) < chi2 < stats.chi2.ppf(0.999, m - k)


def test_registration_of_a_far_measurement_frame(rng):
    robot = load_robot(ROBOTS / "puma560.yaml")
    cm = CompiledModel(robot, load_error_model(None, robot))
    a = 0.7
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    data = simulate(robot, 80, rng, rng.normal(0, 5e-4, robot.n_errors), offset=(R, np.array([3.0, -1.0, 0.5])))
    fit = identify(cm, data)
    assert fit.registration.applied and abs(fit.registration.angle_rad - a) < 0.01
    assert fit.train["max_mm"] < 1e-3


def test_streaming_blocks_give_the_same_fit(rng):
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    cm = CompiledModel(robot, load_error_model(ROBOTS / "industrial6r.errors.yaml", robot))
    data = simulate(robot, 150, rng, rng.normal(0, 5e-4, robot.n_errors), noise=2e-5)
    import gecgen.fit.identify as ident

    whole = identify(cm, data)
    old = ident.BLOCK_POSES
    try:
        ident.BLOCK_POSES = 7
        streamed = identify(cm, data)
    finally:
        ident.BLOCK_POSES = old
    np.testing.assert_allclose(streamed.c, whole.c, atol=1e-9)


def test_compensation_puts_the_true_robot_on_target(tmp_path, rng):
    robot = load_robot(ROBOTS / "pps.yaml")
    model = load_error_model(None, robot)
    cm = CompiledModel(robot, model)
    truth, noise = rng.normal(0, 1e-3, robot.n_errors), 2e-5
    fit = identify(cm, simulate(robot, 200, rng, truth, [0, 1, 2], noise=noise))
    q_cmd = random_q(robot, rng, 30) * 0.8
    q_cmp, status = cm.compensate(q_cmd, None, None, fit.c)
    assert np.all(status == 0)
    wanted = target_positions(robot, q_cmd)  # where the nominal model puts the targets
    uncompensated = np.linalg.norm(target_positions(robot, q_cmd, truth) - wanted, axis=2)
    compensated = np.linalg.norm(target_positions(robot, q_cmp, truth) - wanted, axis=2)
    assert uncompensated.max() > 1e-3
    assert compensated.max() < 3 * noise


def test_cli_identify_evaluate_compensate_and_refusal(tmp_path, rng, capsys):
    robot = load_robot(ROBOTS / "pps.yaml")
    truth = rng.normal(0, 1e-3, robot.n_errors)
    write_measurements(tmp_path / "train.csv", robot, simulate(robot, 100, rng, truth, [0, 1, 2], noise=2e-5))
    write_measurements(tmp_path / "val.csv", robot, simulate(robot, 40, rng, truth, [0, 1, 2], noise=2e-5))
    calib = tmp_path / "c.json"
    constant = tmp_path / "const.errors.yaml"
    constant.write_text('default: ["1"]\n')
    assert main(["identify", str(ROBOTS / "pps.yaml"), str(tmp_path / "train.csv"), "--errors", str(constant),
                 "-o", str(calib), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_params"] == 42 and out["n_identifiable"] == 24
    assert len([e for e in out["eliminated"] if e["reason"] == "structural"]) == 18
    assert {"param", "reason"} <= set(out["eliminated"][0]) and out["train"]["rms_mm"] < 0.1 < out["before"]["rms_mm"]
    assert main(["evaluate", str(calib), str(tmp_path / "val.csv"), "--json"]) == 0
    ev = json.loads(capsys.readouterr().out)
    assert ev["after"]["rms_mm"] < 0.1 < ev["before"]["rms_mm"]
    (tmp_path / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6,note\n0.1,0.0,0.2,0.3,0.01,-0.01,7\n")
    assert main(["compensate", str(calib), str(tmp_path / "cmd.csv"), "-o", str(tmp_path / "o.csv"), "--json"]) == 0
    lines = (tmp_path / "o.csv").read_text().splitlines()
    assert lines[0] == "q1,q2,q3,q4,q5,q6,note,status,residual_mm" and lines[1].split(",")[6:8] == ["7", "0"]
    assert not lines[1].startswith("0.1,0.0,0.2,0.3,0.01,-0.01,7")
    # a calibration is refused against a changed model
    d = json.loads(calib.read_text())
    d["error_model"]["frames"]["1"] = {"ex": ["1", "q1"]}  # only errors beyond the constant are listed
    calib.write_text(json.dumps(d))
    with pytest.raises(ModelError, match="does not match"):
        calibration.load(calib)


@pytest.mark.parametrize("edit, expect", [
    (lambda h, r: (h.replace(",target", ",tgt"), r), "missing column 'target'"),
    (lambda h, r: (h, r.replace(",t1,", ",t9,", 1)), "unknown target 't9'"),
    (lambda h, r: (h, r.replace(",t2,", ",t1,", 1)), "measures target 't1' twice"),
    (lambda h, r: (h, r.replace(",0.0,", ",nan,", 1)), "not finite"),
])
def test_bad_measurement_files_name_row_and_column(tmp_path, rng, edit, expect):
    robot = load_robot(ROBOTS / "pps.yaml")
    write_measurements(tmp_path / "d.csv", robot, simulate(robot, 3, rng, np.zeros(robot.n_errors), [0, 1, 2]))
    head, rest = (tmp_path / "d.csv").read_text().split("\n", 1)
    head, rest = edit(head, rest)
    (tmp_path / "d.csv").write_text(head + "\n" + rest)
    with pytest.raises(ModelError) as err:
        read_measurements(tmp_path / "d.csv", robot)
    assert expect in str(err.value) and "d.csv" in str(err.value) and "\n" not in str(err.value)


def test_millimetres_joint_limits_and_disagreeing_poses_are_refused(tmp_path, rng):
    robot = load_robot(ROBOTS / "pps.yaml")
    data = simulate(robot, 3, rng, np.zeros(robot.n_errors), [0, 1, 2])
    cases = [(Measurements(data.q, data.w, data.aux, (), data.pose_ids, data.pose, data.target, data.xyz * 1000),
              "millimetres"),
             (Measurements(data.q + np.array([0, 0, 0, 3.0, 0, 0]), data.w, data.aux, (), data.pose_ids, data.pose,
                           data.target, data.xyz), "outside the joint limits")]
    for bad, expect in cases:
        write_measurements(tmp_path / "d.csv", robot, bad)
        with pytest.raises(ModelError, match=expect):
            read_measurements(tmp_path / "d.csv", robot)
    write_measurements(tmp_path / "d.csv", robot, data)
    lines = (tmp_path / "d.csv").read_text().splitlines()
    fields = lines[2].split(",")
    fields[1] = repr(float(fields[1]) + 0.01)
    lines[2] = ",".join(fields)
    (tmp_path / "d.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelError, match="disagrees with its row 2"):
        read_measurements(tmp_path / "d.csv", robot)


def test_c_compensation_agrees_with_an_independent_python_solution(rng):
    """scipy least squares on the exact numpy chain, with eps depending on q through the basis."""
    from scipy.optimize import least_squares

    from gecgen.model.kinematics import tool_pose

    robot = load_robot(ROBOTS / "industrial6r.yaml")
    model = load_error_model(ROBOTS / "industrial6r.errors.yaml", robot)
    cm = CompiledModel(robot, model)
    c = rng.normal(0, 2e-5, len(model.coefficients))
    w = np.array([10.0, -30.0, -900.0, 5.0, 2.0, -1.0])
    q_cmd = np.radians([20, -70, 30, 30, 40, 10])
    q_c, status = cm.compensate(q_cmd[None], w[None], None, c)
    assert status[0] == 0
    T_nom = tool_pose(robot, q_cmd)[0]

    def pose_error(q):
        T = tool_pose(robot, q, cm.eps(q[None], w[None], None, c))[0]
        rot = 0.5 * sum(np.cross(T[:3, k], T_nom[:3, k]) for k in range(3))
        return np.concatenate([T_nom[:3, 3] - T[:3, 3], rot])

    ref = least_squares(pose_error, q_cmd, xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    assert np.abs(pose_error(ref)).max() < 1e-12
    np.testing.assert_allclose(q_c[0], ref, atol=1e-10)
    assert np.abs(q_c[0] - q_cmd).max() > 1e-4  # a real correction, not the identity


def test_recovered_coefficients_within_three_sigma_of_the_truth(rng):
    """Truth on the identifiable coefficients only (eliminated ones would merge into them)."""
    robot = load_robot(ROBOTS / "pps.yaml")
    model = load_error_model(None, robot)
    cm = CompiledModel(robot, model)
    kept = np.array(redundancy(cm).kept)  # all four targets: 24 identifiable
    truth = np.zeros(len(model.coefficients))
    truth[kept] = rng.normal(0, 1e-3, len(kept))
    data = simulate(robot, 150, rng, truth, noise=4e-5)  # constant model: eps = c
    fit = identify(cm, data)
    assert list(fit.redundancy.kept) == list(kept)
    z = (fit.c[kept] - truth[kept]) / fit.std[kept]
    assert np.all(np.abs(z) < 4.5) and np.mean(np.abs(z) < 3) >= 0.9, z


def test_rank_tolerance_chosen_by_cross_validation_holds_weak_coefficients(tmp_path, rng, capsys):
    """25 poses of one point with the wrist pitch barely moving: the exact fit gives the wrist's
    weakly excited coefficients noise-driven values that extrapolate badly once the wrist moves;
    `--rank-tol auto` (chosen on the training data) holds them at zero and predicts far better."""
    robot = load_robot(ROBOTS / "puma560.yaml")
    truth = rng.normal(0, 5e-4, robot.n_errors)
    n = 25
    q = random_q(robot, rng, n)
    q[:, 4] = rng.uniform(-0.03, 0.03, n)
    y = target_positions(robot, q, truth)[:, 0] + rng.normal(0, 2e-4, (n, 3))
    train = Measurements(q, np.zeros((n, 6)), np.zeros((n, 0)), (), np.arange(n), np.arange(n), np.zeros(n, int), y,
                         "sim")
    write_measurements(tmp_path / "train.csv", robot, train)
    write_measurements(tmp_path / "val.csv", robot, simulate(robot, 200, rng, truth, [0]))  # the wrist moves
    constant = tmp_path / "const.errors.yaml"
    constant.write_text('default: ["1"]\n')
    val_rms = {}
    for option, keep in (("1e-7", True), ("auto", True), ("1e-7", False)):
        calib = tmp_path / f"{option}.json"
        assert main(["identify", str(ROBOTS / "puma560.yaml"), str(tmp_path / "train.csv"), "--errors", str(constant),
                     "--rank-tol", option, "-o", str(calib), "--json"] + ["--keep-insignificant"] * keep) == 0
        if option == "auto":
            fit = json.loads(capsys.readouterr().out)
        capsys.readouterr()
        assert main(["evaluate", str(calib), str(tmp_path / "val.csv"), "--json"]) == 0
        val_rms[option, keep] = json.loads(capsys.readouterr().out)["after"]["rms_mm"]
    weak = [e for e in fit["eliminated"] if e["reason"] == "weak"]
    assert fit["rank_tol"] > 1e-7 and len(weak) > 0 and all(e["merged_into"] for e in weak)
    assert fit["n_identifiable"] == 27 - len(weak) and len(fit["cv"]) == 7
    assert val_rms["auto", True] < 0.5 * val_rms["1e-7", True]
    # holding the insignificant coefficients at zero (the default) does what the weak ones' tolerance does
    assert val_rms["1e-7", False] < 0.5 * val_rms["1e-7", True]
    for bad in ("1.5", "-0.1", "x"):
        assert main(["identify", str(ROBOTS / "puma560.yaml"), str(tmp_path / "train.csv"), "--rank-tol", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--rank-tol" in err[0] and "auto" in err[0]
