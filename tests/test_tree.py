"""Branched robots (trees, issue 19): TALOS's upper body (tests/data/talos: a two-joint torso carrying
two 7-joint arms, from example-robot-data) as one robot with two branches.

Checked against independent computation: the hands' targets against pinocchio's forward kinematics of
the whole URDF tree, gravity_torque against pinocchio's generalized gravity, the generated J_e against
finite differences of the exact tree, the emitted gravity regressor against finite differences of the
potential energy, and the structural identifiable count against the numerical rank of H_e."""
import numpy as np
import pytest
from conftest import ROOT, random_q

from gecgen.model import ModelError, load_robot
from gecgen.model.robot import WRENCH
from gecgen.symbolic.terms import load_error_model
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
    from gecgen.fit.identify import structural_analysis

    model = load_error_model(None, talos)
    cm = CompiledModel(talos, model, backend="c")
    red = structural_analysis(cm, np.arange(len(talos.targets)))
    q = random_q(talos, rng, 200)
    _, H = cm.model_targets(q, np.zeros((200, 6)), np.zeros((200, 0)), np.zeros(len(model.coefficients)),
                            with_H=True)
    H = H.reshape(-1, H.shape[-1])
    H = H / np.maximum(np.linalg.norm(H, axis=0), 1e-300)
    s = np.linalg.svd(H, compute_uv=False)
    assert red.n_identifiable == int(np.sum(s > 1e-9 * s[0])) == 69  # docs/trees.md


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


def part(m, tree, robot, cols):
    """The rows of `m` (measured on the tree) that measure `robot`'s targets, with its joint columns."""
    from gecgen.model.measurements import Measurements

    names = [tree.target_names[t] for t in m.target]
    keep = np.array([n in robot.targets for n in names])
    return Measurements(q=m.q[:, cols], w=m.w, aux=m.aux, aux_names=m.aux_names, pose_ids=m.pose_ids,
                        pose=m.pose[keep], target=np.array([robot.target_names.index(n) for n in np.array(names)[keep]]),
                        xyz=m.xyz[keep], source=m.source)


@pytest.mark.filterwarnings("ignore:extrapolation")
def test_one_fit_of_the_tree_reaches_the_noise_floor_and_beats_two_serial_fits(talos):
    """A torso bent by both arms: the tree's diagnose, from constant errors, traces it to the torso's
    gravity load from both arms; torso + one arm as serial robots cannot (the other arm's weight is a
    rigid mass at its zero pose to them). docs/trees.md has the figures over seeds."""
    import gecgen
    from gecgen.model.validation import read_yaml
    from gecgen.simulate import load_truth, random_design, simulate

    spec = read_yaml(DATA / "talos.truth.yaml", "truth")
    spec["sources"] = spec["sources"][:1]  # the torso alone (docs/trees.md has the shoulders too): fewer rounds
    truth = load_truth(spec, talos)
    floor = 1e3 * np.sqrt(3 * (truth.tracker ** 2 + truth.repeatability ** 2))
    rng = np.random.default_rng(1)
    train, val = (simulate(talos, truth, random_design(talos, n, rng), rng) for n in (200, 100))
    constant = ROOT / "robots" / "constant.errors.yaml"
    tree = gecgen.Diagnoser(errors=constant).fit(talos, train, val=val).diagnosis_
    assert tree.after["val_rms_mm"] < 1.3 * floor, (tree.after, floor)
    # torso_2 under its load: its own angle error (2.es, or 1.es: its axis passes through frame 1's origin
    # along frame 1's y, so a turn there is the same motion), with torso_2's torque or the moment about y
    # that frame 1 or 2 carries
    torso = ("gravity_torque(q2)", "gravity(q2,", "gravity(1,my,", "gravity(2,my,", "gravity_load(1,my)",
             "gravity_load(2,my)")
    assert any(e.error in ("1.es", "2.es") and e.terms[0].startswith(torso) for e in tree.effects), \
        [(e.error, e.terms) for e in tree.effects]
    squares, points = 0.0, 0
    for side, cols in (("left", [0, 1, *range(2, 9)]), ("right", [0, 1, *range(9, 16)])):
        robot = load_robot(DATA / f"talos_{side}.yaml")
        serial = gecgen.Diagnoser(errors=constant).fit(robot, part(train, talos, robot, cols),
                                                      val=part(val, talos, robot, cols)).diagnosis_
        n = len(robot.targets) * val.n_poses
        squares, points = squares + n * serial.after["val_rms_mm"] ** 2, points + n
    assert np.sqrt(squares / points) > 1.5 * tree.after["val_rms_mm"], (np.sqrt(squares / points), tree.after)


ROWS = {"t1": "{name: t1, type: R, d: 0.3, a: 0.0, alpha: 90, limits: [-90, 90]}",
        "t2": "{name: t2, type: R, a: 0.4, alpha: 0, limits: [-60, 60]}",
        "r1": "{name: r1, type: R, a: 0.3, alpha: 90, limits: [-90, 90]}",
        "r2": "{name: r2, type: R, a: 0.25, alpha: 0, limits: [-90, 90]}",
        "l1": "{name: l1, type: R, a: 0.3, alpha: -90, limits: [-90, 90]}",
        "l2": "{name: l2, type: R, d: 0.1, a: 0.2, alpha: 0, limits: [-90, 90]}"}


DH_TREE = ("name: dhtree\nangle_unit: deg\njoints:\n" + "".join(f"  - {ROWS[n]}\n" for n in ("t1", "t2", "r1", "r2"))
           + "  - {name: l1, parent: t2, type: R, a: 0.3, alpha: -90, limits: [-90, 90]}\n"
           + f"  - {ROWS['l2']}\nbranches:\n  right: {{tip: r2, targets: {{a: [0.1, 0, 0]}}}}\n"
           + "  left: {tip: l2, tool: {origin: [0, 0, 0.05]}, targets: {b: [0, 0.1, 0]}}\n")


def dh_tree(folder):
    """A DH torso (t1, t2) with two 2-joint arms, the left one hanging from t2 by `parent`."""
    (folder / "tree.yaml").write_text(DH_TREE)
    return load_robot(folder / "tree.yaml")


@pytest.mark.parametrize("old, new, message", [
    ("parent: t2", "parent: [t2]", r"joints\[4\].parent: expected an earlier row's joint name or 'base', got \['t2'\]"),
    ("tip: l2", "tip: ''", r"branches.'left': tip: expected the name of a joint, got ''"),
    ("left:", "batch_right:", r"branches 'right' and 'batch_right': the generated C would define "
                              r"dhtree_compensate_batch_right twice \(compensate_batch of 'right', compensate of "
                              r"'batch_right'\); rename one"),
])
def test_bad_dh_branches_are_refused_by_name(tmp_path, old, new, message):
    assert old in DH_TREE
    (tmp_path / "tree.yaml").write_text(DH_TREE.replace(old, new, 1))
    with pytest.raises(ModelError, match=message) as err:
        load_robot(tmp_path / "tree.yaml")
    assert str(tmp_path / "tree.yaml") in str(err.value)


def test_a_branch_without_measured_targets_is_named_and_not_compensated(tmp_path, capsys):
    """Data of the right arm alone: identify says the left arm has no data (its frames' errors are
    eliminated for that, not for a lever arm of 0 m), and compensating the left arm is refused."""
    import json

    from gecgen.cli import main

    dh_tree(tmp_path)
    robot = str(tmp_path / "tree.yaml")
    assert main(["simulate", robot, "--poses", "60", "--seed", "2", "-o", str(tmp_path / "t.csv")]) == 0
    rows = (tmp_path / "t.csv").read_text().splitlines(keepends=True)
    (tmp_path / "right.csv").write_text("".join(r for r in rows if ",b," not in r))
    capsys.readouterr()
    assert main(["identify", robot, str(tmp_path / "right.csv"), "-o", str(tmp_path / "c.json")]) == 0
    assert "branch 'left': the data measures none of its targets" in capsys.readouterr().err
    reasons = {e["param"]: e["detail"] for e in json.loads((tmp_path / "c.json").read_text())["eliminated"]}
    for frame in (5, 6):  # l1's and l2's frames
        assert reasons[f"{frame}.ex:1"].startswith(f"frame {frame} moves only branch 'left', of which the data "
                                                   f"measures no target (b)"), reasons[f"{frame}.ex:1"]
    (tmp_path / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n0.1,0.2,0.3,0.2,0.1,0.2\n")
    out = ["-o", str(tmp_path / "out.csv")]
    assert main(["compensate", str(tmp_path / "c.json"), str(tmp_path / "cmd.csv"), "--branch", "left", *out]) == 2
    assert "the calibration's data measured no target of this branch (only of right)" in capsys.readouterr().err
    assert main(["compensate", str(tmp_path / "c.json"), str(tmp_path / "cmd.csv"), "--branch", "right", *out]) == 0


def test_a_dh_tree_is_its_branches_chains(tmp_path, rng):
    """DH rows with a parent: each branch's targets where the serial robot of its rows puts them."""
    rows = ROWS
    tree = dh_tree(tmp_path)
    assert tree.parents == (0, 1, 2, 3, 2, 5) and tree.joint_names == ("t1", "t2", "r1", "r2", "l1", "l2")
    q = random_q(tree, rng, 10)
    P = target_positions(tree, q)
    for name, chain, cols, tool, target in (("r", ("t1", "t2", "r1", "r2"), [0, 1, 2, 3], "", "a: [0.1, 0, 0]"),
                                            ("l", ("t1", "t2", "l1", "l2"), [0, 1, 4, 5],
                                             "tool: {origin: [0, 0, 0.05]}\n", "b: [0, 0.1, 0]")):
        (tmp_path / f"{name}.yaml").write_text(f"name: {name}\nangle_unit: deg\njoints:\n"
                                               + "".join(f"  - {rows[n]}\n" for n in chain)
                                               + f"{tool}targets: {{{target}}}\n")
        serial = load_robot(tmp_path / f"{name}.yaml")
        k = tree.target_names.index(serial.target_names[0])
        np.testing.assert_allclose(P[:, k], target_positions(serial, q[:, cols])[:, 0], atol=1e-14)


def dexterity(robot, q, branch: int, h=1e-6) -> float:
    """The smallest singular value of the branch tool's 6 x 7 Jacobian in its own joints (finite
    differences of the exact tree): away from singular arm postures when it is not small."""
    from gecgen.model.kinematics import tool_poses

    own = range(2, 9) if branch == 0 else range(9, 16)
    cols = []
    for j in own:
        dq = np.eye(robot.n)[j] * h
        Tp, Tm = (tool_poses(robot, (q + s * dq)[None])[branch][0] for s in (1, -1))
        W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ Tp[:3, :3].T
        cols.append([*(Tp[:3, 3] - Tm[:3, 3]) / (2 * h), W[2, 1], W[0, 2], W[1, 0]])
    return np.linalg.svd(np.array(cols).T, compute_uv=False)[-1]


@pytest.mark.filterwarnings("ignore:extrapolation")
def test_a_branch_is_compensated_by_its_own_joints(talos, tmp_path):
    """Each hand's command corrected with the other readings held: the tree as built (without the
    noise) puts that hand where the nominal model puts it; the trunk and the other arm keep their
    commands. The generated C of the tree passes -Wall -Wextra -Werror."""
    import gecgen
    from gecgen.model.validation import read_yaml
    from gecgen.simulate import load_truth, random_design, simulate
    from gecgen.simulate.truth import true_state

    spec = read_yaml(DATA / "talos.truth.yaml", "truth")
    spec["sources"] = []  # geometric errors only: the constant model is then exact
    truth = load_truth(spec, talos)
    rng = np.random.default_rng(2)
    cal = gecgen.Calibrator(errors=load_error_model(None, talos)).fit(
        talos, simulate(talos, truth, random_design(talos, 200, rng), rng))
    q_cmd = random_design(talos, 40, rng).q * 0.5
    q_cmd = q_cmd[[min(dexterity(talos, q, 0), dexterity(talos, q, 1)) > 0.05 for q in q_cmd]][:10]
    with pytest.raises(ModelError, match=r"branch=None: robot talos has branches left, right; name the one"):
        cal.compensate(q_cmd)
    wanted = target_positions(talos, q_cmd)
    for branch, k, own in (("left", 0, range(2, 9)), ("right", 1, range(9, 16))):
        fixed = cal.compensate(q_cmd, branch=branch).q
        held = [j for j in range(talos.n) if j not in own]
        assert np.array_equal(fixed[:, held], q_cmd[:, held])
        q_true, eps = true_state(talos, truth, fixed, np.zeros(len(fixed)), np.zeros(3), {}, np.ones_like(fixed))
        after = 1e3 * np.linalg.norm(target_positions(talos, q_true, eps)[:, k] - wanted[:, k], axis=1)
        q_true, eps = true_state(talos, truth, q_cmd, np.zeros(len(fixed)), np.zeros(3), {}, np.ones_like(fixed))
        before = 1e3 * np.linalg.norm(target_positions(talos, q_true, eps)[:, k] - wanted[:, k], axis=1)
        assert before.max() > 1.0 and after.max() < 0.1, (branch, before.max(), after.max())
    # the other arm's readings beyond its training ranges: no extrapolation of this hand's tool
    ranges = cal.calibration_.report["training_ranges"]
    for branch, own in (("left", range(2, 9)), ("right", range(9, 16))):
        wide = q_cmd.copy()
        other = [j for j in range(2, 16) if j not in own]
        wide[:, other] = [ranges[f"q{j + 1}"][1] + 0.01 for j in other]
        named = {f"q{j + 1}" for j in other}
        assert not set(cal.compensate(wide, branch=branch).extrapolation) & named
        assert named <= set(cal.compensate(wide, branch="right" if branch == "left" else "left").extrapolation)


def test_a_hand_depends_on_its_path_and_on_every_reading_through_a_load(talos):
    """The inputs whose training ranges matter to one hand: the trunk's and its own readings, and
    every reading and the wrench once a frame on its path has a load term (gravity sums over the
    tree)."""
    from gecgen.fit.calibration import branch_inputs
    from gecgen.symbolic.terms import error_model_from_dict

    left = talos.branch_index("left")
    own = {f"q{k + 1}" for k in range(talos.n) if talos.joint_names[k] not in talos.moved_joints(1 - left)}
    assert branch_inputs(talos, load_error_model(None, talos), left) == own
    trunk = error_model_from_dict({"default": ["1"], "frames": {2: {"er": ["1", "gravity_torque(q2)"]}}}, talos, "trunk")
    assert branch_inputs(talos, trunk, left) == {f"q{k + 1}" for k in range(talos.n)} | set(WRENCH)


def test_export_of_a_tree(talos, tmp_path, capsys):
    """--c: the example program compensates the first branch and builds with -Werror; --table lists every
    joint; --urdf (one chain's folding) is refused by name."""
    import json
    import subprocess

    from gecgen.cli import main
    from gecgen.runtime.compiled import compiler

    data = tmp_path / "t.csv"
    assert main(["simulate", str(DATA / "talos.yaml"), "--truth", str(DATA / "talos.truth.yaml"), "--poses", "120",
                 "--seed", "3", "-o", str(data)]) == 0
    assert main(["identify", str(DATA / "talos.yaml"), str(data), "--errors", str(ROOT / "robots" / "constant.errors.yaml"),
                 "-o", str(tmp_path / "c.json")]) == 0
    out = tmp_path / "ex.json"
    capsys.readouterr()
    assert main(["export", str(tmp_path / "c.json"), "--c", str(tmp_path / "ctrl"), "--table", "--json"]) == 0
    out.write_text(capsys.readouterr().out)
    assert [r["joint"] for r in json.loads(out.read_text())["table"]["zero_offsets"]] == list(talos.joint_names)
    ctrl = tmp_path / "ctrl"
    subprocess.run([compiler(), "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(ctrl / "ex"),
                    str(ctrl / "talos_example.c"), str(ctrl / "talos.c"), "-lm"], check=True)
    assert subprocess.run([str(ctrl / "ex")], capture_output=True, text=True).returncode == 0
    # --urdf folds every branch's errors: pinocchio on the copy puts each hand's measured points where the
    # calibration does, each on a link of its own below its hand's tip link
    assert main(["export", str(tmp_path / "c.json"), "--urdf", str(tmp_path / "x.urdf"), "--json"]) == 0
    urdf = json.loads(capsys.readouterr().out)["urdf"]
    assert urdf["tip_links"] == {"left": "arm_left_7_link", "right": "arm_right_7_link"}
    assert urdf["tool_links"] == {t: f"{talos.branches[talos.branch_of(t)].tip_link}_{t}" for t in talos.targets}
    from gecgen.fit.calibration import load as load_calibration
    from gecgen.deliver.export import constant_errors

    eps = constant_errors(load_calibration(tmp_path / "c.json"))
    model = pin.buildModelFromUrdf(str(tmp_path / "x.urdf"))
    pdata = model.createData()
    for q in random_q(talos, np.random.default_rng(0), 4):
        pin.forwardKinematics(model, pdata, pin_config(model, talos, q))
        pin.updateFramePlacements(model, pdata)
        tools = frames(talos, q[None], eps)[talos.n_frames + 1:]
        for target, link in urdf["tool_links"].items():
            T = tools[talos.branch_of(target)][0]
            np.testing.assert_allclose(pdata.oMf[model.getFrameId(link)].translation,
                                       T[:3, :3] @ np.asarray(talos.targets[target]) + T[:3, 3], atol=1e-12)
    # evaluate scores each hand apart; the points of both make the whole (1 left, 2 right per pose)
    assert main(["evaluate", str(tmp_path / "c.json"), str(data), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    hands = result["branches"]
    assert set(hands) == {"left", "right"} and hands["left"]["after"]["rms_mm"] < hands["left"]["before"]["rms_mm"]
    whole = np.sqrt((hands["left"]["after"]["rms_mm"] ** 2 + 2 * hands["right"]["after"]["rms_mm"] ** 2) / 3)
    assert abs(whole - result["after"]["rms_mm"]) < 1e-9
    assert result["after"]["max_mm"] == max(h["after"]["max_mm"] for h in hands.values())


def test_pose_measurements_of_a_tree(tmp_path):
    """A 6-D probe on each hand: orientations simulated on each target's own branch and fitted to
    their noise (0.2 mrad per axis: 0.35 mrad as a rotation angle), per branch."""
    import gecgen
    from gecgen.simulate import load_truth, random_design, simulate

    tree = dh_tree(tmp_path)
    truth = load_truth({"seed": 2, "constant": {"translation_std": 5e-4, "rotation_std": 3e-4},
                        "noise": {"repeatability": 3e-5, "tracker": 5e-5, "orientation": 2e-4}}, tree)
    rng = np.random.default_rng(0)
    cal = gecgen.Calibrator(errors=load_error_model(None, tree)).fit(
        tree, simulate(tree, truth, random_design(tree, 150, rng), rng, orientation=True))
    noise = 1e3 * 2e-4 * np.sqrt(3)
    for hand in ("left", "right"):
        before, train = cal.report_["branches"][hand]["before"], cal.report_["branches"][hand]["train"]
        assert before["rot_rms_mrad"] > 2 * noise and train["rot_rms_mrad"] < 1.2 * noise, (hand, before, train)
        assert train["rms_mm"] < 0.15 < 0.5 < before["rms_mm"], (hand, before, train)


@pytest.mark.filterwarnings("ignore:extrapolation")
def test_calibrate_chooses_for_the_whole_tree_and_scores_each_hand(talos):
    """calibrate's elastic candidate carries the URDF's masses of both arms onto the torso: chosen over
    the geometric one, its held-out error near the noise floor on each hand."""
    import gecgen
    from gecgen.model.validation import read_yaml
    from gecgen.simulate import load_truth, random_design, simulate

    truth = load_truth(read_yaml(DATA / "talos.truth.yaml", "truth"), talos)
    floor = 1e3 * np.sqrt(3 * (truth.tracker ** 2 + truth.repeatability ** 2))
    rng = np.random.default_rng(4)
    train, val = (simulate(talos, truth, random_design(talos, n, rng), rng) for n in (200, 100))
    sel = gecgen.calibrate(talos, train, val=val, models=("geometric", "elastic"))
    assert sel.model == "elastic", sel.table
    assert set(sel.val_branches) == {"left", "right"}
    for hand in sel.val_branches.values():
        assert hand["after"]["rms_mm"] < 1.3 * floor < 5 * floor < hand["before"]["rms_mm"], (hand, floor)


def test_compensate_names_its_option_and_why_a_two_joint_arm_cannot_place_its_tool(tmp_path, capsys):
    """Without --branch, or with one misspelled, the refusal speaks of --branch (not the API's
    branch=None) and names the branches; the DH tree's 2-joint arms cannot place even their tool's
    position, which is said instead of "near a singularity"."""
    from gecgen.cli import main

    dh_tree(tmp_path)
    (tmp_path / "truth.yaml").write_text("constant:\n  values: {'5.ex': 1.0e-3, '2.ey': 1.0e-3, '6.ez': 1.0e-3}\n"
                                         "noise: {repeatability: 1.0e-5, tracker: 1.0e-5}\n")
    robot, t = str(tmp_path / "tree.yaml"), tmp_path
    assert main(["simulate", robot, "--truth", str(t / "truth.yaml"), "--poses", "60", "-o", str(t / "d.csv")]) == 0
    assert main(["identify", robot, str(t / "d.csv"), "-o", str(t / "c.json")]) == 0
    (t / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n0.1,0.2,0.3,0.2,0.1,0.2\n")
    for branch, message in (([], "--branch: robot dhtree has branches; name the one whose tool to place: the "
                                 "choices: right, left"),
                            (["--branch", "lef"], "--branch lef: robot dhtree has branches; name the one whose tool "
                                                  "to place: did you mean 'left'?"),
                            (["--branch", "left"], "cmd.csv: row 2: the correction did not converge: the 2 joints it "
                                                   "moves (l1, l2) cannot place the tool's position (")):
        capsys.readouterr()
        code = main(["compensate", str(t / "c.json"), str(t / "cmd.csv"), "-o", str(t / "out.csv"), *branch])
        err = capsys.readouterr().err.splitlines()
        assert code != 0 and len(err) == 1 and message in err[0], err


@pytest.mark.filterwarnings("ignore")
def test_diagnose_json_holds_each_hands_figures_as_its_report_does(tmp_path, capsys):
    """diagnose --json on a tree: train_branches and val_branches, each hand's uncalibrated, declared
    (before) and diagnosed (after) errors; pooled over the hands they are the whole data's figures."""
    import json

    from gecgen.cli import main

    dh_tree(tmp_path)
    robot = str(tmp_path / "tree.yaml")
    (tmp_path / "truth.yaml").write_text("seed: 3\nconstant: {translation_std: 1.0e-3, rotation_std: 1.0e-3}\n"
                                         "noise: {repeatability: 1.0e-5, tracker: 1.0e-5}\n")
    for name, seed in (("t", "1"), ("v", "2")):
        assert main(["simulate", robot, "--truth", str(tmp_path / "truth.yaml"), "--poses", "60", "--seed", seed,
                     "-o", str(tmp_path / f"{name}.csv"), "--json"]) == 0
    capsys.readouterr()
    assert main(["diagnose", robot, str(tmp_path / "t.csv"), "--val", str(tmp_path / "v.csv"), "--errors",
                 str(ROOT / "robots" / "constant.errors.yaml"), "--max-rounds", "1", "-o",
                 str(tmp_path / "d.errors.yaml"), "--report", str(tmp_path / "report"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    for key, overall in (("train_branches", "train_rms_mm"), ("val_branches", "val_rms_mm")):
        hands = result[key]
        assert set(hands) == {"left", "right"} and all(set(h) == {"uncalibrated", "before", "after"}
                                                       for h in hands.values())
        points = 60  # one target per hand, one row per pose
        pooled = np.sqrt(sum(points * h["after"]["rms_mm"] ** 2 for h in hands.values()) / (2 * points))
        assert pooled == pytest.approx(result["after"][overall], rel=1e-9)
        assert all(h["uncalibrated"]["rms_mm"] > h["after"]["rms_mm"] for h in hands.values())
    report = (tmp_path / "report" / "report.md").read_text()
    for hand in ("left", "right"):
        assert f"{result['val_branches'][hand]['after']['rms_mm']:.3g}" in report


def test_a_five_joint_arm_places_its_tool_position(tmp_path):
    """Each arm of the humanoid has five joints of its own, too few to turn its tool to every
    orientation: compensation places the tool's position (the calibrated model's tool origin at the
    corrected command lands on the nominal one at the command, checked with the robot's targets moved to
    the tool origins), and the export's example command is found (it was refused at every command)."""
    from dataclasses import replace

    from gecgen import Calibrator
    from gecgen.deliver.export import example_command
    from gecgen.model.kinematics import tool_poses
    from gecgen.model.validation import read_yaml
    from gecgen.simulate import load_truth, simulate
    from gecgen.simulate.designs import random_design

    path = ROOT / "robots" / "humanoid.yaml"
    robot = load_robot(path)
    truth = load_truth(read_yaml(ROOT / "robots" / "humanoid.truth.yaml", "truth"), robot)
    rng = np.random.default_rng(2)
    data = simulate(robot, truth, random_design(robot, 60, rng), rng)
    cal = Calibrator(ROOT / "robots" / "constant.errors.yaml").fit(path, data)
    calib, cm = cal.calibration_, cal._model()
    assert example_command(calib, cm, "c.json")["q"]
    lo, hi = data.q.min(axis=0), data.q.max(axis=0)
    q_cmd = np.random.default_rng(3).uniform(lo + 0.2 * (hi - lo), hi - 0.2 * (hi - lo), (12, robot.n))
    origins = replace(robot, targets={name: (0.0, 0.0, 0.0) for name in robot.targets})
    at_origin = CompiledModel(origins, calib.model)
    for k, branch in enumerate(b.name for b in robot.branches):
        done = cal.compensate(q_cmd, branch=branch)
        ok = done.status == 0
        assert ok.sum() >= 9, (branch, done.counts())
        placed = at_origin.model_targets(done.q[ok], np.zeros((ok.sum(), 6)), None, calib.c)[:, k]
        nominal = tool_poses(robot, q_cmd[ok])[k][:, :3, 3]
        assert np.abs(placed - nominal).max() < 1e-9
        before = at_origin.model_targets(q_cmd[ok], np.zeros((ok.sum(), 6)), None, calib.c)[:, k]
        assert np.abs(before - nominal).max() > 1e-4  # the error it corrected: over 0.1 mm
    # an elbow nearly straight: the directions the tool's position does not see are damped too, where
    # they had let a joint swing by turns (status 1, but the row held the swing)
    straight = np.random.default_rng(5).uniform(lo, hi, (60, robot.n))
    straight[:, [robot.joint_names.index("arm_left_4_joint"), robot.joint_names.index("arm_right_4_joint")]] = -0.006
    for branch in ("left", "right"):
        done = cal.compensate(straight, branch=branch)
        assert np.abs(done.q - straight).max() < 0.3, (branch, done.counts())
