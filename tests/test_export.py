"""`gecgen export`: the exported C against the Python compensation, the exported URDF against the
calibrated chain (pinocchio), and the table of zero offsets against simulated joint offsets."""
import contextlib
import difflib
import io
import json
import shlex
import subprocess

import numpy as np
import pytest
from conftest import ROBOTS, random_q
from test_urdf import ARM, MOVING, urdf_text, write_robot

from gecgen.cli import main
from gecgen.model import load_robot
from gecgen.model.kinematics import error_transform, frames, target_positions
from gecgen.model.urdf import folded_copy
from gecgen.runtime import calibration
from gecgen.runtime.compiled import compiler
from gecgen.runtime.export import MDEG_PER_RAD, constant_errors

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


def test_exported_urdf_has_the_calibrated_kinematics(ur10_calib, tmp_path, rng):
    out = gecgen_json("export", ur10_calib, "--urdf", tmp_path / "cal.urdf")["urdf"]
    calib = calibration.load(ur10_calib)
    robot = calib.robot
    assert out["tip_link"] == "wrist_3_link_calibrated" and out["not_carried"] == []
    assert out["registration_applied"] is False
    eps = constant_errors(calib)
    nominal, exported = pin.buildModelFromUrdf(str(UR10_URDF)), pin.buildModelFromUrdf(str(tmp_path / "cal.urdf"))
    dn, de = nominal.createData(), exported.createData()
    t = np.array(list(robot.targets.values()))
    worst = worst_tool0 = 0.0
    for q in random_q(robot, rng, 30):
        named = dict(zip(robot.joint_names, q))
        T = pin_placement(exported, de, named, "wrist_3_link_calibrated", "base_link")
        want = target_positions(robot, q, eps)[0]
        worst = max(worst, np.abs(t @ T[:3, :3].T + T[:3, 3] - want).max())
        # tool0 hangs below the tip on a branch of fixed joints: it moves with the last frame's errors
        W = frames(robot, q, eps)[-2][0]
        Wn = frames(robot, q)[-2][0]
        tool0 = W @ np.linalg.inv(Wn) @ pin_placement(nominal, dn, named, "tool0", "base_link")
        worst_tool0 = max(worst_tool0, np.abs(pin_placement(exported, de, named, "tool0", "base_link") - tool0).max())
    assert worst < 1e-9 and worst_tool0 < 1e-9
    # only the joints the errors go into change, and nothing else in the file
    before, after = UR10_URDF.read_text().splitlines(), (tmp_path / "cal.urdf").read_text().splitlines()
    diff = [line for line in difflib.unified_diff(before, after, lineterm="", n=0) if line[:3] not in ("---", "+++")]
    removed, added = [line for line in diff if line[0] == "-"], [line for line in diff if line[0] == "+"]
    assert len(removed) == len(out["changed_joints"]) - 1 and all("<origin" in line for line in removed)
    assert len(added) == len(removed) + 1 + 6  # the note; the new fixed joint (5 lines) and link


def test_folding_into_fixed_joints_branches_and_missing_origins(tmp_path, rng):
    """Errors of every frame, on an arm with fixed joints between moving ones, a branch off the
    chain, a tool after the last joint, a skew axis and a joint without <origin>."""
    text = urdf_text().replace('    <origin xyz="0.1 0.0 0.2" rpy="0.3 -0.2 1.1"/>\n', "")
    robot = load_robot(write_robot(tmp_path, text))
    eps = rng.normal(0, 1e-2, robot.n_errors)
    E = [error_transform(eps[6 * i:6 * i + 6]) for i in range(robot.n + 1)]
    copy, tips, changed = folded_copy(robot.urdf, "world", ["tool"], E, "test")
    assert tips == ["tool"] and changed == ["flange", "j1", "j3", "j4", "side_joint", "tool_mount"]
    (tmp_path / "cal.urdf").write_text(copy)
    model = pin.buildModelFromUrdf(str(tmp_path / "cal.urdf"))
    data = model.createData()
    for q in random_q(robot, rng, 10):
        named = dict(zip([j.name for j in MOVING], q))
        W = frames(robot, q, eps)
        np.testing.assert_allclose(pin_placement(model, data, named, "tool", "world"), W[-1][0], atol=1e-12)
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
    text = robot_file.read_text().replace("urdf: telescope.urdf", f"urdf: {tmp_path / 'cal.urdf'}")
    text = text.replace(f"tip_link: {robot.tip_link}", f"tip_link: {out['urdf']['tip_link']}")
    (tmp_path / "cal.yaml").write_text(text)
    exported = load_robot(tmp_path / "cal.yaml")
    assert exported.n == robot.n == 4 and robot.n_frames == 7
    q = random_q(robot, rng, 20)
    np.testing.assert_allclose(target_positions(exported, q), target_positions(robot, q, constant_errors(calib)),
                               atol=1e-9)
