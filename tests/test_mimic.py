"""URDF mimic joints on the chain (tests/data/mimic/telescope.urdf): a frame each, no variable of their
own. Kinematics and the generated code against pinocchio, J_e and the joint Jacobian against finite
differences of the exact chain, gravity and wrench loads against pinocchio and virtual work, an
identify round trip on simulated data, and one-line refusals."""
import json
import re
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
import yaml
from conftest import ROBOTS, ROOT, random_q
from test_symbolic import fd_jacobian

from gecgen.emit import frame_names
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import error_model_from_dict, load_error_model
from gecgen.model.gravity import robot_gravity_torques
from gecgen.model.kinematics import frames, tool_pose
from gecgen.model.loads import catalog
from gecgen.runtime.compiled import CompiledModel
from gecgen.symbolic.chain import jacobian_function, tool_jacobian_function

DATA = ROOT / "tests" / "data" / "mimic"
URDF = (DATA / "telescope.urdf").read_text()
#: the chain's moving joints (frames 1..7) and, for each, (variable, multiplier, offset)
CHAIN = {"slew": (0, 1, 0), "lift": (1, 1, 0), "lift2": (1, 1, 0), "boom": (2, 1, 0), "stick": (3, 1, 0),
         "tilt": (3, -1, 0.2), "wrist": (1, 2, -0.1)}
#: off the chain: the counterweight follows lift; the fingers are held (finger_b follows finger_a at 0)
OFF_CHAIN = {"counter": (1, -0.5, 0.0), "finger_a": None, "finger_b": None}
GRAVITY = np.array([0.0, 0.0, -9.80665])


@pytest.fixture(scope="module")
def telescope():
    return load_robot(DATA / "telescope.yaml")


def variant(folder, text: str, name="telescope"):
    """A copy of the test robot whose URDF is `text`."""
    (folder / f"{name}.urdf").write_text(text)
    spec = yaml.safe_load((DATA / "telescope.yaml").read_text())
    spec.update(name=name, urdf=f"{name}.urdf")
    (folder / f"{name}.yaml").write_text(yaml.safe_dump(spec))
    return folder / f"{name}.yaml"


def replaced(old: str, new: str, text: str = URDF) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


# -- pinocchio: every URDF joint independent, set from q by the mimic relations ------------------
def pin_model(path, mimic=False):
    try:
        model = pin.buildModelFromUrdf(str(path), mimic=True) if mimic else pin.buildModelFromUrdf(str(path))
    except TypeError:  # pinocchio before 3.4 has no mimic joints
        pytest.skip("this pinocchio does not parse mimic joints")
    model.gravity.linear = GRAVITY
    return model


def pin_q(model, q):
    """pinocchio's configuration (continuous joints as cos, sin) and dq_pin/dq (nv x n)."""
    cfg, A = np.zeros(model.nq), np.zeros((model.nv, len(q)))
    for i in range(1, model.njoints):
        name = model.names[i]
        k, m, o = CHAIN.get(name) or OFF_CHAIN.get(name) or (None, 0.0, 0.0)
        value = m * q[k] + o if k is not None else 0.0
        iq, iv = model.joints[i].idx_q, model.joints[i].idx_v
        if model.joints[i].nq == 2:
            cfg[iq:iq + 2] = np.cos(value), np.sin(value)
        else:
            cfg[iq] = value
        if k is not None:
            A[iv, k] += m
    return cfg, A


def link_pose(model, data, link):
    return data.oMf[model.getFrameId(link)].homogeneous


# -- the robot noun -------------------------------------------------------------------------------
def test_frames_and_joint_variables_are_counted_apart(telescope):
    r = telescope
    assert r.joint_names == ("slew", "lift", "boom", "stick") and r.n == 4
    assert [j.name for j in r.chain] == list(CHAIN) and r.n_frames == 7 and r.n_errors == 48
    assert r.error_names()[-1] == "7.ep"
    assert [(k, float(m), float(o)) for ((k, m),), o in r.drives()] == list(CHAIN.values())
    assert r.driven(1) == [(2, 1), (3, 1), (7, 2)] and r.frame_of(2) == 4
    # a mimic joint's limits narrow the joint it follows: lift2 <= 0.9 m, tilt = 0.2 - stick >= -0.1 rad
    assert [(j.lower, j.upper) for j in r.joints] == [(-3, 3), (0, 0.9), (-1.2, 1.2), (-2, pytest.approx(0.3))]
    assert (r.chain[6].lower, r.chain[6].upper) == (-np.inf, np.inf)  # continuous wrist: no limit
    # the generated header and manifest list the frames, a mimic joint with its value
    assert frame_names(r) == ["slew", "lift", "lift2 = 1.0*q2 + 0.0", "boom", "stick", "tilt = -1.0*q4 + 0.2",
                              "wrist = 2.0*q2 - 0.1"]


# -- kinematics -----------------------------------------------------------------------------------
def test_chain_and_generated_code_match_pinocchio(telescope, rng):
    model = pin_model(DATA / "telescope.urdf")
    data = model.createData()
    cm = CompiledModel(telescope, load_error_model(None, telescope), backend="c")
    q = np.vstack([np.zeros(4), random_q(telescope, rng, 5)])
    W = frames(telescope, q)
    p_gen = cm.nominal_targets(q)
    for i, qi in enumerate(q):
        pin.framesForwardKinematics(model, data, pin_q(model, qi)[0])
        for f, joint in enumerate(telescope.chain, start=1):  # frame f is the child link of chain joint f
            child = model.frames[model.getFrameId(joint.name)].name  # pinocchio names the joint frame alike
            np.testing.assert_allclose(W[f][i], data.oMi[model.getJointId(child)].homogeneous, atol=1e-13)
        tool = link_pose(model, data, "tool_link")
        np.testing.assert_allclose(W[-1][i], tool, atol=1e-13)
        expected = [tool[:3, :3] @ t + tool[:3, 3] for t in telescope.targets.values()]
        np.testing.assert_allclose(p_gen[i], expected, atol=1e-13)


def test_pinocchio_own_mimic_joints_agree(tmp_path, rng):
    """pinocchio 4.1 parses mimic joints where both have one configuration variable and the mimic
    joint is below the one it follows: a variant with a revolute wrist and the counterweight held."""
    text = replaced('<mimic joint="lift" multiplier="-0.5" offset="0"/>', "",
                    replaced('type="continuous"', 'type="revolute"',
                             replaced('<mimic joint="lift" multiplier="2"', '<limit lower="-3" upper="3" effort="1" '
                                      'velocity="1"/><mimic joint="lift" multiplier="2"')))
    robot = load_robot(variant(tmp_path, text))
    model = pin_model(tmp_path / "telescope.urdf", mimic=True)
    data = model.createData()
    assert model.nq == 6  # slew, lift, boom, stick and the two off-chain independent joints
    for qi in random_q(robot, rng, 4):
        cfg = np.zeros(model.nq)
        for name, value in zip(robot.joint_names, qi):
            cfg[model.joints[model.getJointId(name)].idx_q] = value
        pin.framesForwardKinematics(model, data, cfg)
        np.testing.assert_allclose(frames(robot, qi)[-1][0], link_pose(model, data, "tool_link"), atol=1e-13)
        # generalized gravity on the independent joints, mimic loads through their multipliers
        tau = pin.computeGeneralizedGravity(model, data, cfg)
        idx = [model.joints[model.getJointId(n)].idx_v for n in robot.joint_names]
        # pinocchio's gravity torque is what holds the robot: minus gecgen's tau = -dV/dq
        np.testing.assert_allclose(robot_gravity_torques(robot, qi[None], list(robot.joint_names))[0], -tau[idx],
                                   rtol=1e-12, atol=1e-9)
        cm = CompiledModel(robot, error_model_from_dict(
            {"frames": {2: {"ez": ["1", "gravity_torque(lift)"]}, 4: {"es": ["gravity_torque(boom)",
                                                                             "gravity_torque(stick)"]}}},
            robot, "<test>"), backend="c")
        names, L = cm.load_signals(qi)
        got = [L[0, names.index(f"gravity_torque(q{k})")] for k in (2, 3, 4)]
        np.testing.assert_allclose(got, -tau[idx[1:]], rtol=1e-10, atol=1e-8)


def test_J_e_and_joint_jacobian_match_finite_differences(telescope, rng):
    fn, tj = jacobian_function(telescope), tool_jacobian_function(telescope)
    cm = CompiledModel(telescope, load_error_model(None, telescope), backend="c")
    for q in random_q(telescope, rng, 2):
        eps = rng.normal(0, 0.01, telescope.n_errors)
        fd = fd_jacobian(telescope, q, eps)
        mimic_columns = [6 * f + k for f in (3, 6, 7) for k in range(6)]
        assert np.abs(fd[:, mimic_columns]).max() > 0.1  # the mimic frames' errors move the targets
        np.testing.assert_allclose(fn.evaluate(q=q, eps=eps)["J"].reshape(-1, telescope.n_errors), fd, atol=1e-8)
        np.testing.assert_allclose(cm.J_e(q, eps)[1][0], fd, atol=1e-8)
        # the joint Jacobian of compensation: d(tool pose)/dq with the mimic joints moved along (chain rule)
        out = tj.evaluate(q=q, eps=eps)
        T = tool_pose(telescope, q, eps)[0]
        np.testing.assert_allclose(out["T"].reshape(4, 4), T, atol=1e-13)
        h, Jq = 1e-6, out["Jq"].reshape(6, 4)
        for k in range(4):
            dq = np.eye(4)[k] * h
            Tp, Tm = tool_pose(telescope, q + dq, eps)[0], tool_pose(telescope, q - dq, eps)[0]
            v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T[:3, :3].T
            np.testing.assert_allclose(Jq[:, k], [*v, W[2, 1], W[0, 2], W[1, 0]], atol=1e-8)


# -- loads ----------------------------------------------------------------------------------------
def test_gravity_torques_carry_mimic_joints_and_the_counterweight(telescope, rng, tmp_path):
    """`gecgen gravity`'s numbers against pinocchio's gravity with every URDF joint independent, moved
    by the mimic relations: by virtual work tau = A^T tau_pin, A = dq_pin/dq."""
    model = pin_model(DATA / "telescope.urdf")
    data = model.createData()
    q = random_q(telescope, rng, 5)
    tau = robot_gravity_torques(telescope, q, list(telescope.joint_names))
    for qi, ti in zip(q, tau):
        cfg, A = pin_q(model, qi)
        np.testing.assert_allclose(ti, -A.T @ pin.computeGeneralizedGravity(model, data, cfg), rtol=1e-12, atol=1e-9)
    # the counterweight (200 kg sliding back and down as the lift extends) pulls the lift: without it tau_lift differs
    held = load_robot(variant(tmp_path, replaced('<mimic joint="lift" multiplier="-0.5" offset="0"/>', "")))
    assert np.abs(robot_gravity_torques(held, q, ["lift"]) - tau[:, [1]]).min() > 100


def test_wrench_torque_is_the_virtual_work_of_the_wrench(telescope, rng):
    cm = CompiledModel(telescope, load_error_model(None, telescope), backend="c")
    q, w = random_q(telescope, rng, 3), rng.normal(0, 50, (3, 6))
    names, L = cm.load_signals(q, w)
    h = 1e-6
    for qi, wi, Li in zip(q, w, L):
        T = tool_pose(telescope, qi)[0]
        f, m = T[:3, :3] @ wi[:3], T[:3, :3] @ wi[3:]  # the wrench is measured in the tool frame
        for k in range(4):
            dq = np.eye(4)[k] * h
            Tp, Tm = tool_pose(telescope, qi + dq)[0], tool_pose(telescope, qi - dq)[0]
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T[:3, :3].T
            work = f @ (Tp[:3, 3] - Tm[:3, 3]) / (2 * h) + m @ [W[2, 1], W[0, 2], W[1, 0]]
            assert Li[names.index(f"wrench_torque(q{k + 1})")] == pytest.approx(work, rel=1e-7, abs=1e-7)


def test_gravity_torque_refuses_a_mass_a_mimic_joint_swings_off_the_chain(telescope):
    with pytest.raises(ModelError, match=r"counter_link.*mimics chain joint 'lift' off the chain.*gecgen gravity"):
        error_model_from_dict({"frames": {2: {"ez": ["gravity_torque(lift)"]}}}, telescope, "m.yaml")
    assert "gravity(q2,1)" in catalog(telescope).names  # the unknown-mass columns stay usable


# -- identify round trip --------------------------------------------------------------------------
def gecgen(*args):
    done = subprocess.run([sys.executable, "-m", "gecgen.cli", *map(str, args), "--json"], capture_output=True,
                          text=True, cwd=ROOT)
    return done.returncode, json.loads(done.stdout) if done.stdout.strip() else {}, done.stderr


def test_simulate_and_identify_recover_the_mimic_frames_errors(tmp_path):
    robot = DATA / "telescope.yaml"
    code, red, err = gecgen("redundancy", robot, "--errors", ROBOTS / "constant.errors.yaml")
    assert code == 0, err
    kept = [n for n in red["identifiable"] if n.split(".")[0] in ("3", "6", "7")]
    assert len(kept) >= 12  # most errors of the three mimic frames are identifiable
    rng = np.random.default_rng(7)
    truth = {n.split(":")[0]: float(rng.normal(0, 1e-3)) for n in kept}
    (tmp_path / "truth.yaml").write_text(yaml.safe_dump({"constant": {"values": truth},
                                                          "noise": {"tracker": 1e-6}}))
    code, sim, err = gecgen("simulate", robot, "--truth", tmp_path / "truth.yaml", "--poses", 60, "--seed", 3,
                            "-o", tmp_path / "train.csv")
    assert code == 0, err
    header = (tmp_path / "train.csv").read_text().splitlines()[0].split(",")
    assert [h for h in header if re.fullmatch(r"q\d+", h)] == ["q1", "q2", "q3", "q4"]
    assert sim["uncompensated"]["rms_mm"] > 1
    code, fit, err = gecgen("identify", robot, tmp_path / "train.csv", "--errors", ROBOTS / "constant.errors.yaml",
                            "-o", tmp_path / "calib.json", "--register", "never")
    assert code == 0, err
    coefficients = json.loads((tmp_path / "calib.json").read_text())["coefficients"]
    got = {c["name"].split(":")[0]: c["value"] for c in coefficients if c["name"].split(":")[0] in truth}
    assert set(got) == set(truth)
    np.testing.assert_allclose([got[n] for n in truth], list(truth.values()), atol=2e-5)
    assert fit["train"]["rms_mm"] < 0.01


# -- refusals -------------------------------------------------------------------------------------
REFUSED = {
    "mimicked joint missing": (replaced('<mimic joint="lift" multiplier="1"', '<mimic joint="lfit" multiplier="1"'),
                               "joint 'lift2' mimics joint 'lfit', which this URDF does not have"),
    "multiplier not finite": (replaced('multiplier="-1" offset="0.2"', 'multiplier="inf" offset="0.2"'),
                              "joint 'tilt' mimic multiplier: 'inf' is not finite"),
    "multiplier not a number": (replaced('multiplier="-1" offset="0.2"', 'multiplier="-x" offset="0.2"'),
                                "joint 'tilt' mimic multiplier: '-x' is not a number"),
    "offset not finite": (replaced('multiplier="-1" offset="0.2"', 'multiplier="-1" offset="nan"'),
                          "joint 'tilt' mimic offset: 'nan' is not finite"),
    "multiplier zero": (replaced('multiplier="-1" offset="0.2"', 'multiplier="0" offset="0.2"'),
                        "joint 'tilt' mimic: multiplier 0 holds the joint at its offset; make it a fixed joint"),
    "no joint named": (replaced('<mimic joint="stick"', "<mimic"), "joint 'tilt' mimic: <mimic> names no joint"),
    "mimicked off the chain": (replaced('<mimic joint="stick"', '<mimic joint="finger_a"'),
                               "joint 'tilt' on the chain mimics joint 'finger_a', which is not on the chain from "
                               "'base_link' to 'tool_link'; choose links whose chain holds 'finger_a', or make "
                               "'tilt' fixed"),
    "mimic loop": (replaced('<mimic joint="lift" multiplier="1"', '<mimic joint="wrist" multiplier="1"',
                            replaced('<mimic joint="lift" multiplier="2"', '<mimic joint="lift2" multiplier="2"')),
                   "joint 'lift2': the mimic joints lift2 -> wrist -> lift2 form a loop; let one of them mimic "
                   "nothing"),
    "mimic of a fixed joint": (replaced('<mimic joint="stick"', '<mimic joint="flange"'),
                               "joint 'tilt' mimics joint 'flange', a fixed joint; a mimic joint follows a revolute, "
                               "continuous or prismatic joint: fix its <mimic>"),
    "two joints of one name": (replaced('<joint name="finger_b"', '<joint name="finger_a"'),
                               "joint 'finger_a': a second joint of this name; joint names must be unique"),
    "limits that leave nothing": (replaced('lower="-0.1" upper="2.2"', 'lower="2.4" upper="3"'),
                                  "joint 'tilt': its limits [2.4, 3] allow joint 'stick' only [-2.8, -2.2], outside "
                                  "that joint's limits [-2, 0.5]"),
}


@pytest.mark.parametrize("case", REFUSED)
def test_bad_mimic_joints_are_refused_in_one_line(tmp_path, case):
    text, expect = REFUSED[case]
    with pytest.raises(ModelError) as err:
        load_robot(variant(tmp_path, text))
    message = str(err.value)
    assert expect in message and "telescope.urdf" in message and "\n" not in message, message


def test_a_mimic_of_a_mimic_composes(tmp_path, telescope, rng):
    # wrist = 2 lift2 - 0.1 with lift2 = lift + 0.05: the same chain as wrist = 2 lift + 0.0
    text = replaced('<mimic joint="lift" multiplier="1" offset="0"/>', '<mimic joint="lift" multiplier="1" '
                    'offset="0.05"/>', replaced('<mimic joint="lift" multiplier="2" offset="-0.1"/>',
                                                '<mimic joint="lift2" multiplier="2" offset="-0.1"/>'))
    robot = load_robot(variant(tmp_path, text))
    assert [(k, float(m), float(o)) for ((k, m),), o in robot.drives()][6] == (1, 2.0, 0.0)
    assert (robot.joints[1].lower, robot.joints[1].upper) == (0.0, 0.85)


def test_a_mimic_joint_is_no_term_variable_and_no_gravity_column(telescope, tmp_path):
    with pytest.raises(ModelError, match=r"'lift2' is a mimic joint, with no variable of its own; write its value "
                                         r"1.0\*q2 \+ 0.0 in q2"):
        error_model_from_dict({"frames": {3: {"ez": ["lift2"]}}}, telescope, "m.yaml")
    table = tmp_path / "q.csv"
    table.write_text("q1,q2,q3,q4\n0.1,0.5,0.2,-0.3\n")
    code, out, err = gecgen("gravity", DATA / "telescope.yaml", table, "-o", tmp_path / "g.csv", "--joints", "lift2")
    assert code != 0 and "'lift2' mimics 'lift', whose tau_lift includes its load times the multiplier" in err
    code, out, err = gecgen("gravity", DATA / "telescope.yaml", table, "-o", tmp_path / "g.csv")
    assert code == 0, err
    assert out["columns"] == ["tau_slew", "tau_lift", "tau_boom", "tau_stick"]


# -- the commands on a mimic robot -----------------------------------------------------------------
def test_design_samples_the_independent_joints_within_the_narrowed_limits(tmp_path, telescope):
    code, out, err = gecgen("design", DATA / "telescope.yaml", "--poses", 12, "--candidates", 300, "-o",
                            tmp_path / "poses.csv")
    assert code == 0, err
    rows = np.loadtxt(tmp_path / "poses.csv", delimiter=",", skiprows=1)
    assert rows.shape == (12, 5)  # pose, q1..q4
    lo, hi = np.array([j.lower for j in telescope.joints]), np.array([j.upper for j in telescope.joints])
    assert np.all(rows[:, 1:] >= lo) and np.all(rows[:, 1:] <= hi)  # lift within lift2's 0.9 m, stick <= 0.3


def test_compensate_corrects_the_independent_joint_a_mimic_group_follows(telescope, rng):
    """Errors that are exactly an offset d of lift (q2): stage 1 and stage 2 rise by d along their z axes
    and the wrist turns by 2 d about its own. Compensation must take d off q2 and leave the rest."""
    cm = CompiledModel(telescope, load_error_model(None, telescope), backend="c")
    names = telescope.error_names()
    d = 2e-3
    c = np.zeros(telescope.n_errors)
    c[[names.index("2.ez"), names.index("3.ez"), names.index("7.er")]] = d, d, 2 * d
    q_cmd = random_q(telescope, rng, 4)
    q_cmd[:, 1] = np.clip(q_cmd[:, 1], 0.1, 0.8)
    q, status = cm.compensate(q_cmd, np.zeros((4, 6)), None, c)
    assert np.all(status == 0)
    np.testing.assert_allclose(q - q_cmd, np.tile([0, -d, 0, 0], (4, 1)), atol=1e-10)


def test_tiago_mimic_joints_are_off_its_chain():
    """TIAGo's gripper finger mimics the gripper joint, both beyond arm_7_link: the chain, and so the
    generated code, are those of a robot without mimic joints."""
    from gecgen.model.urdf import load_mass_tree

    tiago = load_robot(ROBOTS / "tiago.yaml")
    assert tiago.n == tiago.n_frames == 8 and not any(j.coupling for j in tiago.chain)
    tree = load_mass_tree(tiago.urdf, tiago.base_link)
    mimics = {j.name: j.mimic.root for j in tree.joint.values() if j.mimic}
    assert mimics == {"gripper_right_finger_joint": "gripper_finger_joint"}
    assert not set(mimics.values()) & set(tiago.joint_names)
