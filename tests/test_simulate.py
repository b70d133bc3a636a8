"""The simulator: each error source does what it says, the paper design is the paper's, and the
sensor reads the payload's weight."""
import json

import numpy as np
import pytest
from conftest import ROBOTS

from gecgen.cli import main

from gecgen.model import ModelError, load_robot
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import read_measurements, write_measurements
from gecgen.model.validation import read_yaml
from gecgen.simulate import Design, load_truth, paper_pps, paper_split, random_design, simulate
from gecgen.simulate.designs import _with_target, treatment_volume_vertices
from gecgen.simulate.truth import true_state


@pytest.fixture
def pps():
    return load_robot(ROBOTS / "pps.yaml")


def test_zero_truth_measures_the_nominal_robot(pps, rng):
    design = random_design(pps, 20, rng)
    data = simulate(pps, load_truth({}, pps), design, rng)
    np.testing.assert_array_equal(data.xyz, target_positions(pps, design.q)[data.pose, data.target])


def test_waviness_is_periodic_with_the_stated_wavelength_and_amplitude(pps):
    truth = load_truth({"sources": [{"type": "sinusoid", "variable": 1, "error": "1.ey", "amplitude": 3e-4,
                                     "period": 0.45}]}, pps)
    q = np.zeros((200, 6))
    q[:, 0] = np.linspace(-1.0, 1.0, 200)
    _, eps = true_state(pps, truth, q, np.zeros(200), np.zeros(3), {}, np.ones((200, 6)))
    ey = eps[:, 7]
    assert abs(ey.max() - 3e-4) < 1e-6 and abs(ey.min() + 3e-4) < 1e-6
    q2 = q.copy()
    q2[:, 0] += 0.45
    _, eps2 = true_state(pps, truth, q2, np.zeros(200), np.zeros(3), {}, np.ones((200, 6)))
    np.testing.assert_allclose(eps2[:, 7], ey, atol=1e-15)
    assert np.count_nonzero(eps[:, np.arange(42) != 7]) == 0


def test_compliance_and_bending_scale_with_the_payload(pps):
    spec = {"gravity": [0, -9.81, 0], "masses": [{"frame": 6, "mass": 50}],
            "sources": [{"type": "compliance", "joint": 5, "compliance": 1e-6},
                        {"type": "cantilever", "joint": 3, "offset": 0.735, "flexibility": 1e-6, "deflection": "-3.ez"}]}
    truth = load_truth(spec, pps)
    q = np.tile(np.radians([0, 0, 0, 30, 0, 0]) + [0.1, 0.1, 0.3, 0, 0, 0], (3, 1))
    payload = np.array([0.0, 70.0, 140.0])
    qt, eps = true_state(pps, truth, q, payload, np.zeros(3), {}, np.ones((3, 6)))
    dq5 = qt[:, 4] - q[:, 4]
    assert abs(dq5[2] - dq5[1] - (dq5[1] - dq5[0])) < 1e-15 and abs(dq5[1] - dq5[0]) > 0  # linear in payload
    sag = -eps[:, 6 * 3 + 2]
    np.testing.assert_allclose(sag, 1e-6 * payload * 9.81 * (0.3 + 0.735) ** 3 / 3, rtol=1e-12)


def test_thermal_error_is_zero_at_the_reference_temperature(pps):
    truth = load_truth({"sources": [{"type": "thermal", "error": "1.ez", "per_kelvin": 1e-5, "reference": 20}]}, pps)
    _, eps = true_state(pps, truth, np.zeros((3, 6)), np.zeros(3), np.zeros(3), {"temp_c": np.array([20.0, 25.0, 30.0])},
                        np.ones((3, 6)))
    np.testing.assert_allclose(eps[:, 8], [0, 5e-5, 1e-4], atol=1e-18)


def test_sensor_reads_the_payload_weight_in_the_tool_frame(pps, rng):
    design = random_design(pps, 10, rng, payloads_kg=(70.0,), payload_at=(0.1, 0.0, 0.2))
    data = simulate(pps, load_truth({"gravity": [0, -9.81, 0]}, pps), design, rng)
    np.testing.assert_allclose(np.linalg.norm(data.w[:, :3], axis=1), 70 * 9.81, rtol=1e-12)
    np.testing.assert_allclose(data.w[:, 3:], np.cross([0.1, 0.0, 0.2], data.w[:, :3]), atol=1e-9)
    home = Design(np.zeros((1, 6)), np.array([70.0]), np.zeros(3), ("t1",), np.array(["home"]))
    at_home = simulate(pps, load_truth({"gravity": [0, -9.81, 0]}, pps), home, rng)
    np.testing.assert_allclose(at_home.w[0, :3], [0, -686.7, 0], atol=1e-9)  # tool y is world up at home


def test_paper_design_counts_and_vertices_on_the_isocenter(pps, rng):
    design = paper_pps(pps)
    assert (design.group == "a").sum() == 112  # 8 vertices x 7 angles x 2 payloads, as in the paper
    assert (design.group == "b").sum() == 340  # the paper reports 338: here home is measured in each sweep
    a = design.q[design.group == "a"]
    for k, q in enumerate(a[:56]):
        v = treatment_volume_vertices()[k % 8]
        np.testing.assert_allclose(target_positions(_with_target(pps, v), q[None])[0, -1], pps.points["isocenter"],
                                   atol=1e-9)
    assert np.all(a[:, 4:] == 0)  # roll and pitch never move
    lo, hi = np.array([j.lower for j in pps.joints]), np.array([j.upper for j in pps.joints])
    assert np.all((design.q >= lo - 1e-12) & (design.q <= hi + 1e-12))
    train, val = paper_split(design, rng)
    assert len(val) == 56 and len(train) == 452 - 56 and not set(train) & set(val)


def test_csv_round_trip(pps, tmp_path, rng):
    truth = load_truth(read_yaml(ROBOTS / "pps.truth.yaml", "truth"), pps)
    data = simulate(pps, truth, random_design(pps, 15, rng, (0.0, 70.0)), rng)
    write_measurements(tmp_path / "d.csv", pps, data)
    back = read_measurements(tmp_path / "d.csv", pps)
    for field in ("q", "w", "xyz", "pose", "target"):
        np.testing.assert_array_equal(getattr(back, field), getattr(data, field))


@pytest.mark.parametrize("spec, expect", [
    ({"sources": [{"type": "wobble"}]}, "type must be one of"),
    ({"sources": [{"type": "sinusoid", "variable": 9, "error": "1.ey", "amplitude": 1, "period": 1}]}, "joint must be 1..6"),
    ({"sources": [{"type": "sinusoid", "variable": 1, "error": "9.ey", "amplitude": 1, "period": 1}]}, "unknown generalized error"),
    ({"constant": {"sigma": 1}}, "unknown key 'sigma'"),
    ({"sources": [{"type": "compliance", "joint": 1, "compliance": 1e-6}]}, "needs a revolute joint"),
])
def test_bad_truth_files_are_refused(pps, spec, expect):
    with pytest.raises(ModelError) as err:
        load_truth(spec, pps, "t.yaml")
    assert expect in str(err.value) and "t.yaml" in str(err.value) and "\n" not in str(err.value)


def test_random_design_writes_validation_poses_of_the_same_truth(tmp_path, capsys):
    """--val-out with the random design: new poses (--val-poses), measured on the same truth (the
    calibration fitted on the training file predicts them as well as its training poses)."""
    robot, truth = ROBOTS / "industrial6r.yaml", ROBOTS / "industrial6r.truth.yaml"
    args = ["simulate", str(robot), "--truth", str(truth), "--poses", "80", "-o", str(tmp_path / "t.csv"),
            "--val-out", str(tmp_path / "v.csv"), "--val-poses", "30", "--json"]
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["files"]["val"] == str(tmp_path / "v.csv")
    val = read_measurements(tmp_path / "v.csv", load_robot(robot))
    train = read_measurements(tmp_path / "t.csv", load_robot(robot))
    assert val.n_poses == 30 and not (set(map(tuple, val.q.round(9))) & set(map(tuple, train.q.round(9))))
    assert main(["identify", str(robot), str(tmp_path / "t.csv"), "-o", str(tmp_path / "c.json"), "--json"]) == 0
    fit = json.loads(capsys.readouterr().out)["train"]["rms_mm"]
    assert main(["evaluate", str(tmp_path / "c.json"), str(tmp_path / "v.csv"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["after"]["rms_mm"] < 3 * fit
    # a validation file the design cannot give is refused, not skipped
    assert main(["simulate", str(robot), "--design", "one-at-a-time", "-o", str(tmp_path / "o.csv"),
                 "--val-out", str(tmp_path / "ov.csv")]) == 2
    assert "--val-out with --design one-at-a-time" in capsys.readouterr().err


def test_seed_draws_poses_and_noise_and_truth_seed_draws_the_robot(tmp_path, capsys):
    """--seed leaves the truth file's draws alone (data of two seeds are of one robot); --truth-seed
    replaces the truth file's seed (another robot), and is refused without a truth file."""
    robot, truth = ROBOTS / "industrial6r.yaml", ROBOTS / "industrial6r.truth.yaml"

    def drawn(name, *options):
        assert main(["simulate", str(robot), "--truth", str(truth), "--poses", "5", "-o", str(tmp_path / f"{name}.csv"),
                     "--truth-out", str(tmp_path / f"{name}.yaml"), "--json", *options]) == 0
        return read_yaml(tmp_path / f"{name}.yaml", "truth"), (tmp_path / f"{name}.csv").read_text()

    base, data = drawn("a", "--seed", "1")
    other_poses, other_data = drawn("b", "--seed", "2")
    assert base == other_poses and data != other_data
    other_robot, _ = drawn("c", "--seed", "1", "--truth-seed", "8")
    assert other_robot["constant"] != base["constant"] and other_robot["joint_offsets"] != base["joint_offsets"]
    assert drawn("d", "--seed", "1", "--truth-seed", "8")[0] == other_robot
    capsys.readouterr()
    assert main(["simulate", str(ROBOTS / "puma560.yaml"), "--truth-seed", "7", "-o", str(tmp_path / "p.csv")]) == 2
    assert capsys.readouterr().err == (f"gecgen simulate: --truth-seed 7: there is no truth file to draw "
                                       f"({ROBOTS / 'puma560.truth.yaml'} does not exist); give --truth FILE\n")
