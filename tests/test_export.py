"""`gecgen export`: the exported C against the Python compensation, the exported URDF against the
calibrated chain (pinocchio), and the table of zero offsets against simulated joint offsets."""
import contextlib
import difflib
import io
import json
import shlex
import subprocess
import warnings

import numpy as np
import pytest
from conftest import ROBOTS, random_q
from test_urdf import ARM, MOVING, urdf_text, write_robot

from gecgen.api import load_calibration
from gecgen.cli import main
from gecgen.model import load_robot
from gecgen.model.kinematics import constant, error_transform, frames, target_positions
from gecgen.model.measurements import read_measurements
from gecgen.model.urdf import folded_copy
from gecgen.fit import calibration
from gecgen.runtime.compiled import compiler
from gecgen.deliver.export import MDEG_PER_RAD, constant_errors

pin = pytest.importorskip("pinocchio")

UR10_URDF = ROBOTS.parent / "tests" / "data" / "ur10" / "ur10_robot.urdf"
CONSTANT = ROBOTS / "constant.errors.yaml"
#: joint offsets of the offsets-only truths (rad)
OFFSETS = [5.0e-4, -3.0e-4, 4.0e-4, -6.0e-4, 2.0e-4, 7.0e-4]


def gecgen_json(*args) -> dict:
    """Run a command in this process; its JSON result (its warnings, on stderr, are not the test's)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main([*map(str, args), "--json"]) == 0
    return json.loads(out.getvalue())


def ur10_file(folder):
    """The UR10 of tests/data with three markers around its flange (tip wrist_3_link, so the last
    frame's errors need a new link in the URDF)."""
    path = folder / "ur10.yaml"
    path.write_text(f"name: ur10\nangle_unit: rad\nurdf: {UR10_URDF}\nbase_link: base_link\ntip_link: wrist_3_link\n"
                    "targets:\n  m1: [0.08, 0.0, 0.05]\n  m2: [-0.04, 0.07, 0.05]\n  m3: [-0.04, -0.07, 0.08]\n")
    return path


def calibrate(folder, robot, truth: str, errors=CONSTANT, poses=40):
    (folder / "truth.yaml").write_text(truth)
    gecgen_json("simulate", robot, "--truth", folder / "truth.yaml", "--poses", poses, "--seed", 1,
                "-o", folder / "train.csv")
    gecgen_json("identify", robot, folder / "train.csv", "--errors", errors, "-o", folder / "calib.json")
    return folder / "calib.json"


@pytest.fixture(scope="session")
def ur10_calib(tmp_path_factory):
    """A constant-error calibration of a UR10 with geometric errors and joint offsets."""
    folder = tmp_path_factory.mktemp("ur10")
    truth = ("seed: 3\nconstant: {translation_std: 5.0e-4, rotation_std: 3.0e-4}\njoint_offsets: {std: 3.0e-4}\n"
             "noise: {repeatability: 1.0e-5, tracker: 1.0e-5}\n")
    return calibrate(folder, ur10_file(folder), truth)


@pytest.fixture(scope="session")
def offsets_calib(tmp_path_factory):
    """name -> a noise-free calibration of industrial6r (DH) or ur10 (URDF) whose only errors are the
    joint offsets OFFSETS; each made once."""
    made = {}

    def make(name: str):
        if name not in made:
            folder = tmp_path_factory.mktemp(f"offsets-{name}")
            robot = ROBOTS / "industrial6r.yaml" if name == "industrial6r" else ur10_file(folder)
            made[name] = calibrate(folder, robot, f"joint_offsets: {{values: {OFFSETS}}}\n"
                                                  f"noise: {{repeatability: 0, tracker: 0}}\n")
        return made[name]

    return make


# -- --c --------------------------------------------------------------------------------------------
@pytest.mark.skipif(compiler() is None, reason="needs a C compiler")
def test_exported_c_compiles_and_compensates_as_python_does(ur10_calib, tmp_path):
    out = gecgen_json("export", ur10_calib, "--c", tmp_path / "c")["c"]
    assert out["files"] == sorted(["ur10.c", "ur10.h", "ur10_casadi.py", "manifest.json", "ur10_calibration.h",
                                   "ur10_example.c"])
    build = subprocess.run(shlex.split(out["compile"]), capture_output=True, text=True)
    assert build.returncode == 0 and "-std=c99 -O2 -Wall -Wextra -Werror" in out["compile"], build.stderr
    run = subprocess.run(shlex.split(out["run"]), capture_output=True, text=True, check=True)
    status, *printed = [line.split() for line in run.stdout.splitlines()]
    calib = calibration.load(ur10_calib)
    assert [name for name, _ in printed] == list(calib.robot.joint_names)
    # the same command through `gecgen compensate`
    q_cmd = out["example_command"]["q"]
    (tmp_path / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n" + ",".join(map(repr, q_cmd)) + "\n")
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        main(["compensate", str(ur10_calib), str(tmp_path / "cmd.csv"), "-o", str(tmp_path / "out.csv")])
    *python, code, residual_mm = (tmp_path / "out.csv").read_text().splitlines()[1].split(",")
    c = np.array([float(v) for _, v in printed])
    assert np.abs(c - np.array(python, float)).max() < 1e-9 and np.abs(c - q_cmd).max() > 1e-4  # a real correction
    assert int(status[1]) == int(code) and abs(float(status[4]) - 1e-3 * float(residual_mm)) < 1e-3 * float(status[4])
    # the header holds the calibration's coefficients exactly, each named
    header = (tmp_path / "c" / "ur10_calibration.h").read_text()
    rows = [line.split(", /* ") for line in header.splitlines() if line.endswith("*/") and line.startswith("    ")]
    assert [float(v) for v, _ in rows] == calib.c.tolist()
    assert [n.split()[1] for _, n in rows] == calib.model.coefficient_names(calib.robot)
    # a header of another model stops the build
    h = tmp_path / "c" / "ur10.h"
    h.write_text(h.read_text().replace("#define UR10_MODEL_HASH 0x", "#define UR10_MODEL_HASH 0x1"))
    build = subprocess.run(shlex.split(out["compile"]), capture_output=True, text=True)
    assert build.returncode != 0 and "another robot or error model" in build.stderr


# -- --urdf -----------------------------------------------------------------------------------------
def pin_placement(model, data, q_by_name: dict, frame: str, base: str) -> np.ndarray:
    """Pose (4x4) of a frame in the base link's frame, at the named joints (others at neutral)."""
    q = pin.neutral(model)
    for name, v in q_by_name.items():
        joint = model.joints[model.getJointId(name)]
        q[joint.idx_q:joint.idx_q + joint.nq] = [np.cos(v), np.sin(v)] if joint.nq == 2 else [v]
    pin.framesForwardKinematics(model, data, q)
    return np.linalg.inv(data.oMf[model.getFrameId(base)].homogeneous) @ data.oMf[model.getFrameId(frame)].homogeneous


def test_exported_urdf_keeps_each_measured_tool_point_as_its_own_link(ur10_calib, tmp_path, rng):
    """pinocchio on the exported URDF: each marker's link is where the calibrated model puts the
    marker (1e-9 m at random joints), and the last joint's link and what hangs on it (tool0) sit
    where the calibrated chain puts them without the last frame's errors: those belong to the
    measured tool, whose placement the data cannot tell from them."""
    out = gecgen_json("export", ur10_calib, "--urdf", tmp_path / "cal.urdf")["urdf"]
    calib = calibration.load(ur10_calib)
    robot = calib.robot
    assert out["tip_link"] == "wrist_3_link" and out["not_carried"] == []
    assert out["tool_links"] == {t: f"wrist_3_link_{t}" for t in robot.targets}
    assert out["registration_applied"] is False
    eps = constant_errors(calib)
    assert np.abs(eps[-6:]).max() > 1e-4  # the last frame has errors: the test can tell where they went
    robot_only = eps.copy()
    robot_only[-6:] = 0.0
    nominal, exported = pin.buildModelFromUrdf(str(UR10_URDF)), pin.buildModelFromUrdf(str(tmp_path / "cal.urdf"))
    dn, de = nominal.createData(), exported.createData()
    worst = worst_link = 0.0
    for q in random_q(robot, rng, 30):
        named = dict(zip(robot.joint_names, q))
        want = target_positions(robot, q, eps)[0]
        for k, (name, link) in enumerate(out["tool_links"].items()):
            worst = max(worst, np.abs(pin_placement(exported, de, named, link, "base_link")[:3, 3] - want[k]).max())
        W = frames(robot, q, robot_only)[-2][0]
        Wn = frames(robot, q)[-2][0]
        for link in ("wrist_3_link", "tool0"):  # tool0 hangs below the last link on fixed joints
            moved = W @ np.linalg.inv(Wn) @ pin_placement(nominal, dn, named, link, "base_link")
            worst_link = max(worst_link, np.abs(pin_placement(exported, de, named, link, "base_link") - moved).max())
    assert worst < 1e-9 and worst_link < 1e-9
    # only the joints the errors go into change, and nothing else in the file but the tool links
    before, after = UR10_URDF.read_text().splitlines(), (tmp_path / "cal.urdf").read_text().splitlines()
    diff = [line for line in difflib.unified_diff(before, after, lineterm="", n=0) if line[:3] not in ("---", "+++")]
    removed, added = [line for line in diff if line[0] == "-"], [line for line in diff if line[0] == "+"]
    assert len(removed) == len(out["changed_joints"]) - 3 and all("<origin" in line for line in removed)
    assert len(added) == len(removed) + 1 + 3 * 6  # the note; per marker a fixed joint (5 lines) and its link


def test_folding_into_fixed_joints_branches_and_missing_origins(tmp_path, rng):
    """Errors of every frame, on an arm with fixed joints between moving ones, a branch off the
    chain, a tool after the last joint, a skew axis and a joint without <origin>: the robot's links
    carry the errors of every frame but the last, and the tool point's own link the last one's."""
    text = urdf_text().replace('    <origin xyz="0.1 0.0 0.2" rpy="0.3 -0.2 1.1"/>\n', "")
    robot = load_robot(write_robot(tmp_path, text))
    eps = rng.normal(0, 1e-2, robot.n_errors)
    E = [error_transform(eps[6 * i:6 * i + 6]) for i in range(robot.n + 1)]
    point = np.eye(4)
    point[:3, 3] = [0.01, -0.02, 0.03]
    copy, tips, links, changed = folded_copy(robot.urdf, "world", ["tool"], E, "test",
                                             [{"p": constant(robot.tool) @ point}])
    assert tips == ["tool"] and links == {"p": "tool_p"}
    assert changed == ["flange", "j1", "j3", "j4", "side_joint", "tool_p_joint"]
    (tmp_path / "cal.urdf").write_text(copy)
    model = pin.buildModelFromUrdf(str(tmp_path / "cal.urdf"))
    data = model.createData()
    robot_only = eps.copy()
    robot_only[-6:] = 0.0
    for q in random_q(robot, rng, 10):
        named = dict(zip([j.name for j in MOVING], q))
        W, W0 = frames(robot, q, eps), frames(robot, q, robot_only)
        np.testing.assert_allclose(pin_placement(model, data, named, "tool_p", "world"), W[-1][0] @ point, atol=1e-12)
        np.testing.assert_allclose(pin_placement(model, data, named, "tool", "world"), W0[-1][0], atol=1e-12)
        side = next(j for j in ARM if j.name == "side_joint")
        np.testing.assert_allclose(pin_placement(model, data, named, "side", "world")[:3, 3],
                                   W[2][0][:3, :3] @ side.xyz + W[2][0][:3, 3], atol=1e-12)


def test_non_constant_terms_are_listed_with_their_largest_effect(ur10_calib, tmp_path, capsys):
    errors = tmp_path / "q3.errors.yaml"
    errors.write_text('default: ["1"]\nframes:\n  3:\n    ey: ["1", "q3"]\n')
    calib_path = tmp_path / "q3.json"
    gecgen_json("identify", ur10_file(tmp_path), ur10_calib.parent / "train.csv", "--errors", errors, "-o", calib_path,
                "--keep-insignificant")  # q3's term is what is exported here, determined or not
    capsys.readouterr()
    assert main(["export", str(calib_path), "--urdf", str(tmp_path / "cal.urdf"), "--json"]) == 0
    run = capsys.readouterr()
    out = json.loads(run.out)["urdf"]
    calib = calibration.load(calib_path)
    k = calib.model.coefficient_names(calib.robot).index("3.ey:q3")
    lo, hi = calib.report["training_ranges"]["q3"]
    assert out["not_carried"] == [{"coefficient": "3.ey:q3", "unit": "mm",
                                   "max_effect": pytest.approx(1e3 * abs(calib.c[k]) * max(-lo, hi), rel=1e-12)}]
    warning = [line for line in run.err.splitlines() if "warning" in line]
    assert len(warning) == 1 and "3.ey:q3" in warning[0]


def test_dh_robot_urdf_refused_in_one_line(offsets_calib, tmp_path, capsys):
    calib = offsets_calib("industrial6r")
    assert main(["export", str(calib), "--urdf", str(tmp_path / "x.urdf"), "--c", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "DH robot file" in err[0] and "--c" in err[0]
    assert not (tmp_path / "x.urdf").exists() and not (tmp_path / "c").exists()


def test_a_calibration_whose_poses_are_all_singular_is_refused_with_why(ur10_calib, tmp_path, capsys):
    """Training ranges that hold only a stretched elbow (the UR10's q3 = 0): no command there can be
    compensated without a swing, and the refusal says so instead of only that none converged."""
    calib = json.loads(ur10_calib.read_text())
    for k, q in enumerate([0.3, -1.0, 0.0, -1.0, 1.2, 0.2]):
        calib["training_ranges"][f"q{k + 1}"] = [q - 1e-4, q + 1e-4]
    (tmp_path / "calib.json").write_text(json.dumps(calib))
    assert main(["export", str(tmp_path / "calib.json"), "--c", str(tmp_path / "c")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "(singular at 21)" in err[0] and "near a singular posture" in err[0], err
    assert not (tmp_path / "c").exists()


# -- --table ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["industrial6r", "ur10"])
def test_zero_offset_error_is_the_joint_reading_off(name, tmp_path, rng):
    """Alone, joint i's zero-offset error moves the robot exactly as the joint reading off by it."""
    robot = load_robot(ROBOTS / "industrial6r.yaml" if name == "industrial6r" else ur10_file(tmp_path))
    q = random_q(robot, rng, 5)
    for i in range(1, robot.n + 1):
        index, sign = robot.zero_offset_error(i)
        eps = np.zeros(robot.n_errors)
        eps[index] = 1e-3
        moved = q.copy()
        moved[:, i - 1] += sign * 1e-3
        np.testing.assert_allclose(target_positions(robot, q, eps), target_positions(robot, moved), atol=1e-15)
    if name == "industrial6r":  # DH: er of frame i-1
        assert [robot.zero_offset_error(i)[0] for i in range(1, 7)] == [6 * (i - 1) + 4 for i in range(1, 7)]


@pytest.mark.parametrize("name", ["industrial6r", "ur10"])
def test_table_recovers_simulated_joint_offsets(offsets_calib, name):
    table = gecgen_json("export", offsets_calib(name), "--table")["table"]
    got = [z["value"] for z in table["zero_offsets"]]
    np.testing.assert_allclose(got, MDEG_PER_RAD * np.array(OFFSETS), atol=0.02)  # mdeg; second order: 0.01
    links = [abs(f[k]) for f in table["frames"] for k in f if k not in ("frame", "std") and f[k] is not None]
    assert max(links) < 1e-4  # mm, mrad: nothing else was simulated
    assert table["reexpressed_change_mm"] < 1e-4
    assert all(z["std"] is not None and z["std"] < 1e-6 for z in table["zero_offsets"])  # noise-free


def test_export_of_a_robot_with_mimic_joints(tmp_path, rng):
    """Frames and joint variables differ on a robot with mimic joints (7 frames, 4 variables): the
    URDF copy folds every frame's errors, and reloaded (its mimic joints intact) it puts the
    targets where the calibrated model does; the table lists the four independent joints."""
    robot_file = ROBOTS.parent / "tests" / "data" / "mimic" / "telescope.yaml"
    calib_file = calibrate(tmp_path, robot_file, "seed: 2\nconstant: {translation_std: 5.0e-4, rotation_std: 3.0e-4}\n"
                                                 "noise: {repeatability: 0, tracker: 0}\n")
    out = gecgen_json("export", calib_file, "--urdf", tmp_path / "cal.urdf", "--table")
    calib = calibration.load(calib_file)
    robot = calib.robot
    assert [o["joint"] for o in out["table"]["zero_offsets"]] == list(robot.joint_names)
    q = random_q(robot, rng, 20)
    want = target_positions(robot, q, constant_errors(calib))
    for k, (name, link) in enumerate(out["urdf"]["tool_links"].items()):  # each target at its own link's origin
        (tmp_path / "cal.yaml").write_text(f"name: telescope\nangle_unit: rad\nurdf: {tmp_path / 'cal.urdf'}\n"
                                           f"base_link: {robot.base_link}\ntip_link: {link}\n"
                                           f"targets:\n  {name}: [0.0, 0.0, 0.0]\n")
        exported = load_robot(tmp_path / "cal.yaml")
        assert exported.n == robot.n == 4 and robot.n_frames == 7
        np.testing.assert_allclose(target_positions(exported, q)[:, 0], want[:, k], atol=1e-9)


def test_urdf_of_an_elastic_calibration_states_what_leaving_the_load_terms_out_costs(ur10_calib, tmp_path, capsys):
    """A UR10 whose shoulder gives under gravity, calibrated with a load term the URDF cannot carry:
    export scores the exported model on the training and held-out data against the full
    calibration, and its figures are pinocchio's forward kinematics of the written URDF, scored
    against the measured points by hand."""
    from gecgen.fit.identify import to_world

    robot_file = ur10_file(tmp_path)
    (tmp_path / "truth.yaml").write_text("seed: 3\nmasses: urdf\nconstant: {translation_std: 5.0e-4, rotation_std: "
                                         "3.0e-4}\nsources:\n  - {type: compliance, joint: 2, compliance: 2.0e-5}\n"
                                         "noise: {repeatability: 1.0e-5, tracker: 1.0e-5}\n")
    (tmp_path / "elastic.errors.yaml").write_text('default: ["1"]\nframes:\n  2: ["1", "gravity_torque(q2)"]\n')
    gecgen_json("simulate", robot_file, "--truth", tmp_path / "truth.yaml", "--poses", 40, "--seed", 1,
                "-o", tmp_path / "train.csv", "--val-out", tmp_path / "val.csv", "--val-poses", 20)
    gecgen_json("identify", robot_file, tmp_path / "train.csv", "--errors", tmp_path / "elastic.errors.yaml",
                "-o", tmp_path / "cal.json")
    capsys.readouterr()
    assert main(["export", str(tmp_path / "cal.json"), "--urdf", str(tmp_path / "cal.urdf"), "--data",
                 str(tmp_path / "train.csv"), "--val", str(tmp_path / "val.csv"), "--json"]) == 0
    run = capsys.readouterr()
    out = json.loads(run.out)["urdf"]
    assert [c["coefficient"] for c in out["not_carried"]] == ["2.er:gravity_torque(q2)"]
    calib = calibration.load(tmp_path / "cal.json")
    model = pin.buildModelFromUrdf(str(tmp_path / "cal.urdf"))
    pdata = model.createData()
    for name in ("training", "held_out"):
        cost = out["cost"][name]
        data = read_measurements(cost["data"], calib.robot)
        y = to_world(calib.frames, data)
        got = np.array([pin_placement(model, pdata, dict(zip(calib.robot.joint_names, data.q[p])),
                                      out["tool_links"][calib.robot.target_names[t]], "base_link")[:3, 3]
                        for p, t in zip(data.pose, data.target)])
        e = 1e3 * np.linalg.norm(got - y, axis=1)
        assert cost["exported_rms_mm"] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-6)
        assert cost["exported_max_mm"] == pytest.approx(e.max(), rel=1e-6)
        # the load term is what the fit needed: without it the error is tens of times the calibration's
        assert cost["exported_rms_mm"] > 10 * cost["calibration_rms_mm"]
        # the gap between the two models, whatever the data measured: the URDF against the calibration
        assert len(data.pose) == len(data.q) * len(calib.robot.targets)  # every target at every pose
        with warnings.catch_warnings():  # the held-out poses leave the training ranges: said above
            warnings.simplefilter("ignore")
            want = load_calibration(tmp_path / "cal.json").predict(data.q, data.w)[data.pose, data.target]
        gap = 1e3 * np.linalg.norm(got - want, axis=1)
        assert cost["gap_rms_mm"] == pytest.approx(np.sqrt(np.mean(gap ** 2)), rel=1e-6)
        assert cost["gap_max_mm"] == pytest.approx(gap.max(), rel=1e-6)
    warning = [line for line in run.err.splitlines() if "constant errors only" in line]
    assert len(warning) == 1 and f"{out['cost']['held_out']['exported_rms_mm']:.3g} mm" in warning[0]


def test_a_ball_offset_the_data_cannot_tell_from_the_robot_goes_into_the_tool_link(tmp_path, capsys, rng):
    """A Panda measured at one ball on its last joint's axis, the ball 15 mm further out than the
    robot file says: the fit carries the ball's offset along that axis in errors of frame 6 (tens of
    mm and mrad). The export gives it back to the ball's link: pinocchio puts the ball where the
    calibration does (1e-9 m at training, held-out and random poses) while panda_joint7's origin
    stays within 0.01 mm and 0.01 mrad of nominal, as in the simulated robot, and the ball's link
    is 15 mm further out."""
    robot_file = ROBOTS / "panda_ball.yaml"
    (tmp_path / "truth.yaml").write_text('seed: 1\nconstant: {values: {"7.ez": 0.015}}\n'
                                         "noise: {repeatability: 1.0e-5, tracker: 1.0e-5}\n")
    gecgen_json("simulate", robot_file, "--truth", tmp_path / "truth.yaml", "--poses", 60, "--seed", 1,
                "-o", tmp_path / "train.csv", "--val-out", tmp_path / "val.csv", "--val-poses", 20)
    gecgen_json("identify", robot_file, tmp_path / "train.csv", "--errors", CONSTANT, "-o", tmp_path / "cal.json")
    capsys.readouterr()
    assert main(["export", str(tmp_path / "cal.json"), "--urdf", str(tmp_path / "cal.urdf"), "--json"]) == 0
    run = capsys.readouterr()
    out = json.loads(run.out)["urdf"]
    calib = calibration.load(tmp_path / "cal.json")
    carried = out["tool_offset_carried"]
    assert carried["errors"] == ["7.ez:1"] and carried["carried_by"]
    names = calib.model.coefficient_names(calib.robot)
    assert all(v == pytest.approx(1e3 * calib.c[names.index(k)]) and not k.startswith("7.")
               for k, v in carried["carried_by"].items())
    assert max(abs(v) for v in carried["carried_by"].values()) > 10  # the fit's frame 6 carries it
    moved = carried["reexpressed"]
    assert moved["applied"] and moved["tool"]["7.ez"] == pytest.approx(15.0, abs=0.01)
    [joint7] = moved["last_joint_origin"]
    assert joint7["joint"] == "panda_joint7" and joint7["fit_mm"] > 10
    warning = [line for line in run.err.splitlines() if "tool's offset" in line]
    assert len(warning) == 1 and all(k in warning[0] for k in carried["carried_by"]) and "7.ez 15 mm" in warning[0]
    robot = calib.robot
    model = pin.buildModelFromUrdf(str(tmp_path / "cal.urdf"))
    nominal = pin.buildModelFromUrdf(str(robot.urdf))
    placed = [m.jointPlacements[m.getJointId("panda_joint7")] for m in (model, nominal)]
    assert 1e3 * np.linalg.norm(placed[0].translation - placed[1].translation) < 0.01
    assert 1e3 * np.linalg.norm(pin.log3(placed[0].rotation.T @ placed[1].rotation)) < 0.01
    assert 1e3 * np.linalg.norm(placed[0].translation - placed[1].translation) == pytest.approx(
        joint7["exported_mm"], abs=1e-6)
    pdata = model.createData()
    eps = constant_errors(calib)
    q = np.vstack([read_measurements(tmp_path / f, robot).q for f in ("train.csv", "val.csv")]
                  + [random_q(robot, rng, 20)])
    for qk in q:
        got = pin_placement(model, pdata, dict(zip(robot.joint_names, qk)), out["tool_links"]["ball"], "panda_link0")
        np.testing.assert_allclose(got[:3, 3], target_positions(robot, qk, eps)[0, 0], atol=1e-9)
