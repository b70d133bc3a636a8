"""Frame loads: the whole wrench every frame carries (gravity_load, gravity(F, c, r), wrench_load),
passive joints and the base included. Against pinocchio's static RNEA (a serial URDF, the TALOS tree
and a robot with a passive coupled joint), against the derivative of the potential energy in the
frame's own generalized errors (a DH robot with random masses), against the simulator's independent
walk down the URDF, in the generated C and CasADi; the truth's frame and beam compliances; the term
spellings (their refusals are in test_loads.py); `gecgen gravity` on a robot with couplings."""
import csv

import numpy as np
import pytest
from conftest import FRAME_LOADS, ROBOTS, random_q

from gecgen.cli import main
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import error_model_from_dict
from gecgen.model.gravity import robot_frame_wrenches
from gecgen.model.kinematics import error_transform, frames, joint_values
from gecgen.model.loads import catalog, signal_values
from gecgen.model.robot import ERROR_NAMES, WRENCH
from gecgen.runtime.compiled import CompiledModel
from gecgen.simulate.truth import beam_compliance, load_truth

TALOS = ROBOTS.parent / "tests" / "data" / "talos" / "talos.yaml"
#: a frame's error that a small motion of each wrench component does work through: fx..mz -> ex ey ez ep es er
WORK = [ERROR_NAMES.index(e) for e in ("ex", "ey", "ez", "ep", "es", "er")]


def frame_loads(robot, q, kind="gravity_load", w=None):
    """(P, m+1, 6) of the catalog's `kind` signals (a component the catalog lacks is zero: refused as
    never loaded)."""
    names = catalog(robot).names
    L = signal_values(robot, q, np.zeros(6) if w is None else w)
    out = np.zeros((len(q), robot.n_frames + 1, 6))
    for f in range(robot.n_frames + 1):
        for c, comp in enumerate(WRENCH):
            if f"{kind}({f},{comp})" in names:
                out[:, f, c] = L[:, names.index(f"{kind}({f},{comp})")]
    return out


@pytest.mark.parametrize("path", [ROBOTS / "panda.yaml", TALOS, ROBOTS / "humanoid.yaml"])
def test_gravity_load_is_minus_pinocchios_transmitted_force(path):
    """data.f[joint] after a static RNEA is the spatial force the joint passes to its child, in the
    joint's frame (the child link's, where gecgen's frame sits): ours is the load, its opposite. The
    humanoid's passive torso joint takes its value from the couplings."""
    pin = pytest.importorskip("pinocchio")
    robot = load_robot(path)
    model = pin.buildModelFromUrdf(robot.urdf)
    model.gravity.linear = np.array([float(v) for v in robot.gravity])
    data = model.createData()
    q = random_q(robot, np.random.default_rng(3), 12)
    ours = frame_loads(robot, q)
    values = joint_values(robot, q)
    for i in range(len(q)):
        config = pin.neutral(model)
        for joint, v in zip(robot.chain, values[i]):
            config[model.joints[model.getJointId(joint.name)].idx_q] = v
        pin.rnea(model, data, config, np.zeros(model.nv), np.zeros(model.nv))
        theirs = np.array([-data.f[model.getJointId(j.name)].vector for j in robot.chain])
        np.testing.assert_allclose(ours[i, 1:], theirs, rtol=1e-9, atol=1e-9 * np.abs(theirs).max())


def test_the_simulators_walk_down_the_urdf_agrees():
    robot = load_robot(ROBOTS / "humanoid.yaml")
    q = random_q(robot, np.random.default_rng(4), 20)
    walked = robot_frame_wrenches(robot, q, list(range(1, robot.n_frames + 1)))
    np.testing.assert_allclose(frame_loads(robot, q)[:, 1:], walked, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("path", [ROBOTS / "industrial6r.yaml", TALOS])
def test_frame_regressor_spans_minus_the_derivative_of_the_potential_energy(path):
    """Random point masses rigid with every frame: the work of gravity over a small generalized error
    of frame F (everything after it moves, as the errors do) is component c of the wrench F carries
    times that motion, by central differences of the exact chain; it lies in the span of the kept
    columns gravity(F, c, 1..r) at every pose (the masses are the same at all poses)."""
    robot = load_robot(path)
    rng = np.random.default_rng(5)
    masses, at = rng.uniform(1, 20, robot.n_frames + 1), rng.normal(0, 0.2, (robot.n_frames + 1, 3))
    masses[0] = 0.0
    g = np.array([float(v) for v in robot.gravity])
    q = random_q(robot, rng, 120)
    names, L = catalog(robot).names, signal_values(robot, q, np.zeros(6))

    def potential(eps):
        W = frames(robot, q, eps)
        return -sum(m * (W[k][:, :3, :3] @ at[k] + W[k][:, :3, 3]) @ g for k, m in enumerate(masses))

    h = 1e-6
    for f in range(robot.n_frames + 1):
        for c, comp in enumerate(WRENCH):
            eps = np.zeros(robot.n_errors)
            eps[6 * f + WORK[c]] = h
            load = -(potential(eps) - potential(-eps)) / (2 * h)
            cols = [k for k, n in enumerate(names) if n.startswith(f"gravity({f},{comp},")]
            if not cols:
                assert np.abs(load).max() < 1e-6, (f, comp)
                continue
            coef, *_ = np.linalg.lstsq(L[:, cols], load, rcond=None)
            np.testing.assert_allclose(L[:, cols] @ coef, load, atol=1e-6 * max(1.0, np.abs(load).max()))


def test_wrench_load_moves_the_measured_wrench_to_each_frame(rng):
    """The measured wrench, read in the sensor (tool) frame, as the frames that carry it feel it:
    force and moment about the frame's origin in its axes, from the exact chain."""
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    q, w = random_q(robot, rng, 6), rng.normal(0, 40, (6, 6))
    ours = frame_loads(robot, q, "wrench_load", w)
    W = frames(robot, q)
    tool = W[robot.n_frames + 1]
    force, moment = np.einsum("nij,nj->ni", tool[:, :3, :3], w[:, :3]), np.einsum("nij,nj->ni", tool[:, :3, :3], w[:, 3:])
    for f in range(robot.n_frames + 1):
        R, o = W[f][:, :3, :3], W[f][:, :3, 3]
        about = moment + np.cross(tool[:, :3, 3] - o, force)
        expect = np.concatenate([np.einsum("nji,nj->ni", R, force), np.einsum("nji,nj->ni", R, about)], axis=1)
        np.testing.assert_allclose(ours[:, f], expect, rtol=1e-10, atol=1e-9)


def test_frame_loads_in_generated_c_and_casadi_and_their_spellings(rng):
    robot = load_robot(ROBOTS / "humanoid.yaml")
    model = error_model_from_dict(FRAME_LOADS, robot, "<frame loads>")
    assert [t.text for t in model.terms[6 * 4 + 3]] == ["1", "gravity_load(4,my)", "q2", "q3"]  # and its ratios
    rank = catalog(robot).frame_rank(2, 3)
    assert [t.text for t in model.terms[6 * 2 + 5]] == ["1"] + [f"gravity(2,mx,{r})" for r in range(1, rank + 1)]
    assert [t.label for t in model.terms[6 * 2 + 5]][1] == "gravity(torso_2_joint, mx, 1)"
    c_model, ca_model = CompiledModel(robot, model, "c"), CompiledModel(robot, model, "casadi")
    q, w = random_q(robot, rng, 4), rng.normal(0, 30, (4, 6))
    names, L = c_model.load_signals(q, w)
    value = [dict(zip(names, row)) for row in L]
    f_c, f_ca = c_model.basis(q, w, None), ca_model.basis(q, w, None)
    np.testing.assert_allclose(f_c, f_ca, atol=1e-12)
    for i in range(len(q)):
        term = dict(value[i], **{"1": 1.0, "q1*wrench_load(2,mz)": q[i, 0] * value[i]["wrench_load(2,mz)"],
                                 "q2": q[i, 1], "q3": q[i, 2], "sign(gravity(5,mx,1))": np.sign(value[i]["gravity(5,mx,1)"])})
        np.testing.assert_allclose(f_c[i], [term[t.text] for t in model.unique_terms()], rtol=1e-12, atol=1e-12)
    # the generated code computes the model's own signals only
    assert model.load_signals(robot) == [n for n in names if n in {"gravity_load(4,my)", "wrench_load(2,mz)",
                                                                   "gravity(5,mx,1)"} or n.startswith("gravity(2,mx,")]


def test_frame_compliance_turns_the_frames_errors_with_its_wrench():
    """The truth's frame_compliance adds C times the wrench the frame carries (from the URDF walk)."""
    from gecgen.simulate.truth import frame_wrenches, true_state
    robot = load_robot(ROBOTS / "humanoid.yaml")
    spec = {"masses": "urdf", "gravity": [0, 0, -9.81],
            "sources": [{"type": "frame_compliance", "frame": "torso_4_joint", "compliance": {"es": 6e-5}},
                        {"type": "frame_compliance", "frame": 5, "compliance": {"ey": {"fy": 1e-7, "mz": 2e-6}}}]}
    truth = load_truth(spec, robot)
    q = random_q(robot, np.random.default_rng(6), 8)
    _, eps = true_state(robot, truth, q, np.zeros(8), np.zeros(3), {}, np.ones_like(q))
    W = frame_wrenches(robot, truth, q, np.zeros(8), np.zeros(3))
    np.testing.assert_allclose(W[:, 1:], robot_frame_wrenches(robot, q, list(range(1, robot.n_frames + 1)),
                                                              truth.gravity), rtol=1e-12, atol=1e-12)
    expect = np.zeros_like(eps)
    expect[:, 6 * 4 + 3] = 6e-5 * W[:, 4, 4]
    expect[:, 6 * 5 + 1] = 1e-7 * W[:, 5, 1] + 2e-6 * W[:, 5, 5]
    np.testing.assert_allclose(eps, expect, rtol=1e-12, atol=1e-15)
    with pytest.raises(ModelError, match=r"sources\[0\].compliance: 'eq' is not a generalized error"):
        load_truth({"sources": [{"type": "frame_compliance", "frame": 1, "compliance": {"eq": 1e-5}}]}, robot)
    with pytest.raises(ModelError, match=r"sources\[0\].frame: 'elbow' is not a frame"):
        load_truth({"sources": [{"type": "frame_compliance", "frame": "elbow", "compliance": {"ep": 1e-5}}]}, robot)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_beam_compliance_is_the_cantilevers_closed_form(axis):
    """A cantilever of length L along `axis`, 1/EI = k: a tip force F across it deflects the tip by
    F L^3 k / 3 and turns it by F L^2 k / 2; a tip moment M by M L^2 k / 2 and M L k. Applied as the
    frame's errors (E at the clamp), the tip point moves and turns by exactly that, to first order."""
    L, k = 0.7, 3e-6
    C = beam_compliance(axis, L, k)
    u = np.eye(3)["xyz".index(axis)]
    tip = L * u
    for v in (e for e in np.eye(3) if abs(e @ u) < 0.5):
        w = np.cross(u, v)
        for F, M in ((1.0, 0.0), (0.0, 1.0)):
            wrench = np.concatenate([F * v, M * w + np.cross(tip, F * v)])  # about the clamp (the frame's origin)
            eps = C @ wrench
            E = error_transform(eps[None] * 1e-3)[0]  # a small load: the first-order answer
            moved = (E[:3, :3] @ tip + E[:3, 3] - tip) / 1e-3
            np.testing.assert_allclose(moved @ v, F * L ** 3 * k / 3 + M * L ** 2 * k / 2, rtol=1e-5)
            np.testing.assert_allclose(moved @ u, 0.0, atol=1e-12)
            turn = E[:3, :3] - np.eye(3)
            np.testing.assert_allclose(np.array([turn[2, 1], turn[0, 2], turn[1, 0]]) / 1e-3 @ w,
                                       F * L ** 2 * k / 2 + M * L * k, rtol=1e-5)


def test_gravity_command_on_a_robot_with_couplings_writes_torques_and_wrenches(tmp_path, capsys):
    """The passive torso joint's load reaches the readings it follows, by virtual work; --wrench
    writes the six components of every frame (the passive one's too)."""
    robot = load_robot(ROBOTS / "humanoid.yaml")
    q = random_q(robot, np.random.default_rng(7), 5)
    table = tmp_path / "q.csv"
    with open(table, "w", newline="") as f:
        csv.writer(f).writerows([[f"q{k + 1}" for k in range(robot.n)], *q.tolist()])
    out = tmp_path / "out.csv"
    assert main(["gravity", str(ROBOTS / "humanoid.yaml"), str(table), "-o", str(out), "--wrench"]) == 0, \
        capsys.readouterr().err
    rows = list(csv.DictReader(open(out)))
    names, L = catalog(robot).names, signal_values(robot, q, np.zeros(6))
    for k, name in enumerate(robot.joint_names):
        if f"gravity_torque(q{k + 1})" in names:
            np.testing.assert_allclose([float(r[f"tau_{name}"]) for r in rows],
                                       L[:, names.index(f"gravity_torque(q{k + 1})")], rtol=1e-10, atol=1e-9)
    loads = frame_loads(robot, q)
    for f, joint in enumerate(robot.chain, start=1):
        for c, comp in enumerate(WRENCH):
            np.testing.assert_allclose([float(r[f"{comp}_{joint.name}"]) for r in rows], loads[:, f, c],
                                       rtol=1e-10, atol=1e-9)


def test_a_model_with_frame_loads_compiles_pedantic_runs_clean_and_compensates(tmp_path, rng):
    """The Panda with lateral and measured-wrench loads on its wrist: the generated C builds under
    -pedantic -Wconversion with the sanitizers and runs clean; compensating with it puts the modelled
    tool where the nominal model puts the command (the loads held at the command's, as for every
    load signal)."""
    import subprocess

    from gecgen.emit import render
    from gecgen.model.kinematics import tool_pose
    from test_emit import DRIVER

    robot = load_robot(ROBOTS / "panda.yaml")
    spec = {"default": ["1"], "frames": {4: {"ep": ["1", "gravity_load(panda_joint4, mx)", "wrench_load(4, mx)"]},
                                         6: {"es": ["1", "gravity(q6, my)"]}}}
    model = error_model_from_dict(spec, robot, "<frame loads>")
    for name, text in render(robot, model).items():
        (tmp_path / name).write_text(text)
    (tmp_path / "driver.c").write_text(DRIVER % {"name": "panda", "N": "PANDA"})
    flags = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-Wshadow", "-Wconversion", "-g",
             "-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
    build = subprocess.run(["cc", *flags, "driver.c", "panda.c", "-o", "driver", "-lm"], cwd=tmp_path,
                           capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    run = subprocess.run(["./driver"], cwd=tmp_path, capture_output=True, text=True)
    assert "runtime error" not in run.stderr and "AddressSanitizer" not in run.stderr, run.stderr
    cm = CompiledModel(robot, model, "c")
    c = rng.normal(0, 2e-4, len(model.coefficients))
    q = random_q(robot, rng, 6) * 0.5
    w = np.tile([0.0, 0.0, -30.0, 0.5, -0.2, 0.0], (6, 1))
    fixed, status, _ = cm.correct(q, w, None, c)
    ok = status == 0
    assert ok.sum() >= 4, status
    W = frames(robot, fixed, cm.eps(q, w, None, c))  # the errors at the command's loads
    np.testing.assert_allclose(W[robot.n_frames + 1][ok][:, :3, 3], tool_pose(robot, q)[ok][:, :3, 3], atol=1e-9)
