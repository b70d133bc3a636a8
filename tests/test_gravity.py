"""Gravity torques from URDF masses: against the closed form of a two-link arm with a rigid hand
and an off-chain finger, against -dV/dq of the potential energy, and refusals in one line."""
import csv
import json

import numpy as np
import pytest
from conftest import ROBOTS, random_q

from gecgen.cli import main
from gecgen.model import ModelError, load_robot
from gecgen.model.gravity import gravity_torques, load_mass_tree, robot_gravity_torques

G = 9.80665
M1, M2, M3, M4 = 3.0, 2.0, 0.7, 0.2  # link1, link2, hand (fixed to link2), finger (prismatic off the chain)
L1, C2, L2 = 0.5, 0.15, 0.35


def arm_urdf(path, hand_mass='<mass value="0.7"/>'):
    """A vertical two-link arm: joints about +y, links along x, the hand rigidly at x = L2 on link2."""
    path.write_text(f"""<?xml version="1.0"?>
<robot name="planar">
  <link name="base"/>
  <link name="link1"><inertial><origin xyz="{L1 / 2} 0 0"/><mass value="{M1}"/></inertial></link>
  <link name="link2"><inertial><origin xyz="{C2} 0 0"/><mass value="{M2}"/></inertial></link>
  <link name="hand"><inertial>{hand_mass}</inertial></link>
  <link name="finger"><inertial><mass value="{M4}"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="link1"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 1 0"/><limit lower="-3" upper="3"/></joint>
  <joint name="elbow" type="revolute"><parent link="link1"/><child link="link2"/>
    <origin xyz="{L1} 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3"/></joint>
  <joint name="wrist_mount" type="fixed"><parent link="link2"/><child link="hand"/><origin xyz="{L2} 0 0"/></joint>
  <joint name="grip" type="prismatic"><parent link="hand"/><child link="finger"/>
    <axis xyz="0 0 1"/><limit lower="0" upper="0.05"/></joint>
</robot>
""")
    return path


def test_two_link_arm_matches_the_closed_form(tmp_path):
    tree = load_mass_tree(arm_urdf(tmp_path / "arm.urdf"), "base")
    q1, q2 = np.random.default_rng(0).uniform(-3, 3, (2, 50))
    tau = gravity_torques(tree, {"shoulder": q1, "elbow": q2, "grip": np.full(50, 0.03)}, ["shoulder", "elbow", "grip"])
    # a turn by q about +y takes x to (cos q, 0, -sin q); the torque of weight m g at lever x about +y is m g x
    c1, c12, s12 = np.cos(q1), np.cos(q1 + q2), np.sin(q1 + q2)
    tail = M3 + M4
    finger = M4 * 0.03 * s12  # the finger sits 0.03 m along the hand's z, which the turn tips to (sin, 0, cos)
    assert np.allclose(tau[:, 0], G * (M1 * L1 / 2 * c1 + M2 * (L1 * c1 + C2 * c12) + tail * (L1 * c1 + L2 * c12)
                                       + finger), rtol=1e-12, atol=1e-12)
    assert np.allclose(tau[:, 1], G * ((M2 * C2 + tail * L2) * c12 + finger), rtol=1e-12, atol=1e-12)
    # the finger's weight along its own axis, the hand's z
    assert np.allclose(tau[:, 2], -G * M4 * c12, rtol=1e-12, atol=1e-12)


def test_torques_are_minus_the_gradient_of_the_potential_energy(tmp_path):
    """Virtual work on the TIAGo URDF (56 links, the gripper's fingers off the chain): tau_i = -dV/dq_i."""
    robot = load_robot(ROBOTS / "tiago.yaml")
    tree = load_mass_tree(robot.urdf, robot.base_link)
    q = random_q(robot, np.random.default_rng(1), 20)
    names = list(robot.joint_names)

    def potential(qq):  # V = -sum m g . c = -g . (first moment of mass)
        return -first_moment(tree, dict(zip(names, qq.T))) @ np.array([0, 0, -G])

    tau = gravity_torques(tree, dict(zip(names, q.T)), names)
    h = 1e-6
    for j in range(robot.n):
        dq = np.zeros(robot.n)
        dq[j] = h
        grad = (potential(q + dq) - potential(q - dq)) / (2 * h)
        assert np.allclose(tau[:, j], -grad, atol=1e-6), names[j]
    lifted = sum(tree.mass.get(k, 0.0) for k in below(tree, "torso_lift_link"))
    assert lifted > 10 and np.allclose(tau[:, 0], -G * lifted)  # the torso lifts everything above it
    assert np.allclose(tau[:, 1], 0.0, atol=1e-12)  # arm_1 turns about the vertical


def below(tree, link) -> set:
    out, todo = set(), [link]
    while todo:
        k = todo.pop()
        out.add(k)
        todo += [c for c, p in tree.parent.items() if p == k]
    return out


def first_moment(tree, q) -> np.ndarray:
    """sum m * c over every link (P, 3), composed link by link from the URDF transforms (independent
    of the subtree sums in gravity_torques)."""
    from scipy.spatial.transform import Rotation

    P = len(next(iter(q.values())))
    world = {tree.links[0]: np.broadcast_to(np.eye(4), (P, 4, 4))}
    total = np.zeros((P, 3))
    for link in tree.links[1:]:
        j = tree.joint[link]
        motion = np.broadcast_to(np.eye(4), (P, 4, 4)).copy()
        v = q.get(j.name, np.zeros(P))
        if j.kind == "R":
            motion[:, :3, :3] = Rotation.from_rotvec(np.outer(v, j.axis)).as_matrix()
        elif j.kind == "P":
            motion[:, :3, 3] = np.outer(v, j.axis)
        world[link] = world[tree.parent[link]] @ j.origin @ motion
    for link, m in tree.mass.items():
        if link in world:
            total += m * (world[link][:, :3, :3] @ tree.com[link] + world[link][:, :3, 3])
    return total


def test_gravity_command_appends_columns_and_copies_every_cell(tmp_path, capsys):
    table = tmp_path / "commands.csv"
    robot = load_robot(ROBOTS / "tiago.yaml")
    q = random_q(robot, np.random.default_rng(2), 5)
    with table.open("w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["label", *[f"q{i + 1}" for i in range(robot.n)]])
        out.writerows([[f"p{k}", *[f"{v:.6f}" for v in row]] for k, row in enumerate(q)])
    assert main(["gravity", str(ROBOTS / "tiago.yaml"), str(table), "-o", str(tmp_path / "out.csv"),
                 "--joints", "arm_2_joint,arm_6_joint", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["columns"] == ["tau_arm_2_joint", "tau_arm_6_joint"] and report["unit"]["tau_arm_2_joint"] == "N m"
    rows = list(csv.reader((tmp_path / "out.csv").open()))
    original = list(csv.reader(table.open()))
    assert rows[0] == original[0] + report["columns"]
    assert [r[:-2] for r in rows[1:]] == original[1:]
    expected = robot_gravity_torques(robot, np.array([[float(v) for v in r[1:]] for r in original[1:]]),
                                     ["arm_2_joint", "arm_6_joint"])
    assert np.array_equal(np.array([[float(v) for v in r[-2:]] for r in rows[1:]]), expected)


@pytest.mark.parametrize("case, expect", [
    ("dh", "gravity torques need the link masses of a URDF"),
    ("coupled dh", "gravity torques need the link masses of a URDF"),  # not its couplings
    ("joint", "--joints: 'elbow' is not a joint of tiago"),
    ("clash", "column 'tau_arm_2_joint' is already there"),
    ("gravity", "--gravity 0,-9.8: expected three finite numbers"),
])
def test_gravity_command_refuses_in_one_line(case, expect, tmp_path, capsys):
    robot = {"dh": "pps.yaml", "coupled dh": "fanuc.yaml"}.get(case, "tiago.yaml")
    n = load_robot(ROBOTS / robot).n
    table = tmp_path / "t.csv"
    header = [f"q{i + 1}" for i in range(n)] + (["tau_arm_2_joint"] if case == "clash" else [])
    table.write_text(",".join(header) + "\n" + ",".join(["0.1"] * len(header)) + "\n")
    args = ["gravity", str(ROBOTS / robot), str(table), "-o", str(tmp_path / "o.csv"),
            "--joints", {"joint": "elbow", "dh": "theta", "coupled dh": "J2"}.get(case, "arm_2_joint")]
    if case == "gravity":
        args += ["--gravity", "0,-9.8"]
    assert main(args) != 0
    err = capsys.readouterr().err.strip()
    assert expect in err and "\n" not in err


def test_a_link_without_mass_value_or_a_massless_subtree_is_refused(tmp_path):
    with pytest.raises(ModelError, match="link 'hand' inertial: no <mass value=...>"):
        load_mass_tree(arm_urdf(tmp_path / "a.urdf", hand_mass="<mass/>"), "base")
    tree = load_mass_tree(arm_urdf(tmp_path / "b.urdf"), "hand")  # only the finger below the hand
    with pytest.raises(ModelError, match="'shoulder' is not a moving joint below the base link"):
        gravity_torques(tree, {"grip": np.zeros(1)}, ["shoulder"])


def test_compensation_of_an_elastic_model_needs_and_uses_the_torques_of_the_commands(tmp_path, capsys):
    """End to end on a simulated TIAGo whose arm_4 twists under gravity: identify the shipped elastic
    model from data with the torques, then compensate commands to which `gecgen gravity` added them.
    The true robot at the corrected joints puts the markers where the nominal one does at the commands."""
    from gecgen.model.kinematics import target_positions
    from gecgen.model.measurements import Measurements, write_measurements

    robot = load_robot(ROBOTS / "tiago.yaml")
    joints = [f"arm_{k}_joint" for k in range(2, 8)]
    rng = np.random.default_rng(3)
    errors = np.random.default_rng(7).normal(0, 5e-4, robot.n_errors)

    def truth(q):
        eps = np.tile(errors, (len(q), 1))
        eps[:, 5 * 6 + 4] += 3e-4 * robot_gravity_torques(robot, q, ["arm_4_joint"])[:, 0]
        return target_positions(robot, q, eps)

    q = random_q(robot, rng, 150)
    n = len(q)
    data = Measurements(q, np.zeros((n, 6)), robot_gravity_torques(robot, q, joints), tuple(f"tau_{j}" for j in joints),
                        np.arange(n), np.repeat(np.arange(n), 4), np.tile(np.arange(4), n), truth(q).reshape(-1, 3), "sim")
    write_measurements(tmp_path / "train.csv", robot, data, wrench=False)
    calib = tmp_path / "c.json"
    assert main(["identify", str(ROBOTS / "tiago.yaml"), str(tmp_path / "train.csv"), "--errors",
                 str(ROBOTS / "tiago.elastic.errors.yaml"), "-o", str(calib), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["train"]["rms_mm"] < 1e-3

    q_cmd = random_q(robot, rng, 6)
    cmds = tmp_path / "cmds.csv"
    cmds.write_text(",".join(f"q{i + 1}" for i in range(robot.n)) + "\n"
                    + "".join(",".join(map(repr, row)) + "\n" for row in q_cmd.tolist()))
    assert main(["compensate", str(calib), str(cmds), "-o", str(tmp_path / "x.csv")]) != 0
    assert "missing column 'tau_arm_2_joint'" in capsys.readouterr().err  # and says gecgen gravity writes it
    assert main(["gravity", str(ROBOTS / "tiago.yaml"), str(cmds), "--joints", ",".join(joints),
                 "-o", str(tmp_path / "cmds_tau.csv")]) == 0
    assert main(["compensate", str(calib), str(tmp_path / "cmds_tau.csv"), "-o", str(tmp_path / "out.csv")]) == 0
    capsys.readouterr()
    q_new = np.array([[float(v) for v in row[:robot.n]] for row in list(csv.reader((tmp_path / "out.csv").open()))[1:]])
    nominal = target_positions(robot, q_cmd)
    before = 1e3 * np.linalg.norm(truth(q_cmd) - nominal, axis=-1).max()
    after = 1e3 * np.linalg.norm(truth(q_new) - nominal, axis=-1).max()
    # the command's torque stands in for the corrected pose's: a second-order difference of micrometres
    assert before > 0.5 and after < 0.02, (before, after)
