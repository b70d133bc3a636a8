"""Branched robots (trees, issue 19): TALOS's upper body (tests/data/talos: a two-joint torso carrying
two 7-joint arms, from example-robot-data) as one robot with two branches.

Checked against independent computation: the hands' targets against pinocchio's forward kinematics of
the whole URDF tree, gravity_torque against pinocchio's generalized gravity, the generated J_e against
finite differences of the exact tree, the emitted gravity regressor against finite differences of the
potential energy, and the structural identifiable count against the numerical rank of H_e."""
import numpy as np
import pytest
from conftest import ROOT, random_q

from gecgen.model import ModelError, load_error_model, load_robot
from gecgen.model.kinematics import frames, target_positions
from gecgen.runtime.compiled import CompiledModel

pin = pytest.importorskip("pinocchio")

DATA = ROOT / "tests" / "data" / "talos"


@pytest.fixture(scope="module")
def talos():
    return load_robot(DATA / "talos.yaml")


def test_a_tree_numbers_shared_frames_once(talos):
    assert talos.n == talos.n_frames == 16 and talos.n_errors == 6 * 17
    # torso 1-2, left arm 3-9 hanging from torso_2, right arm 10-16 hanging from torso_2 too
    assert talos.parents == (0, 1, 2, 3, 4, 5, 6, 7, 8, 2, 10, 11, 12, 13, 14, 15)
    assert [(b.name, b.tip) for b in talos.branches] == [("left", 9), ("right", 16)]
    assert talos.subtree(2) == list(range(2, 17)) and talos.subtree(10) == list(range(10, 17))
    assert talos.path(12) == [0, 1, 2, 10, 11, 12]
    assert {t: talos.branch_of(t) for t in talos.targets} == {"lh": 0, "rh": 1, "rh2": 1}


def pin_setup(talos):
    model = pin.buildModelFromUrdf(str(DATA / "talos_reduced.urdf"))
    model.gravity.linear = np.array([float(g) for g in talos.gravity])
    return model, model.createData()


def pin_config(model, talos, q):
    cfg = np.zeros(model.nq)  # every joint off the tree (legs, head, grippers) at zero
    for k, name in enumerate(talos.joint_names):
        cfg[model.joints[model.getJointId(name)].idx_q] = q[k]
    return cfg


def test_kinematics_and_gravity_of_the_tree_agree_with_pinocchio(talos, rng):
    model, data = pin_setup(talos)
    cm = CompiledModel(talos, load_error_model(None, talos), backend="c")
    names = cm.load_signals(np.zeros((1, talos.n)))[0]
    loaded = range(2, talos.n + 1)  # torso_1 turns about the vertical: gravity never loads it
    assert all(f"gravity_torque(q{k})" in names for k in loaded) and "gravity_torque(q1)" not in names
    for q in random_q(talos, rng, 5):
        cfg = pin_config(model, talos, q)
        pin.forwardKinematics(model, data, cfg)
        pin.updateFramePlacements(model, data)
        P = target_positions(talos, q[None])[0]
        for t, (k, link) in (("lh", (0, "arm_left_7_link")), ("rh", (1, "arm_right_7_link")),
                             ("rh2", (2, "arm_right_7_link"))):
            T = data.oMf[model.getFrameId(link)].homogeneous
            np.testing.assert_allclose(P[k], T[:3, :3] @ np.array(talos.targets[t]) + T[:3, 3], atol=1e-12)
        tau = pin.computeGeneralizedGravity(model, data, cfg)
        idx = [model.joints[model.getJointId(n)].idx_v for n in talos.joint_names]
        _, L = cm.load_signals(q[None])
        got = [0.0] + [L[0, names.index(f"gravity_torque(q{k})")] for k in loaded]
        # pinocchio's gravity term is what holds the robot: minus gecgen's tau = -dV/dq
        np.testing.assert_allclose(got, -tau[idx], rtol=1e-9, atol=1e-8)


def test_J_e_of_the_tree_matches_finite_differences_and_is_zero_off_each_branch(talos, rng):
    cm = CompiledModel(talos, load_error_model(None, talos), backend="c")
    q, eps, h = random_q(talos, rng, 2), rng.normal(0, 0.01, (2, talos.n_errors)), 1e-6
    p, J = cm.J_e(q, eps)
    np.testing.assert_allclose(p.reshape(2, -1, 3), target_positions(talos, q, eps), atol=1e-12)
    for k in range(talos.n_errors):
        e1, e2 = eps.copy(), eps.copy()
        e1[:, k] += h
        e2[:, k] -= h
        fd = ((target_positions(talos, q, e1) - target_positions(talos, q, e2)) / (2 * h)).reshape(2, -1)
        np.testing.assert_allclose(J[:, :, k], fd, atol=1e-8)
    right_arm = [6 * f + e for f in range(10, 17) for e in range(6)]
    assert not J[:, 0:3, right_arm].any()  # the left hand's rows: the right arm's errors never move it


def test_the_gravity_regressor_carries_every_branch(talos, rng):
    """A unit mass at the origin of a frame of either arm loads the torso by g . dp/dq (virtual work),
    and never the other arm's joints."""
    from gecgen.model.loads import _numeric_columns

    q = random_q(talos, rng, 6)
    g = np.array([float(v) for v in talos.gravity])
    columns, h = _numeric_columns(talos, q), 1e-6
    for joint in (0, 1, 2, 9):  # torso_1, torso_2, arm_left_1, arm_right_1
        first = talos.driven(joint)[0][0]
        dq = np.eye(talos.n)[joint] * h
        for frame in (5, 9, 13, 16):
            fd = ((frames(talos, q + dq)[frame][:, :3, 3] - frames(talos, q - dq)[frame][:, :3, 3]) @ g) / (2 * h)
            column = columns[joint][:, 4 * (frame - first)] if frame >= first else np.zeros(len(q))
            np.testing.assert_allclose(column, fd, atol=1e-8, err_msg=f"joint {joint}, frame {frame}")
        if joint == 2:
            assert not fd.any()  # the left shoulder does not carry frame 16 of the right arm


def test_the_identifiable_count_of_the_tree_is_its_structural_count(talos, rng):
    """The count identify reports is the numerical rank of H_e at generic poses (an SVD, independent of
    the redundancy analysis's greedy rank test), and it is what the tree's structure gives: a chain's
    4 per revolute joint and 6 per tip point set (here 3 per single-point tip, 6 with two points), less
    nothing for the shared trunk, whose errors both branches see."""
    from gecgen.runtime.identify import structural_analysis

    model = load_error_model(None, talos)
    cm = CompiledModel(talos, model, backend="c")
    red = structural_analysis(cm, np.arange(len(talos.targets)))
    q = random_q(talos, rng, 200)
    _, H = cm.model_targets(q, np.zeros((200, 6)), np.zeros((200, 0)), np.zeros(len(model.coefficients)),
                            with_H=True)
    H = H.reshape(-1, H.shape[-1])
    H = H / np.maximum(np.linalg.norm(H, axis=0), 1e-300)
    s = np.linalg.svd(H, compute_uv=False)
    assert red.n_identifiable == int(np.sum(s > 1e-9 * s[0]))


@pytest.mark.parametrize("text, message", [
    ("branches: {left: {tip_link: arm_left_7_link}}", r"branches.'left': missing key 'targets'"),
    ("branches: {left: {tip_link: arm_left_7_link, targets: {a: [0, 0, 0]}}, "
     "right: {tip_link: arm_right_7_link, targets: {a: [0, 0, 0]}}}",
     r"branches.'right': targets: 'a' is a target of another branch too"),
    ("tool: {origin: [0, 0, 0]}\nbranches: {left: {tip_link: arm_left_7_link, targets: {a: [0, 0, 0]}}}",
     r"tool: a robot with branches gives each branch its own tool"),
    ("branches: []", r"branches: expected a mapping from branch names"),
])
def test_bad_branches_are_refused_by_name(tmp_path, text, message):
    (tmp_path / "talos_reduced.urdf").write_text((DATA / "talos_reduced.urdf").read_text())
    (tmp_path / "r.yaml").write_text(f"name: t\nangle_unit: rad\nurdf: talos_reduced.urdf\nbase_link: base_link\n{text}\n")
    with pytest.raises(ModelError, match=message):
        load_robot(tmp_path / "r.yaml")
