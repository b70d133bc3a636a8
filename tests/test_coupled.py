"""Coupled joints (issue 19): a robot file declares the chain's joint values as affine maps of the
controller's readings. robots/fanuc.yaml is a FANUC-like arm whose controller reads J3 as the
forearm's angle to the horizontal (chain joint 3 = J2 + J3); its truth has the coupling 0.3% off.

Checked against independent computation: the coupled chain at the readings against an uncoupled
robot at hand-converted chain variables (the exact chain and the generated code), the joint
Jacobian in the readings against finite differences, virtual-work gravity torques of a passive
coupled joint against finite differences of the potential energy, and the fits against the
simulated truth."""
import numpy as np
import pytest
from conftest import ROBOTS

import gecgen
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import error_model_from_dict, load_error_model
from gecgen.model.kinematics import frames, joint_values, target_positions, tool_pose
from gecgen.model.loads import _numeric_columns
from gecgen.model.measurements import Measurements
from gecgen.model.validation import read_yaml
from gecgen.runtime.compiled import CompiledModel
from gecgen.simulate import load_truth, random_design, simulate
from gecgen.simulate.truth import Truth, gravity_torques, true_state
from gecgen.symbolic.chain import tool_jacobian_function

MDEG = 180e3 / np.pi
MDEG = 180e3 / np.pi
RATIO_ERROR = 0.003  # robots/fanuc.truth.yaml: J3 = 1.003 J2 + J3 as built


def floor_mm(truth) -> float:
    """RMS point error of the noise alone (tracker and repeatability, three coordinates)."""
    return 1e3 * np.sqrt(3 * (truth.tracker ** 2 + truth.repeatability ** 2))


@pytest.fixture(scope="module")
def fanuc():
    return load_robot(ROBOTS / "fanuc.yaml")


@pytest.fixture(scope="module")
def truth(fanuc):
    return load_truth(read_yaml(ROBOTS / "fanuc.truth.yaml", "truth"), fanuc)


@pytest.fixture(scope="module")
def uncoupled(tmp_path_factory):
    """The same arm described in chain variables: no couplings, joint 3's limits wide enough for J2 + J3."""
    folder = tmp_path_factory.mktemp("uncoupled")
    text = (ROBOTS / "fanuc.yaml").read_text()
    text = text.replace("couplings:\n  J3: J2 + J3", "").replace("limits: [-80, 90]", "limits: [-170, 170]")
    (folder / "fanuc.yaml").write_text(text)
    return load_robot(folder / "fanuc.yaml")


@pytest.fixture(scope="module")
def data(fanuc, truth):
    """150 training and 100 held-out poses of the truth, in the controller's readings."""
    rng = np.random.default_rng(3)
    return [simulate(fanuc, truth, random_design(fanuc, n, rng), rng) for n in (150, 100)]


@pytest.fixture(scope="module")
def calibrator(fanuc, data):
    return gecgen.Calibrator(errors=load_error_model(None, fanuc)).fit(fanuc, data[0])


def converted(m: Measurements) -> Measurements:
    """The readings turned into chain variables by hand: q3 := q2 + q3."""
    q = m.q.copy()
    q[:, 2] += q[:, 1]
    return Measurements(q=q, w=m.w, aux=m.aux, aux_names=m.aux_names, pose_ids=m.pose_ids, pose=m.pose,
                        target=m.target, xyz=m.xyz, source=m.source)


def test_a_coupling_is_an_affine_map_of_the_readings(fanuc):
    assert fanuc.n == fanuc.n_frames == 6 and fanuc.joint_names == ("J1", "J2", "J3", "J4", "J5", "J6")
    terms, offset = fanuc.drives()[2]
    assert [(k, float(m)) for k, m in terms] == [(1, 1.0), (2, 1.0)] and offset == 0
    assert fanuc.driven(1) == [(2, 1), (3, 1)]  # J2 turns frames 2 and 3
    # joint 3 turns about frame 2's z: its ratio to J2 is term q2 on 2.er, added to any model with 2.er's constant
    assert fanuc.ratio_terms() == {6 * 2 + 4: ["q2"]}
    model = load_error_model(None, fanuc)
    assert [t.text for t in model.terms[16]] == ["1", "q2"] and len(model.coefficients) == 43
    assert [t.text for t in error_model_from_dict({"default": ["q1"]}, fanuc, "m.yaml").terms[16]] == ["q1"]


@pytest.mark.parametrize("couplings, message", [
    ({"J3": "J2 * J3"}, r"couplings.J3: 'J2 \* J3' is not affine in the readings"),
    ({"J3": "J2**2 + J3"}, r"couplings.J3: 'J2\*\*2 \+ J3' is not an affine map"),
    ({"J3": "J7 + J3"}, r"couplings.J3: 'J7 \+ J3': 'J7' is not a joint of this robot; use the joint names"),
    ({"J3": "sin(J2)"}, r"couplings.J3: 'sin\(J2\)' is not an affine map of the readings"),
    ({"J3": "J2 +"}, r"couplings.J3: 'J2 \+' is not an expression"),
    ({"J3": ""}, r"couplings.J3: expected the joint's value in the readings"),
    ({"J3": 5}, r"couplings.J3: expected the joint's value in the readings"),
    ({"J3": "J2 - J2 + 4"}, r"couplings.J3: 'J2 - J2 \+ 4' depends on no joint"),
    ({"J3": "J2 / J3"}, r"couplings.J3: 'J2 / J3': divide only by a nonzero number"),
    ({"J9": "J2"}, r"couplings: 'J9' is not a joint on the chain; couple one of J1, J2"),
    ({"J4": "-J3", "J5": "J4 + J5"}, r"couplings: joint 'J5' follows 'J4', which has no reading of its own"),
    ([1, 2], r"couplings: expected a mapping from joint names"),
    ({"J2": "J2 + J3", "J3": "J2 + J3"}, r"couplings: J2, J3: the joints' values do not determine their readings"),
    ({"J2": "J2 + J3", "J3": "J2 + 1.000001*J3"}, r"couplings: J2, J3: these couplings can hardly be inverted "
                                                  r"\(condition number .*, beyond 1e\+06\)"),
    ({"J3": "1e300*J2 + J3"}, r"couplings.J3: '1e300\*J2 \+ J3': the multiplier of J2, rad per rad, is 1e\+300, "
                              r"beyond \+-1000"),
    ({"J3": "J2 + J3 + 1e300"}, r"couplings.J3: .*the offset, rad, is 1.75e\+298, beyond \+-1000"),
    ({"J3": "-" * 100_000 + "J2"}, r"couplings.J3: '----.* is longer than 1000 characters"),
    ({"J3": "0*J3 + J2"}, r"couplings.J3: '0\*J3 \+ J2': the multiplier of J3's own reading cancels to 0"),
    ({"J3": "J3 - J3 + J2"}, r"couplings.J3: 'J3 - J3 \+ J2': the multiplier of J3's own reading cancels to 0"),
])
def test_bad_couplings_are_refused_by_name(tmp_path, couplings, message):
    import yaml

    spec = yaml.safe_load((ROBOTS / "fanuc.yaml").read_text())
    spec["couplings"] = couplings
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(spec))
    with pytest.raises(ModelError, match=message) as err:
        load_robot(tmp_path / "r.yaml")
    assert str(tmp_path / "r.yaml") in str(err.value) and "\n" not in str(err.value)


def test_the_coupled_chain_is_the_hand_converted_chain(fanuc, uncoupled, rng):
    """Exact chain and generated code at the readings equal the uncoupled arm at q3 := q2 + q3; the
    joint Jacobian of compensation, in the readings, equals finite differences of the exact chain."""
    q = random_design(fanuc, 40, rng).q
    v = joint_values(fanuc, q)
    assert np.allclose(v[:, 2], q[:, 1] + q[:, 2], atol=0, rtol=1e-15)
    eps = rng.normal(0, 1e-3, fanuc.n_errors)
    for a, b in zip(frames(fanuc, q, eps), frames(uncoupled, v, eps)):
        assert np.abs(a - b).max() < 1e-14
    model = load_error_model(None, uncoupled)
    coupled_cm, plain_cm = CompiledModel(fanuc, model), CompiledModel(uncoupled, model)
    E = np.tile(eps, (len(q), 1))
    (p1, J1), (p2, J2) = coupled_cm.J_e(q, E), plain_cm.J_e(v, E)
    assert np.abs(p1 - p2).max() < 1e-13 and np.abs(J1 - J2).max() < 1e-13
    assert np.abs(p1.reshape(len(q), -1, 3) - target_positions(fanuc, q, eps)).max() < 1e-13
    tj = tool_jacobian_function(fanuc)
    for qi in q[:4]:
        Jq = tj.evaluate(q=qi, eps=eps)["Jq"].reshape(6, fanuc.n)
        T, h = tool_pose(fanuc, qi, eps)[0], 1e-6
        for k in range(fanuc.n):
            dq = np.eye(fanuc.n)[k] * h
            Tp, Tm = tool_pose(fanuc, qi + dq, eps)[0], tool_pose(fanuc, qi - dq, eps)[0]
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T[:3, :3].T
            np.testing.assert_allclose(Jq[:, k], [*(Tp[:3, 3] - Tm[:3, 3]) / (2 * h), W[2, 1], W[0, 2], W[1, 0]],
                                       atol=1e-8)


@pytest.mark.filterwarnings("ignore:extrapolation")
def test_a_calibration_from_readings_equals_one_from_hand_converted_chain_variables(fanuc, uncoupled, data,
                                                                                    calibrator):
    """The coupling declared, or the data converted by hand with the ratio term written out: one fit."""
    by_hand = error_model_from_dict({"default": ["1"], "frames": {2: {"er": ["1", "q2"]}}}, uncoupled, "m.yaml")
    plain = gecgen.Calibrator(errors=by_hand).fit(uncoupled, converted(data[0]))
    a, b = calibrator.report_, plain.report_
    assert a["n_params"] == b["n_params"] == 43 and a["n_identifiable"] == b["n_identifiable"]
    assert abs(a["train"]["rms_mm"] - b["train"]["rms_mm"]) < 1e-9
    held_out = calibrator.predict(data[1].q) - plain.predict(converted(data[1]).q)
    assert 1e3 * np.abs(held_out).max() < 1e-9


@pytest.mark.filterwarnings("ignore:extrapolation")
def test_the_coupling_ratio_error_is_recovered_and_held_out_reaches_the_noise_floor(calibrator, truth, data):
    found = next(c for c in calibrator.calibration_.to_dict()["coefficients"] if c["name"] == "2.er:q2")
    assert found["identified"] and found["std"] < 1e-5
    assert abs(found["value"] - RATIO_ERROR) < 3 * found["std"], found  # docs/coupled-joints.md: z over seeds
    score = calibrator.score(data[1])
    assert score.before.rms_mm > 20 * floor_mm(truth)
    assert score.after.rms_mm < 1.1 * floor_mm(truth), (score.after, floor_mm(truth))


def test_compensated_readings_put_the_robot_as_built_where_the_nominal_model_puts_it(fanuc, truth, calibrator, rng):
    q_cmd = random_design(fanuc, 60, rng).q * 0.5  # off the stretched arm, which a shorter arm cannot reach
    q_cmd = q_cmd[np.abs(q_cmd[:, 4]) > 0.3][:30]  # and off the wrist singularity (J5 = 0)
    fixed = calibrator.compensate(q_cmd).q

    def as_built(q):  # the truth robot (its coupling 0.3% off) at the readings it is sent
        q_true, eps = true_state(truth.robot, truth, q, np.zeros(len(q)), np.zeros(3), {}, np.ones_like(q))
        return target_positions(truth.robot, q_true, eps)

    wanted = target_positions(fanuc, q_cmd)
    before = 1e3 * np.linalg.norm(as_built(q_cmd) - wanted, axis=2)
    after = 1e3 * np.linalg.norm(as_built(fixed) - wanted, axis=2)
    assert before.max() > 3.0 and after.max() < 0.05, (before.max(), after.max())


@pytest.fixture(scope="module")
def torso(tmp_path_factory):
    """A torso whose fourth joint is passive, -(t2 + t3) (it keeps the chest upright), and a gripper
    gear that drives its last joint at half the wrist's speed: no reading for t4 and t6."""
    folder = tmp_path_factory.mktemp("torso")
    (folder / "torso.yaml").write_text("""name: torso
angle_unit: deg
joints:
  - {name: t1, type: R, d: 0.3, a: 0.05, alpha: 90, limits: [-90, 90]}
  - {name: t2, type: R, a: 0.4, alpha: 0, limits: [-60, 60]}
  - {name: t3, type: R, a: 0.35, alpha: 0, limits: [-60, 60]}
  - {name: t4, type: R, a: 0.1, alpha: -90, limits: [-120, 120]}
  - {name: t5, type: R, d: 0.2, a: 0, alpha: 90, limits: [-170, 170]}
  - {name: t6, type: R, d: 0.1, a: 0, alpha: 0, limits: [-170, 170]}
couplings:
  t4: -(t2 + t3)
  t6: 0.5*t5 + 10
targets:
  hand: [0.0, 0.05, 0.1]
""")
    return load_robot(folder / "torso.yaml")


def test_passive_coupled_joints_have_no_reading_and_carry_their_loads_by_virtual_work(torso, rng):
    assert torso.n == 4 and torso.n_frames == 6 and torso.joint_names == ("t1", "t2", "t3", "t5")
    assert [(k, float(m)) for k, m in torso.drives()[5][0]] == [(3, 0.5)]
    assert abs(float(torso.drives()[5][1]) - np.radians(10)) < 1e-15
    q = random_design(torso, 20, rng).q
    g = np.array([float(v) for v in torso.gravity])

    def potential(q, masses):  # V = -sum m g . p, frames' origins and the tool
        F = frames(torso, q)
        return -sum(m * (F[i][:, :3, 3] @ g) for i, m in masses)

    masses = [(2, 3.0), (4, 2.0), (6, 1.5), (7, 0.5)]  # kg at frame origins (7: the tool frame)
    spec = Truth(np.zeros(torso.n_errors), np.zeros(torso.n), (), g, tuple({"frame": i, "mass": m, "at": [0, 0, 0]}
                                                                           for i, m in masses[:-1]), 0.0, 0.0)
    tau = gravity_torques(torso, spec, q, np.full(len(q), 0.5), np.zeros(3))
    columns = _numeric_columns(torso, q)
    h = 1e-6
    for k in range(torso.n):
        dq = np.zeros(torso.n)
        dq[k] = h
        fd = -(potential(q + dq, masses) - potential(q - dq, masses)) / (2 * h)
        assert np.abs(tau[:, k] - fd).max() < 1e-6, k
        # the regressor's unit mass at frame 4's origin (passive, moved by t2 and t3 through -1)
        first = torso.driven(k)[0][0]
        if first <= 4:
            unit = -(potential(q + dq, [(4, 1.0)]) - potential(q - dq, [(4, 1.0)])) / (2 * h)
            assert np.abs(columns[k][:, 4 * (4 - first)] - unit).max() < 1e-6, k


def test_a_term_naming_a_passive_joint_says_how_to_write_it(torso):
    with pytest.raises(ModelError, match=r"'t4' is a passive coupled joint, with no variable of its own; write its value "
                                         r"-1.0\*q2 - 1.0\*q3 \+ 0.0 in q2, q3"):
        error_model_from_dict({"frames": {3: {"er": ["1", "t4"]}}}, torso, "m.yaml")


def test_simulate_identify_and_compensate_through_the_cli(tmp_path, capsys):
    """The commands take and return the controller's readings; the summary gives each joint's largest
    correction with its unit."""
    from gecgen.cli import main

    robot, out = str(ROBOTS / "fanuc.yaml"), tmp_path
    assert main(["simulate", robot, "--poses", "80", "--seed", "4", "-o", str(out / "t.csv")]) == 0
    assert main(["identify", robot, str(out / "t.csv"), "-o", str(out / "c.json")]) == 0
    (out / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n0.1,0.3,-0.2,0.4,0.5,-0.3\n")
    assert main(["compensate", str(out / "c.json"), str(out / "cmd.csv"), "-o", str(out / "fixed.csv")]) == 0
    fixed = np.loadtxt(out / "fixed.csv", delimiter=",", skiprows=1, usecols=range(6))
    assert 1e-5 < np.abs(fixed - [0.1, 0.3, -0.2, 0.4, 0.5, -0.3]).max() < 0.02
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("max_correction")]
    assert len(line) == 1 and line[0].count(" rad") == 6, line


def test_the_table_gives_the_readings_zero_offsets_through_the_couplings(fanuc):
    """An offset of reading J2 turns joints 2 and 3 (J3 = J2 + J3): the table's J2 holds it and J3
    stays zero, as the controller needs them."""
    from gecgen.deliver.export import table

    spec = {"seed": 1, "joint_offsets": {"values": [0.0, 1e-3, 0.0, -5e-4, 0.0, 0.0]},
            "noise": {"repeatability": 1e-6, "tracker": 1e-6}}
    truth = load_truth(spec, fanuc)
    rng = np.random.default_rng(5)
    data = simulate(fanuc, truth, random_design(fanuc, 80, rng), rng)
    cal = gecgen.Calibrator(errors=load_error_model(None, fanuc)).fit(fanuc, data)
    rows = {r["joint"]: r for r in table(cal.calibration_, cal._model())["zero_offsets"]}
    assert rows["J3"]["through_couplings"] == {"1.er:1": -1.0, "2.er:1": 1.0}  # dq3 = dv3 - dv2
    for name, truth_mdeg in (("J2", 1e-3 * MDEG), ("J3", 0.0), ("J4", -5e-4 * MDEG)):
        if rows[name]["value"] is not None:
            assert abs(rows[name]["value"] - truth_mdeg) < max(5 * rows[name]["std"], 0.05), rows[name]
    assert rows["J2"]["value"] is not None and rows["J3"]["value"] is not None


def test_unnamed_dh_rows_and_restated_urdf_mimics_are_refused_with_the_fix(tmp_path):
    import yaml

    spec = yaml.safe_load((ROBOTS / "fanuc.yaml").read_text())
    for row in spec["joints"]:
        row.pop("name")
    spec["couplings"] = {"q4": "-(q2 + q3)"}
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(spec))
    with pytest.raises(ModelError, match=r"joints\[0\]: give every DH row a name when couplings make a joint passive"):
        load_robot(tmp_path / "r.yaml")
    telescope = (ROBOTS.parent / "tests" / "data" / "mimic" / "telescope.yaml").read_text()
    (tmp_path / "telescope.urdf").write_text((ROBOTS.parent / "tests" / "data" / "mimic" / "telescope.urdf").read_text())
    (tmp_path / "t.yaml").write_text(telescope + "\ncouplings: {lift2: lift}\n")
    with pytest.raises(ModelError, match=r"couplings: 'lift2' is a <mimic> joint of the URDF.*change its <mimic>"):
        load_robot(tmp_path / "t.yaml")
