"""Load signals in the term language (wrench_torque, gravity, gravity_torque) and sign/abs: the
emitted values against pinocchio (Panda, a URDF with masses) and against finite differences of the
exact chain (industrial6r, DH), the term spellings and refusals, `gecgen gravity` against the
emitted gravity torques, and compensation across a load's sign change."""
import csv
import json
import subprocess

import numpy as np
import pytest
from conftest import JOINT_LOADS, ROBOTS, random_q

from gecgen.cli import main
from gecgen.emit import render
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import error_model_from_dict
from gecgen.model.kinematics import tool_pose
from gecgen.model.loads import catalog
from gecgen.runtime.compiled import OK, CompiledModel
from gecgen.symbolic.functions import all_functions

CONSTANT = {"default": ["1"]}


@pytest.fixture(scope="module")
def panda():
    """The Panda robot, its compiled constant model and its pinocchio model with the robot file's gravity."""
    pin = pytest.importorskip("pinocchio")
    robot = load_robot(ROBOTS / "panda.yaml")
    model = pin.buildModelFromUrdf(robot.urdf)
    model.gravity.linear = np.array([float(v) for v in robot.gravity])
    cm = CompiledModel(robot, error_model_from_dict(CONSTANT, robot, "<constant>"), "c")
    columns = [model.joints[model.getJointId(name)].idx_v for name in robot.joint_names]
    return pin, model, robot, cm, columns


def pin_q(model, robot, q):
    """pinocchio's configuration: the chain's joints from q, the fingers (off the chain) at zero."""
    out = np.zeros(model.nq)
    for name, v in zip(robot.joint_names, q):
        out[model.joints[model.getJointId(name)].idx_q] = v
    return out


def signal_columns(names, prefix):
    return {n: k for k, n in enumerate(names) if n.startswith(prefix)}


def test_gravity_torque_is_minus_pinocchios_generalized_gravity(panda):
    pin, model, robot, cm, columns = panda
    data = model.createData()
    q = random_q(robot, np.random.default_rng(1), 20)
    names, L = cm.load_signals(q)
    torque = signal_columns(names, "gravity_torque(")
    assert list(torque) == [f"gravity_torque(q{j})" for j in range(2, 8)]  # joint 1 turns about the vertical
    for i in range(len(q)):
        g = pin.computeGeneralizedGravity(model, data, pin_q(model, robot, q[i]))[columns]
        assert abs(g[0]) < 1e-12
        ours = np.array([L[i, k] for k in torque.values()])
        np.testing.assert_allclose(ours, -g[1:], rtol=1e-9, atol=1e-9 * np.abs(g).max())


def test_gravity_columns_span_pinocchios_regressor_row(panda):
    """For each joint: our columns are independent, pinocchio's gravity torque for random masses and
    centres of mass is a combination of them, and each of them a combination of pinocchio's
    regressor columns of the masses and first moments (so they span exactly that row)."""
    pin, model, robot, cm, columns = panda
    q = random_q(robot, np.random.default_rng(2), 120)
    names, L = cm.load_signals(q)
    data = model.createData()
    first_order = np.array([k % 10 < 4 for k in range(10 * (model.njoints - 1))])  # m, m c per body
    Y = np.array([pin.computeJointTorqueRegressor(model, data, pin_q(model, robot, qi), np.zeros(model.nv),
                                                  np.zeros(model.nv))[columns][:, first_order] for qi in q])
    rng = np.random.default_rng(3)
    heavy = model.copy()
    for k in range(1, model.njoints):
        heavy.inertias[k] = pin.Inertia(rng.uniform(0.5, 5), rng.normal(0, 0.1, 3), np.eye(3) * 0.01)
    hdata = heavy.createData()
    tau = np.array([pin.computeGeneralizedGravity(heavy, hdata, pin_q(model, robot, qi))[columns] for qi in q])
    for j in range(robot.n):
        G = L[:, list(signal_columns(names, f"gravity(q{j + 1},").values())]
        Yj = Y[:, j, :]
        assert G.shape[1] == np.linalg.matrix_rank(Yj, tol=1e-9 * np.abs(Yj).max(initial=1.0))
        if not G.shape[1]:
            assert np.abs(Yj).max() < 1e-12
            continue
        assert np.linalg.matrix_rank(G) == G.shape[1]
        fit = np.linalg.lstsq(G, tau[:, j], rcond=None)[0]
        assert np.linalg.norm(G @ fit - tau[:, j]) < 1e-9 * np.linalg.norm(tau[:, j]), j
        back = np.linalg.lstsq(Yj, G, rcond=None)[0]
        assert np.linalg.norm(Yj @ back - G) < 1e-9 * np.linalg.norm(G), j


def test_wrench_torque_is_the_transposed_frame_jacobian(panda):
    """tau = J^T w with pinocchio's Jacobian of the tool frame (panda_hand_tcp) in that frame."""
    pin, model, robot, cm, columns = panda
    data = model.createData()
    rng = np.random.default_rng(4)
    q, w = random_q(robot, rng, 10), rng.normal(0, 20, (10, 6))
    names, L = cm.load_signals(q, w)
    wrench = list(signal_columns(names, "wrench_torque(").values())
    tcp = model.getFrameId("panda_hand_tcp")
    for i in range(len(q)):
        J = pin.computeFrameJacobian(model, data, pin_q(model, robot, q[i]), tcp, pin.LOCAL)[:, columns]
        np.testing.assert_allclose(L[i, wrench], J.T @ w[i], rtol=1e-9, atol=1e-9)


def test_wrench_torque_is_the_virtual_work_of_the_wrench_on_a_dh_robot(rng):
    """industrial6r: the work of the wrench (sensor frame, at its origin) over a small joint motion,
    from central differences of the exact chain."""
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    cm = CompiledModel(robot, error_model_from_dict(CONSTANT, robot, "<constant>"), "c")
    q, w = random_q(robot, rng, 5), rng.normal(0, 50, (5, 6))
    names, L = cm.load_signals(q, w)
    h = 1e-6
    for j in range(robot.n):
        dq = np.zeros(robot.n)
        dq[j] = h
        plus, minus = tool_pose(robot, q + dq), tool_pose(robot, q - dq)
        dp = (plus[:, :3, 3] - minus[:, :3, 3]) / (2 * h)
        turn = np.einsum("nij,nkj->nik", plus[:, :3, :3], minus[:, :3, :3])  # I + 2h [dtheta]x + O(h^2), symmetric
        skew = (turn - turn.transpose(0, 2, 1)) / (4 * h)
        dtheta = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=1)
        T = tool_pose(robot, q)
        force, moment = np.einsum("nij,nj->ni", T[:, :3, :3], w[:, :3]), np.einsum("nij,nj->ni", T[:, :3, :3], w[:, 3:])
        work = np.einsum("ni,ni->n", force, dp) + np.einsum("ni,ni->n", moment, dtheta)
        np.testing.assert_allclose(L[:, names.index(f"wrench_torque(q{j + 1})")], work, rtol=1e-6, atol=1e-6)


def test_load_terms_agree_in_c_casadi_and_sympy_and_compose(rng):
    robot = load_robot(ROBOTS / "panda.yaml")
    model = error_model_from_dict(JOINT_LOADS, robot, "<loads>")
    c_model, ca_model = CompiledModel(robot, model, "c"), CompiledModel(robot, model, "casadi")
    fns = {f.name: f for f in all_functions(robot, model)}
    q, w = random_q(robot, rng, 3), rng.normal(0, 30, (3, 6))
    coef = rng.normal(0, 1e-4, len(model.coefficients))
    np.testing.assert_allclose(c_model.eps(q, w, None, coef), ca_model.eps(q, w, None, coef), atol=1e-13)
    names, L = c_model.load_signals(q, w)  # every signal, in numpy
    assert names == ca_model.load_signals(q, w)[0] == catalog(robot).names
    # the generated code computes the model's own signals only, in catalog order
    used = model.load_signals(robot)
    assert used == [n for n in names if n in {"gravity_torque(q6)", "wrench_torque(q2)", "gravity(q4,2)"}
                    or n.startswith("gravity(q6,")]
    own = [names.index(n) for n in used]
    f_c, f_ca = c_model.basis(q, w, None), ca_model.basis(q, w, None)
    np.testing.assert_allclose(f_c, f_ca, atol=1e-12)
    for i in range(3):
        np.testing.assert_allclose(L[i, own], fns["loads"].evaluate(q=q[i], w=w[i])["L"], atol=1e-12)
        f = fns["basis"].evaluate(q=q[i], w=w[i], aux=[])["f"]
        np.testing.assert_allclose(f, fns["basis_at_loads"].evaluate(q=q[i], w=w[i], aux=[], L=L[i, own])["f"],
                                   atol=1e-12)
        value = dict(zip(names, L[i]))
        expect = [1.0, np.sign(value["gravity_torque(q6)"]), *[value[f"gravity(q6,{r})"] for r in range(1, 5)],
                  q[i, 2] * value["wrench_torque(q2)"], abs(value["gravity(q4,2)"])]
        np.testing.assert_allclose(f, expect, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(f_c[i], expect, rtol=1e-12, atol=1e-12)  # the C's loads: the numpy values


def test_spellings_canonical_text_labels_and_round_trip():
    robot = load_robot(ROBOTS / "panda.yaml")
    spec = {"default": ["1"], "frames": {3: {"er": ["gravity(panda_joint2)", "wrench_torque(panda_joint3)",
                                                    "sign(gravity(q4, 1))", "gravity_torque(q6) * q6"]}}}
    model = error_model_from_dict(spec, robot, "<spellings>")
    terms = model.terms[6 * 3 + 4]
    rank = catalog(robot).gravity_rank(2)
    assert [t.text for t in terms] == [f"gravity(q2,{r})" for r in range(1, rank + 1)] + [
        "wrench_torque(q3)", "sign(gravity(q4,1))", "gravity_torque(q6)*q6"]
    assert [t.label for t in terms][:2] == ["gravity(panda_joint2, 1)", "gravity(panda_joint2, 2)"]
    again = error_model_from_dict(model.to_yaml_dict(robot), robot, "<round trip>")
    assert [t.text for t in again.terms[6 * 3 + 4]] == [t.text for t in terms]
    # every name load_signals returns is a term a model file can hold verbatim
    names = catalog(robot).names
    parsed = error_model_from_dict({"default": names}, robot, "<all>")
    assert [t.text for t in parsed.terms[0]] == names


@pytest.mark.parametrize("robot, term, expect", [
    ("pps", "gravity_torque(q5)", "needs link masses, which"),
    ("panda", "gravity(q1)", "gravity loads joint q1 (panda_joint1) in no posture (its axis is along gravity)"),
    ("panda", "gravity_torque(panda_joint1)", "in no posture"),
    ("pps", "gravity(lateral, 1)", "it moves across gravity"),
    ("panda", "gravity(q2, 13)", "joint q2 has 12 independent gravity columns: use gravity(q2, 1) .. gravity(q2, 12)"),
    ("panda", "gravity(q2, 0)", "independent gravity columns"),
    ("panda", "gravity(q2, 1.0)", "independent gravity columns"),
    ("panda", "gravity(q8, 1)", "'q8' is not a joint of panda; use a joint name or q1..q7"),
    ("panda", "wrench_torque(fx)", "'fx' is not a joint"),
    ("panda", "sign(gravity(q2))", "must stand alone"),
    ("panda", "gravity(q2, 1, 2)", "gravity takes (joint) or (joint, column)"),
    ("panda", "gravity_torque(q2, 1)", "gravity_torque takes one joint"),
    ("panda", "wrench_torque(q=q2)", "keyword arguments"),
    ("panda", "sign(q1, q2)", "sign takes one argument"),
    ("pps", "gravity_load(q5, mx)", "needs link masses, which"),
    ("humanoid", "wrench_load(arm_right_1_joint, mx)", "which frame 10 (arm_right_1_joint) does not carry"),
    ("humanoid", "gravity_load(torso_4_joint, tx)", "'tx' is not a wrench component; use one of fx fy fz mx my mz"),
    ("humanoid", "gravity_load(99, mx)", "'99' is not a frame of humanoid"),
    ("humanoid", "gravity_load(elbow, mx)", "'elbow' is not a frame of humanoid"),
    ("humanoid", "sign(gravity(torso_2_joint, mx))", "must stand alone"),
    ("humanoid", "gravity(torso_2_joint, mx, 999)", "frame 2 mx has"),
    ("humanoid", "gravity_load(torso_2_joint)", "gravity_load takes (frame, component)"),
    ("humanoid", "gravity_load(torso_1_joint, fx)", "gravity puts no fx on frame 1 (torso_1_joint) in any posture"),
])
def test_load_terms_are_refused_in_one_line(robot, term, expect):
    with pytest.raises(ModelError) as err:
        error_model_from_dict({"default": [term]}, load_robot(ROBOTS / f"{robot}.yaml"), "m.errors.yaml")
    message = str(err.value)
    assert expect in message and "m.errors.yaml" in message and "\n" not in message


def test_a_wrench_measured_upstream_loads_only_the_joints_before_it(tmp_path):
    text = (ROBOTS / "puma560.yaml").read_text()
    path = tmp_path / "puma560.yaml"
    path.write_text(text + "\nwrench_frame: 3\n")
    robot = load_robot(path)
    assert [n for n in catalog(robot).names if n.startswith("wrench_torque")] == [f"wrench_torque(q{j})"
                                                                                  for j in (1, 2, 3)]
    assert {n.split(",")[0] for n in catalog(robot).names if n.startswith("wrench_load")} == {
        f"wrench_load({f}" for f in (0, 1, 2, 3)}  # the frames that carry the sensor
    with pytest.raises(ModelError, match=r"measured in frame 3, which joint q4 does not move; use wrench_torque\(q1\)"):
        error_model_from_dict({"default": ["wrench_torque(q4)"]}, robot, "m")


def test_robot_gravity_key_is_validated(tmp_path):
    path = tmp_path / "puma560.yaml"
    path.write_text((ROBOTS / "puma560.yaml").read_text() + "\ngravity: [0, -9.8]\n")
    with pytest.raises(ModelError, match=r"puma560.yaml: gravity: expected a list of 3 numbers"):
        load_robot(path)


def test_gravity_command_agrees_with_the_emitted_torques_and_follows_the_robot_files_gravity(tmp_path, capsys, panda):
    """`gecgen gravity` (numpy, base link frame) and the emitted gravity_torque (chain, world) give the
    same numbers; on a Panda mounted on a wall (base turned, gravity given in that world) both still
    give the upright Panda's torques (its base's z points along the world's x, against gravity)."""
    _, _, robot, cm, _ = panda
    q = random_q(robot, np.random.default_rng(5), 6)
    table = tmp_path / "q.csv"
    table.write_text(",".join(f"q{i + 1}" for i in range(robot.n)) + "\n"
                     + "".join(",".join(map(repr, row)) + "\n" for row in q.tolist()))
    names, L = cm.load_signals(q)
    joints = [f"panda_joint{j}" for j in range(2, 8)]
    expected = L[:, [names.index(f"gravity_torque(q{j})") for j in range(2, 8)]]
    wall = tmp_path / "panda_wall.yaml"
    wall.write_text((ROBOTS / "panda.yaml").read_text().replace("urdf: panda/panda.urdf", f"urdf: {robot.urdf}")
                    + "base: {rotation: [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]}\ngravity: [-9.80665, 0, 0]\n")
    wall_robot = load_robot(wall)
    wall_model = CompiledModel(wall_robot, error_model_from_dict(CONSTANT, wall_robot, "<c>"), "c")
    wall_names, wall_L = wall_model.load_signals(q)
    assert wall_names == names
    np.testing.assert_allclose(wall_L[:, [names.index(f"gravity_torque(q{j})") for j in range(2, 8)]], expected,
                               atol=1e-12)
    for robot_file in (ROBOTS / "panda.yaml", wall):
        out = tmp_path / f"{robot_file.stem}.csv"
        args = ["gravity", str(robot_file), str(table), "--joints", ",".join(joints), "-o", str(out), "--json"]
        assert main(args) == 0
        assert json.loads(capsys.readouterr().out)["columns"] == [f"tau_{j}" for j in joints]
        tau = np.array([[float(v) for v in row[robot.n:]] for row in list(csv.reader(out.open()))[1:]])
        np.testing.assert_allclose(tau, expected, rtol=1e-12, atol=1e-12)


def bisect_root(fn, a: float, b: float) -> float:
    """A root of fn in [a, b] (opposite signs at the ends), to the last bit."""
    fa = fn(a)
    for _ in range(200):
        m = 0.5 * (a + b)
        if m in (a, b):
            break
        if np.sign(fn(m)) == np.sign(fa):
            a, fa = m, fn(m)
        else:
            b = m
    return a


@pytest.mark.parametrize("term, joint, bracket", [
    ("sign(gravity(q6, 4))", 6, None),  # exactly 0.0 at Q_BASE, changing sign with joint 7
    ("sign(gravity_torque(q6))", 5, (0.45, 0.92)),  # changes sign as joint 6 turns through the bracket
])
def test_compensate_converges_across_a_load_sign_change(term, joint, bracket, panda):
    """Free play that follows a load's sign: commands on both sides of the change and at it converge
    (the loads are held at the command); the correction jumps by the play across the change, and
    exactly at it (sign 0) lies half way."""
    _, _, robot, _, _ = panda
    play = 2e-3  # rad: the frame turns by +-1 mrad with the sign of the load
    model = error_model_from_dict({"default": ["1"], "frames": {6: {"er": ["1", term]}}}, robot, "<play>")
    cm = CompiledModel(robot, model, "c")
    coef = np.random.default_rng(6).normal(0, 2e-4, len(model.coefficients))
    names = catalog(robot).names
    step = np.eye(robot.n)[joint]

    def load(v):
        q = Q_BASE + (v - Q_BASE[joint]) * step
        return cm.load_signals(q[None])[1][0, names.index(term[len("sign("):-1].replace(", ", ","))]

    at = Q_BASE + ((bisect_root(load, *bracket) if bracket else Q_BASE[joint]) - Q_BASE[joint]) * step
    assert abs(load(at[joint])) < 1e-12 and load(at[joint] - 1e-3) * load(at[joint] + 1e-3) < 0
    assert (load(at[joint]) == 0.0) == (bracket is None)
    commands = np.array([at - 1e-3 * step, at, at + 1e-3 * step, at + 1e-9 * step, at - 1e-9 * step])
    for direction in (1, -1):  # one of them makes the correction cross the change
        coef[model.coefficient_names(robot).index(f"6.er:{term}")] = direction * play / 2
        q_out, status = cm.compensate(commands, None, None, coef)
        assert (status == OK).all(), (direction, status)
        below, above = q_out[0] - commands[0], q_out[2] - commands[2]
        assert 0.5 * play < np.abs(above - below).max() < 3 * play
        if bracket is None:
            np.testing.assert_allclose(q_out[1] - at, 0.5 * (below + above), atol=2e-5)


Q_BASE = np.array([0.3, -0.5, 0.4, -2.0, 0.0, 1.5, 0.0])


SIGN_DRIVER = r"""
#include <stdio.h>
#include "puma560.h"
int main(void) {
    const double q[2][PUMA560_NQ] = {{0.3, 0.0, 0.4, 0.0, 0.0, 0.0}, {0.3, -1.2, -0.4, 0.1, 0.0, 0.0}};
    const double w[6] = {10, -20, 30, 1, -2, 3};
    double f[PUMA560_NF];
    int i, k;
    for (i = 0; i < 2; ++i) {
        puma560_basis(q[i], w, NULL, f);
        for (k = 0; k < PUMA560_NF; ++k) printf("%.17g ", f[k]);
        printf("\n");
    }
    return 0;
}
"""


def test_sign_and_abs_in_strict_c_and_sign_of_zero_is_zero(tmp_path):
    """sign and abs compile clean under -pedantic -Wconversion; sign(0) = 0 for a variable and for a
    load signal that is exactly 0.0 (puma560's gravity(q4,1) with the wrist straight)."""
    robot = load_robot(ROBOTS / "puma560.yaml")
    model = error_model_from_dict({"default": ["1", "sign(q2)", "abs(q3)", "sign(gravity(q4, 1))",
                                               "wrench_torque(q1)*abs(fx)"]}, robot, "<sign>")
    for fname, text in render(robot, model).items():
        (tmp_path / fname).write_text(text)
    (tmp_path / "driver.c").write_text(SIGN_DRIVER)
    flags = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-Wshadow", "-Wconversion"]
    build = subprocess.run(["cc", *flags, "driver.c", "puma560.c", "-o", "driver", "-lm"], cwd=tmp_path,
                           capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    rows = subprocess.run(["./driver"], cwd=tmp_path, capture_output=True, text=True, check=True).stdout.split("\n")
    f = np.array([[float(v) for v in row.split()] for row in rows if row.strip()])
    q = np.array([[0.3, 0.0, 0.4, 0.0, 0.0, 0.0], [0.3, -1.2, -0.4, 0.1, 0.0, 0.0]])
    names, L = CompiledModel(robot, model, "c").load_signals(q, [10, -20, 30, 1, -2, 3])
    load = L[:, names.index("gravity(q4,1)")]
    assert load[0] == 0.0 and load[1] != 0.0
    expect = np.column_stack([np.ones(2), np.sign(q[:, 1]), np.abs(q[:, 2]), np.sign(load),
                              10 * L[:, names.index("wrench_torque(q1)")]])
    assert f[0, 1] == 0.0 and f[0, 3] == 0.0
    np.testing.assert_allclose(f, expect, rtol=1e-14, atol=1e-14)


def test_gravity_torque_needs_the_inertials_and_a_mass_below_the_joint(tmp_path):
    """A URDF whose inertials are broken keeps its other load terms; a massless arm has no torque."""
    import re

    from test_gravity import arm_urdf

    (tmp_path / "arm.yaml").write_text("name: arm\nangle_unit: rad\nurdf: arm.urdf\nbase_link: base\ntip_link: hand\n"
                                       "targets: {t: [0.1, 0, 0]}\n")
    arm_urdf(tmp_path / "arm.urdf", hand_mass="<mass/>")
    robot = load_robot(tmp_path / "arm.yaml")
    assert error_model_from_dict({"default": ["gravity(elbow)", "wrench_torque(elbow)"]}, robot, "m")
    with pytest.raises(ModelError, match=r"term 'gravity_torque\(elbow\)': .*link 'hand' inertial: no <mass value"):
        error_model_from_dict({"default": ["gravity_torque(elbow)"]}, robot, "m")
    path = arm_urdf(tmp_path / "arm.urdf")
    path.write_text(re.sub(r'<mass value="[^"]*"/>', '<mass value="0"/>', path.read_text()))
    with pytest.raises(ModelError, match=r"the URDF's masses put no gravity torque on joint q1 \(shoulder\)"):
        error_model_from_dict({"default": ["gravity_torque(shoulder)"]}, load_robot(tmp_path / "arm.yaml"), "m")
