"""gecgen filter: robot programs corrected through a calibration (gecgen/deliver/programs).

Checked against independent computation: the controllers' angle conventions built by hand from
elementary rotations; a zero calibration leaves every byte; every byte outside the target numbers
is unchanged after a real correction; and the corrected program, executed on the simulated truth
robot through the controller's nominal model, lands nearer the intended targets than the original.
"""
import contextlib
import csv
import io
import json
import shutil
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
import yaml

from gecgen.api import Calibrator, load_robot
from gecgen.cli import main
from gecgen.deliver.programs import abb, fanuc, filter_program, kuka, program_format, trial, ur
from gecgen.deliver.programs.core import correct, read_frames
from gecgen.deliver.programs.kinematics import arm_of, pose_error
from gecgen.model import ModelError
from gecgen.simulate import load_truth, random_design, simulate

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "programs"


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _calibrated(robot_file, truth_file, errors, seed=1, n=80):
    """A Calibrator fitted on simulated measurements of the truth robot, the robot and its truth."""
    robot = load_robot(robot_file)
    truth = load_truth(yaml.safe_load(Path(truth_file).read_text()), robot)
    rng = np.random.default_rng(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = Calibrator(errors).fit(robot, simulate(robot, truth, random_design(robot, n, rng), rng))
    return cal, robot, truth


@pytest.fixture(scope="module")
def kuka_cal():
    return _calibrated(ROOT / "robots" / "industrial6r.yaml", ROOT / "robots" / "industrial6r.truth.yaml",
                       str(ROOT / "robots" / "industrial6r.errors.yaml"))


@pytest.fixture(scope="module")
def ur_cal():
    return _calibrated(DATA / "robots" / "ur10.yaml", DATA / "robots" / "ur10.truth.yaml",
                       str(ROOT / "robots" / "constant.errors.yaml"))


def _zero(cal):
    """The same calibration with every coefficient zero: the nominal robot."""
    out = Calibrator()
    out._set(replace(cal.calibration_, c=np.zeros_like(cal.calibration_.c)))
    return out


def _copy_krl(tmp_path):
    for name in ("palletize.src", "palletize.dat", "frames.yaml"):
        shutil.copy(DATA / "krl" / name, tmp_path / name)
    return tmp_path / "palletize.src"


def _outside_targets(program, texts):
    """Each file's text with the numbers of every target cut out: what must not change."""
    out = {}
    for path, text in texts.items():
        spans = sorted((n.start, n.end) for t in program.targets if t.file == path for n in t.numbers)
        pieces, at = [], 0
        for start, end in spans:
            pieces.append(text[at:start])
            at = end
        out[path.suffix] = pieces + [text[at:]]
    return out


def _round_trips(fmt, cal, source, out, frames=None):
    """Filter `source` with a zero calibration (every byte of every file kept), then with `cal`: only
    target numbers change, every target keeps its configuration. The outcome of the real filtering."""
    filter_program(_zero(cal), source, out, frames)
    original = fmt.parse(source)
    for path in original.texts:
        assert out.with_suffix(path.suffix).read_bytes() == path.read_bytes()
    outcome, _, _ = filter_program(cal, source, out, frames)
    filtered = fmt.parse(out)
    assert _outside_targets(original, original.texts) == _outside_targets(filtered, filtered.texts)
    assert [t.config for t in original.targets] == [t.config for t in filtered.targets]
    return outcome


def _lands_nearer(fmt, source, out, frames, calibrated, outcome):
    """Run the original and the filtered program on the truth robot through the controller's nominal
    model: the corrected targets' tool RMS must drop to under 0.35 of the original's (the calibrations
    here remove about 90 % of the error), and a kept target misses as before. Returns the done mask."""
    _, robot, truth = calibrated
    arm = arm_of(robot, frames.flange)
    original, filtered = fmt.parse(source), fmt.parse(out)
    done = np.array([c.after is not None for c in outcome.changes])
    before = trial.execute(fmt, original, original, frames, arm, robot, truth)
    after = trial.execute(fmt, original, filtered, frames, arm, robot, truth)
    assert after.reached[done].all()
    miss_before = 1e3 * np.linalg.norm(before.placed - before.intended, axis=1)[done]
    miss_after = 1e3 * np.linalg.norm(after.placed - after.intended, axis=1)[done]
    assert np.sqrt(np.mean(miss_after ** 2)) < 0.35 * np.sqrt(np.mean(miss_before ** 2))
    kept = ~done & before.reached
    assert np.allclose(after.placed[kept], before.placed[kept])
    return done


# -- conventions, by hand ------------------------------------------------------------------------

def test_kuka_abc_is_z_y_x_euler_in_mm_and_deg():
    T = kuka.pose((100.0, -20.0, 5.0, 30.0, -50.0, 70.0))
    assert np.allclose(T[:3, :3], _rz(np.radians(30)) @ _ry(np.radians(-50)) @ _rx(np.radians(70)))
    assert np.allclose(T[:3, 3], [0.1, -0.02, 0.005])
    target = kuka.Target("P", Path("p"), 1, "pose", tuple(
        kuka.numbers_in("100 -20 5 31 -50 69", 0, 19, ["mm"] * 3 + ["deg"] * 3)))
    assert np.allclose(kuka.numbers(T, target), [100, -20, 5, 30, -50, 70])


def test_ur_pose_is_a_rotation_vector_in_m_and_rad():
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    angle = 0.7
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K  # Rodrigues
    T = ur.pose((0.4, -0.1, 0.3, *(angle * axis)))
    assert np.allclose(T[:3, :3], R) and np.allclose(T[:3, 3], [0.4, -0.1, 0.3])


def test_kuka_turn_and_status_follow_the_joint_signs_and_the_wrist():
    arm = arm_of(load_robot(ROOT / "robots" / "industrial6r.yaml"), np.eye(4))
    q = np.radians([[-10, -60, -40, 20, -30, -90], [10, -60, -140, -20, 30, 90]])
    s, t = kuka.config(arm)(q).T
    assert list(t) == [0b110111, 0b001110]  # bit k: axis k+1 negative
    assert list(s & 4) == [4, 0]  # A5 < 0: the hand flipped, as T's bit 4
    assert list(s & 4) == list((t & 16) // 4)
    # the stretched arm (contract: q = 0, -90, -90) divides elbow up from down, at the offset of a3
    assert list(s & 2) == [2, 0]


# -- round trips -----------------------------------------------------------------------------------

def test_zero_calibration_leaves_a_krl_program_byte_identical(kuka_cal, tmp_path):
    source = _copy_krl(tmp_path)
    out = tmp_path / "out" / "palletize.src"
    outcome, written, log = filter_program(_zero(kuka_cal[0]), source, out, tmp_path / "frames.yaml")
    assert outcome.corrected == 0
    assert out.read_bytes() == source.read_bytes()
    assert out.with_suffix(".dat").read_bytes() == source.with_suffix(".dat").read_bytes()
    assert log.is_file()


def test_krl_program_corrected_changes_only_target_numbers(kuka_cal, tmp_path):
    source = _copy_krl(tmp_path)
    out = tmp_path / "out" / "palletize.src"
    outcome, _, log = filter_program(kuka_cal[0], source, out, tmp_path / "frames.yaml")
    original, filtered = kuka.parse(source), kuka.parse(out)
    assert [t.name for t in original.targets] == [t.name for t in filtered.targets]
    assert _outside_targets(original, original.texts) == _outside_targets(filtered, filtered.texts)
    assert b"\r\n" in out.read_bytes() and b"\n" not in out.read_bytes().replace(b"\r\n", b"")
    reasons = {c.target.name: c.reason for c in outcome.changes}
    assert reasons["LIN_REL line 25"].startswith("a relative motion")
    assert reasons["XHOME (line 14)"].startswith("declared outside")
    corrected = [c for c in outcome.changes if c.after is not None]
    assert len(corrected) >= 10
    # the log names every target, with the corrections it made
    rows = log.read_text().splitlines()
    assert len(rows) == 1 + len(outcome.changes)
    assert all(0.05 < c.position_mm < 20 for c in corrected)
    # the configuration is kept: S and T as written
    for a, b in zip(original.targets, filtered.targets):
        assert a.config == b.config


def test_corrected_krl_program_lands_on_its_targets_on_the_truth_robot(kuka_cal, tmp_path):
    """The filtered program run through the controller's nominal inverse kinematics on the truth
    robot: its tool lands nearer the intended targets than the original's, by the calibration's
    gain."""
    cal = kuka_cal[0]
    source = _copy_krl(tmp_path)
    out = tmp_path / "out" / "palletize.src"
    outcome, _, _ = filter_program(cal, source, out, tmp_path / "frames.yaml")
    _lands_nearer(kuka.FORMAT, source, out, read_frames(tmp_path / "frames.yaml", kuka.FORMAT), kuka_cal, outcome)


def test_ur_script_zero_and_real_calibration(ur_cal, tmp_path):
    source, out = DATA / "ur" / "pick_place.script", tmp_path / "pick_place.script"
    outcome = _round_trips(ur.FORMAT, ur_cal[0], source, out)
    done = _lands_nearer(ur.FORMAT, source, out, read_frames(None, ur.FORMAT), ur_cal, outcome)
    assert done.sum() >= len(done) - 1


# -- what is kept, and what is refused ---------------------------------------------------------------

@pytest.mark.parametrize("old, new, name, reason", [
    (b"XP1={A1 -142.53669", b"XP1={A1 -192.53669", "XP1", "outside the joint limits"),
    # XP2 names S 6; given S 7 (the wrist behind axis 1) its pose is out of reach in that configuration
    (b"C -135.36718,S 6,T 27", b"C -135.36718,S 7,T 27", "XP2",
     "unreachable by the nominal model in its configuration"),
])
def test_a_target_that_cannot_be_corrected_is_kept_and_listed(kuka_cal, tmp_path, old, new, name, reason):
    source = _copy_krl(tmp_path)
    dat = source.with_suffix(".dat")
    dat.write_bytes(dat.read_bytes().replace(old, new))
    outcome, _, log = filter_program(kuka_cal[0], source, tmp_path / "out" / "palletize.src", tmp_path / "frames.yaml")
    change = next(c for c in outcome.changes if c.target.name == name)
    assert change.after is None and change.reason == reason
    line = next(ln for ln in dat.read_bytes().split(b"\r\n") if new in ln)
    assert line in (tmp_path / "out" / "palletize.dat").read_bytes()
    assert f"{name},palletize.dat,{change.target.line},{change.target.kind},{reason}" in log.read_text()


def _cli(*args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([*map(str, args), "--json"])
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def kuka_cal_file(kuka_cal, tmp_path_factory):
    path = tmp_path_factory.mktemp("cal") / "calibration.json"
    kuka_cal[0].save(path)
    return path


def test_cli_filter_writes_program_dat_and_log(kuka_cal_file, tmp_path):
    source = _copy_krl(tmp_path)
    code, out, err = _cli("filter", kuka_cal_file, source, "-o", tmp_path / "out" / "palletize.src",
                          "--frames", tmp_path / "frames.yaml")
    result = json.loads(out)
    # two motions have no target of this program's own: listed, and the command says so; the robot file
    # names no controller, which one warning line says
    lines = err.strip().splitlines()
    assert code == 1 and len(lines) == 2 and "kept as written" in lines[0]
    assert lines[1].startswith("gecgen filter: warning: robot industrial6r: industrial6r.yaml names no controller")
    assert result["n_targets"] == 15 and result["corrected"] + len(result["kept"]) == 15
    assert {k["target"] for k in result["kept"]} >= {"LIN_REL line 25", "XHOME (line 14)"}
    assert (tmp_path / "out" / "palletize.dat").is_file() and Path(result["log"]).is_file()


@pytest.mark.parametrize("edit, expected", [
    (lambda d: (d / "frames.yaml").write_text("tools:\n  1: [0, 0, 320, 0, -90, 0]\n"),
     "palletize.src:26: target PTP line 26 is in base 2, which neither the program nor a frames file describes; "
     "give its pose under bases: 2 in a frames file (--frames)"),
    (lambda d: (d / "palletize.dat").unlink(),
     "palletize.src:14: PTP to XHOME, and no palletize.dat beside the program declares it; copy palletize.dat "
     "beside it"),
    (lambda d: (d / "palletize.dat").write_bytes((d / "palletize.dat").read_bytes().replace(b"Y 1702.63624,", b"")),
     "palletize.dat:13: E6POS XP2 lacks Y; give every component of the target"),
])
def test_cli_filter_refuses_bad_programs_in_one_line(kuka_cal_file, tmp_path, edit, expected):
    source = _copy_krl(tmp_path)
    edit(tmp_path)
    code, out, err = _cli("filter", kuka_cal_file, source, "-o", tmp_path / "out" / "palletize.src",
                          "--frames", tmp_path / "frames.yaml")
    assert code == 2 and out == ""
    assert err.strip() == f"gecgen filter: {tmp_path / expected}"
    assert not (tmp_path / "out").exists()


def test_krl_output_must_keep_the_program_name(kuka_cal_file, tmp_path):
    source = _copy_krl(tmp_path)
    code, _, err = _cli("filter", kuka_cal_file, source, "-o", tmp_path / "other.src", "--frames",
                        tmp_path / "frames.yaml")
    assert code == 2 and "write it as palletize.src in another folder" in err


def test_ur_move_to_an_expression_is_listed_and_the_next_pose_has_no_target_before(ur_cal, tmp_path):
    """A move to an expression is kept and named; the pose after it cannot be solved near the joints before
    the expression's motion (the robot stands wherever it took it), so it is kept too."""
    program = tmp_path / "expr.script"
    program.write_text("def p():\n  set_tcp(p[0, 0, 0.15, 0, 0, 0])\n  movej([0.3, -1.2, 1.6, -1.9, -1.57, 0.4])\n"
                       "  movel(pose_trans(base, p[0, 0, 0.1, 0, 0, 0]), "
                       "a=1, v=0.1)\n  movel(p[-0.8, -0.4, 0.1, 2.2, 2.2, 0.0])\nend\n")
    outcome, _, _ = filter_program(ur_cal[0], program, tmp_path / "out.script")
    assert [(c.target.name, c.target.line, c.reason.split(" (")[0].split(":")[0]) for c in outcome.changes] == [
        ("movej line 3", 3, "corrected"), ("movel to pose_trans(base, p[0, 0, 0.1, (line 4)", 4,
                                           "a target computed at run time"),
        ("movel line 5", 5, "no earlier target to solve it near")]


def test_unknown_suffix_is_refused_naming_the_formats(tmp_path):
    with pytest.raises(ModelError, match=r"x.txt: no program format reads .txt; give one of .src \(krl\)"):
        program_format(tmp_path / "x.txt")


def test_ur_first_pose_without_an_earlier_target_is_kept(ur_cal, tmp_path):
    program = tmp_path / "first.script"
    program.write_text("def first():\n  set_tcp(p[0, 0, 0.15, 0, 0, 0])\n  movel(p[0.5, -0.3, 0.4, 3.0, 0.5, 0.1], "
                       "a=1.2, v=0.25)\nend\n")
    outcome = correct(ur.FORMAT, ur.parse(program), ur_cal[0], read_frames(None, ur.FORMAT))
    assert outcome.changes[0].after is None and outcome.changes[0].reason.startswith("no earlier target")


# -- ABB RAPID -------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def abb_cal():
    return _calibrated(DATA / "robots" / "irb6700.yaml", DATA / "robots" / "irb6700.truth.yaml",
                       str(ROOT / "robots" / "constant.errors.yaml"))


def test_abb_quaternion_is_w_x_y_z_and_keeps_its_sign():
    half = np.radians(40) / 2
    T = abb.pose((10.0, 20.0, 30.0, np.cos(half), 0.0, 0.0, np.sin(half)))
    assert np.allclose(T[:3, :3], _rz(np.radians(40))) and np.allclose(T[:3, 3], [0.01, 0.02, 0.03])
    negative = abb.Target("p", Path("p"), 1, "pose", tuple(
        abb.numbers_in("10 20 30 -0.9 0 0 -0.3", 0, 23, ["mm"] * 3 + ["1"] * 4)))
    assert np.allclose(abb.numbers(T, negative), [10, 20, 30, -np.cos(half), 0, 0, -np.sin(half)])


def test_abb_confdata_quadrants_and_cfx_by_hand():
    arm = arm_of(load_robot(DATA / "robots" / "irb6700.yaml"), np.eye(4))
    q = np.radians([[10, 20, -30, -100, 40, 185], [-95, 10, -120, 30, -40, -5]])
    cf = abb.config(arm)(q)
    assert cf[:, :3].tolist() == [[0, -2, 2], [-2, 0, -1]]
    assert list(cf[:, 3] & 1) == [0, 1]  # axis 5 negative


def test_abb_cfx_agrees_with_an_independent_rule_away_from_its_boundaries(rng):
    """cfx against the rule of robot_motion_program_opt's ABB helper (4 when the flange point is behind
    axis 1, 2 when axis 3 < -90 deg, 1 when axis 5 < 0), on postures clear of where the two rules'
    boundaries differ: the flange point within 0.25 m of axis 1's plane (the wrist centre is 0.2 m
    from it), axis 3 between -90 deg and the stretched arm's -80.1 deg."""
    arm = arm_of(load_robot(DATA / "robots" / "irb6700.yaml"), np.eye(4))
    low, high = arm.limits()
    q = rng.uniform(low, high, (400, 6))
    ahead = np.einsum("ni,ni->n", arm.fk(q)[:, :3, 3], np.column_stack([np.cos(q[:, 0]), np.sin(q[:, 0]), 0 * q[:, 0]]))
    clear = (np.abs(ahead) > 0.25) & ((q[:, 2] < np.radians(-91)) | (q[:, 2] > np.radians(-79)))
    other = 4 * (ahead < 0) + 2 * (q[:, 2] < np.radians(-90)) + (q[:, 4] < 0)
    assert clear.sum() > 250 and len(set(other[clear])) == 8
    assert np.array_equal(abb.config(arm)(q[clear])[:, 3], other[clear])


def test_rapid_module_zero_real_and_untouched_bytes(abb_cal, tmp_path):
    source, out = DATA / "rapid" / "Cell.mod", tmp_path / "Cell.mod"
    outcome = _round_trips(abb.FORMAT, abb_cal[0], source, out)
    assert outcome.corrected == 10 and outcome.changes[-1].reason.startswith("a target computed")
    _lands_nearer(abb.FORMAT, source, out, read_frames(None, abb.FORMAT), abb_cal, outcome)


def test_rapid_egm_and_arc_welding_motions_read_their_target_and_tool(abb_cal, tmp_path):
    """EGMMoveL egmID, ToPoint, ...; ArcL \\On, ToPoint, speed, seam, weld, weave, zone, tool; ArcLStart
    ToPoint, speed, seam, weld, zone, tool\\WObj\\SeamName: the same target and tool as MoveJ ToPoint,
    speed, zone, tool (before, p3 moved only by one of them was 'used by no move instruction' and left
    uncorrected). A tool that is not described is refused, named."""
    lines = (DATA / "rapid" / "Cell.mod").read_text().splitlines(keepends=True)
    head = "".join(lines[:9] + [line for line in lines if "robtarget p3:=" in line])

    def corrected_p3(motion):
        source = tmp_path / "Cell.mod"
        source.write_text(f"{head}    PROC main()\n        {motion};\n    ENDPROC\nENDMODULE\n")
        outcome, _, _ = filter_program(abb_cal[0], source, None)
        return next(c for c in outcome.changes if c.target.name == "p3").after

    plain = corrected_p3("MoveJ p3, v1000, z10, tGripper\\WObj:=wobjTable")
    assert plain is not None
    for motion in ("EGMMoveL egmID1, p3, v1000, z10, tGripper\\WObj:=wobjTable",
                   "ArcL \\On, p3, v100, seam1, weld5, noweave, fine, tGripper\\WObj:=wobjTable",
                   'ArcLStart p3, v100, seam1, weld5, fine, tGripper\\WObj:=wobjTable\\SeamName:="s1"',
                   "ArcC \\Off, p3, p3, v100, seam1, weld5, noweave, fine, tGripper\\WObj:=wobjTable"):
        assert corrected_p3(motion) == plain, motion
    for motion in ("EGMMoveL egmID1, p3, v1000, z10, tWelder", "ArcL \\On, p3, v100, seam1, weld5, noweave, fine, tWelder"):
        with pytest.raises(ModelError, match="target p3 is in tool tWelder"):
            corrected_p3(motion)


@pytest.mark.parametrize("old, new, expected", [
    (b"PERS tooldata tGripper:=[TRUE,", b"PERS tooldata tGripper:=[FALSE,",
     "Cell.mod:8: tooldata tGripper is a stationary tool (robhold FALSE); correct programs of a tool the robot holds"),
    (b"MoveJ p3, v1000, z10, tGripper", b"MoveJ p3, v1000, z10, tWelder",
     "Cell.mod:15: target p3 is in tool tWelder, which neither the program nor a frames file describes; give its "
     "pose under tools: tWelder in a frames file (--frames)"),
])
def test_rapid_refusals_name_the_line_and_the_fix(abb_cal, tmp_path, old, new, expected):
    bad = tmp_path / "Cell.mod"
    bad.write_bytes((DATA / "rapid" / "Cell.mod").read_bytes().replace(old, new))
    with pytest.raises(ModelError) as err:
        filter_program(abb_cal[0], bad, tmp_path / "out" / "Cell.mod")
    assert str(err.value) == f"{tmp_path / expected}"


# -- FANUC TP ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def fanuc_cal():
    return _calibrated(ROOT / "robots" / "fanuc.yaml", ROOT / "robots" / "fanuc.truth.yaml",
                       str(ROOT / "robots" / "fanuc.errors.yaml"))


def test_fanuc_wpr_are_fixed_x_y_z_angles_and_turns_count_from_180():
    T = fanuc.pose((1.0, 2.0, 3.0, 30.0, -50.0, 70.0))
    assert np.allclose(T[:3, :3], _rz(np.radians(70)) @ _ry(np.radians(-50)) @ _rx(np.radians(30)))
    assert fanuc.turns(np.radians([180.0, 180.5, -180.0, -179.5, 539.0, -541.0])).tolist() == [0, 1, -1, 0, 1, -2]


def _copy_tp(tmp_path):
    for name in ("weld_seam.ls", "frames.yaml"):
        shutil.copy(DATA / "tp" / name, tmp_path / name)
    return tmp_path / "weld_seam.ls"


def test_tp_program_zero_real_and_untouched_bytes(fanuc_cal, tmp_path):
    """On the coupled arm (the controller's J3 is the forearm's angle: couplings J3 = J2 + J3, the truth
    1.003 J2 + J3): joint positions corrected in the controller's readings, Cartesian ones in their
    user frame and tool; the aligned columns of the /POS section stay aligned."""
    source, out = _copy_tp(tmp_path), tmp_path / "out" / "weld_seam.ls"
    outcome = _round_trips(fanuc.FORMAT, fanuc_cal[0], source, out, tmp_path / "frames.yaml")
    original, filtered = fanuc.parse(source), fanuc.parse(out)
    assert all(len(a.text) <= len(b.text) <= len(a.text) + 1 for s, f in zip(original.targets, filtered.targets)
               for a, b in zip(s.numbers, f.numbers))
    assert outcome.corrected == 8 and outcome.changes[-1].reason.startswith("a position register")
    _lands_nearer(fanuc.FORMAT, source, out, read_frames(tmp_path / "frames.yaml", fanuc.FORMAT), fanuc_cal,
                  outcome)


@pytest.mark.parametrize("old, new, expected", [
    (b"\t\tCONFIG : 'N U T, 0, 0, 0',\r\n\tX = -1994.919", b"\r\n\tX = -1994.919",
     "weld_seam.ls:38: P[2] has no CONFIG; write it as CONFIG : 'N U T, 0, 0, 0'"),
    (b"   7:L P[3] 500mm/sec", b"   7:L P[9] 500mm/sec",
     "weld_seam.ls:22: motion to P[9], which the /POS section does not define; export the program with its "
     "positions"),
    (b"UF : 2, UT : 1,\t\tCONFIG : 'F U T, 0, 0, 0',\r\n\tX =   832.008",
     b"UF : 3, UT : 1,\t\tCONFIG : 'F U T, 0, 0, 0',\r\n\tX =   832.008",
     "weld_seam.ls:44: target P[3] is in base 3, which neither the program nor a frames file describes; give its "
     "pose under bases: 3 in a frames file (--frames)"),
])
def test_tp_refusals_name_the_line_and_the_fix(fanuc_cal, tmp_path, old, new, expected):
    source = _copy_tp(tmp_path)
    text = source.read_bytes()
    assert old in text
    source.write_bytes(text.replace(old, new))
    with pytest.raises(ModelError) as err:
        filter_program(fanuc_cal[0], source, tmp_path / "out" / "weld_seam.ls", tmp_path / "frames.yaml")
    assert str(err.value) == f"{tmp_path / expected}"


def _taught_twice(arm, deg, flip_letter_wrong):
    """A TP program with one posture (deg, the controller's readings) twice: as joints, and as the
    Cartesian position the nominal arm reaches there with gecgen's CONFIG string (its F/N letter
    swapped when flip_letter_wrong): the check docs/program-filters.md gives for a configuration rule."""
    q = np.radians(deg)
    T = arm.fk(q[None])[0]
    r, p, w = Rotation.from_matrix(T[:3, :3]).as_euler("ZYX", degrees=True)
    x, y, z = 1000 * T[:3, 3]
    flip, up, front, *turns = fanuc.config(arm)(q[None])[0]
    letters = f"{'NF'[int(flip) ^ flip_letter_wrong]} {'DU'[int(up)]} {'BT'[int(front)]}"
    joints = ",".join(f"\tJ{k + 1}= {v:9.3f} deg" + ("\n" if k == 2 else "") for k, v in enumerate(deg))
    return ("/PROG  TWICE\n/ATTR\n/MN\n   1:J P[1] 100% FINE    ;\n   2:J P[2] 100% FINE    ;\n/POS\n"
            f"P[1]{{\n   GP1:\n\tUF : 0, UT : 0,\t\n{joints}\n}};\n"
            f"P[2]{{\n   GP1:\n\tUF : 0, UT : 0,\t\tCONFIG : '{letters}, {turns[0]}, {turns[1]}, {turns[2]}',\n"
            f"\tX = {x:9.3f}  mm,\tY = {y:9.3f}  mm,\tZ = {z:9.3f}  mm,\n"
            f"\tW = {w:9.3f} deg,\tP = {p:9.3f} deg,\tR = {r:9.3f} deg\n}};\n/END\n")


@pytest.mark.parametrize("flip_letter_wrong", [0, 1])
def test_a_point_taught_as_joints_and_as_cartesian_gets_one_correction(fanuc_cal, tmp_path, flip_letter_wrong):
    """The same posture written as joints and as a Cartesian position with its CONFIG: the corrected
    joints and the corrected Cartesian position place the flange within 0.01 mm of each other. With
    the F/N letter swapped the Cartesian target is solved on the other wrist branch and its correction
    differs by more than 0.5 mm: the check tells a wrong configuration rule."""
    cal, robot, _ = fanuc_cal
    arm = arm_of(robot, np.eye(4))
    source = tmp_path / "twice.ls"
    source.write_text(_taught_twice(arm, np.array([25.0, 15.0, -20.0, 35.0, -55.0, 40.0]), flip_letter_wrong))
    outcome, _, _ = filter_program(cal, source, None)
    joint, cartesian = outcome.changes
    assert joint.after is not None and cartesian.after is not None
    by_joints = arm.fk(np.radians([float(v) for v in joint.after])[None])[0][:3, 3]
    apart = 1e3 * np.linalg.norm(by_joints - fanuc.pose([float(v) for v in cartesian.after])[:3, 3])
    assert (apart < 0.01) if not flip_letter_wrong else (apart > 0.5)


def test_the_fanuc_template_turns_its_joints_as_fanuc_s_recorded_postures():
    """robots/r2000ic.yaml (an R-2000iC-sized arm in the controller's joint senses) orients its flange as
    FANUC's 83 recorded CRX-10iA postures are oriented at their joints, within their 0.02 deg rounding: a
    FANUC's six axes turn alike whatever its link lengths. robots/fanuc.yaml, the simulation arm, does on 3."""
    rows = list(csv.DictReader((DATA / "tp" / "crx10ia" / "CRX10iA-solutions.csv").open(encoding="utf-8-sig")))
    q = np.radians([[float(r[f"J{k}"]) for k in range(1, 7)] for r in rows])
    recorded = np.array([fanuc.pose([0, 0, 0, *(float(r[k]) for k in "WPR")]) for r in rows])

    def oriented(robot_file):
        turn = pose_error(recorded, arm_of(load_robot(robot_file), np.eye(4)).fk(q))[:, 3:]
        return int(np.sum(np.linalg.norm(turn, axis=1) < np.radians(0.02)))

    assert oriented(ROOT / "robots" / "r2000ic.yaml") == len(rows) == 83
    assert oriented(ROOT / "robots" / "fanuc.yaml") == 3


def test_a_cartesian_target_of_an_arm_whose_wrist_axes_do_not_meet_is_kept_and_listed(tmp_path):
    """The CRX-10iA's wrist is offset (its axes 4, 5 and 6 pass 75 mm from one point): a pose and its
    CONFIG letters leave more than one posture, and which one the controller takes is its own rule, so
    the Cartesian target is kept as written, with why; the same posture taught as joints is corrected."""
    truth = tmp_path / "crx.truth.yaml"
    truth.write_text("seed: 3\nconstant: {translation_std: 0.0005, rotation_std: 0.0003}\n")
    cal, robot, _ = _calibrated(DATA / "robots" / "crx10ia.yaml", truth, str(ROOT / "robots" / "constant.errors.yaml"),
                                n=40)
    arm = arm_of(robot, np.eye(4))
    assert abs(arm.wrist_miss - 0.075) < 1e-9
    source = tmp_path / "twice.ls"
    source.write_text(_taught_twice(arm, np.array([25.0, 15.0, -20.0, 35.0, -55.0, 40.0]), 0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the robot file names no controller
        joint, cartesian = filter_program(cal, source, None)[0].changes
    assert joint.after is not None
    assert cartesian.after is None and "axes 4, 5 and 6 pass 75 mm from one point" in cartesian.reason


def test_fanuc_config_letters_are_the_controllers_on_recorded_postures():
    """83 postures of a FANUC CRX-10iA, each with its joints, its pose and the CONFIG letters FANUC gives
    it (FANUC RoboGuide and Abbes & Poisson 2024: tests/data/programs/README.md). The robot file in the
    controller's joint senses puts the faceplate at every recorded pose but two, and gecgen's rules (F
    when J5 > 0; U when the chain's joint 3 is at or above the stretched arm; T when the wrist centre is
    in front of axis 1) give FANUC's letters on all but three, each named. "N when J5 >= 0", as two
    statements not from FANUC have it, gives the recorded flip letter on 15 of the 83 only."""
    rows = list(csv.DictReader((DATA / "tp" / "crx10ia" / "CRX10iA-solutions.csv").open(encoding="utf-8-sig")))
    name = [f"{r['TEST CASE']}.{r['SOLUTION ID']}" for r in rows]
    arm = arm_of(load_robot(DATA / "robots" / "crx10ia.yaml"), np.eye(4))
    q = np.radians([[float(r[f"J{k}"]) for k in range(1, 7)] for r in rows])
    err = pose_error(np.array([fanuc.pose([float(r[k]) for k in "XYZWPR"]) for r in rows]), arm.fk(q))
    # the recorded numbers carry 0.01 mm and 0.001 deg: 0.05 mm and 0.02 deg hold their rounding
    off = {n for n, e in zip(name, err) if np.linalg.norm(e[:3]) > 5e-5 or np.linalg.norm(e[3:]) > np.radians(0.02)}
    assert off == {"1.2", "1.3"}  # Z 625 recorded for the home target their joints put at Z 380, as 1.1 does
    ours = ["NF"[f] + "DU"[u] + "BT"[t] for f, u, t in fanuc.config(arm)(q)[:, :3]]
    recorded = [r["FB"] + r["UD"] + r["TB"] for r in rows]
    assert {n: (r, o) for n, r, o in zip(name, recorded, ours) if r != o} == {
        "6.1": ("NUB", "NUT"),  # the wrist centre on axis 1 (stretched straight up): FANUC says B, gecgen T
        "14.5": ("NUT", "FUB"),  # the one flip letter against J5's sign; wrist centre 581 mm behind axis 1
        "15.4": ("NBD", "NDB")}  # the elbow and front letters written in each other's column
    assert sum((q5 >= 0) != (r[0] == "N") for q5, r in zip(q[:, 4], recorded)) == 68


def test_tp_indirect_motions_are_listed_not_refused(tmp_path):
    """`L P[R[1]]` and `J PR[R[2]]` (the register picks the position while the program runs) are valid
    TP: listed with why, where the whole program was refused as a motion to an undefined P[R]."""
    source = tmp_path / "ind.ls"
    source.write_text("/PROG  IND\n/ATTR\n/MN\n   1:  R[1]=1 ;\n   2:L P[R[1]] 500mm/sec FINE    ;\n"
                      "   3:J PR[ R[2] ] 100% FINE    ;\n   4:J P[1] 100% FINE    ;\n/POS\nP[1]{\n   GP1:\n"
                      "\tUF : 0, UT : 0,\t\n\tJ1=    25.000 deg,\tJ2=    15.000 deg,\tJ3=   -20.000 deg,\n"
                      "\tJ4=    35.000 deg,\tJ5=   -55.000 deg,\tJ6=    40.000 deg\n};\n/END\n")
    found = {t.name: (t.kind, t.line, t.note) for t in fanuc.parse(source).targets}
    assert found == {
        "P[1]": ("joint", 9, None),
        "P[R[1]] (line 5)": ("motion", 5, "the position is chosen by R[1] while the program runs: the /POS positions "
                                          "it may pick are corrected where they are defined"),
        "PR[R[2]] (line 6)": ("motion", 6, "the position is chosen by R[2] while the program runs: correct the "
                                            "position registers on the controller")}

# -- details ---------------------------------------------------------------------------------------

def test_the_controller_arm_is_the_robot_files_chain(rng):
    """Arm.frames (the solver's own evaluation, constants folded once) equals the model's exact chain."""
    from gecgen.model.kinematics import frames

    for robot_file in (ROOT / "robots" / "fanuc.yaml", DATA / "robots" / "ur10.yaml"):
        robot = load_robot(robot_file)
        arm = arm_of(robot, np.eye(4))
        q = rng.uniform(-2, 2, (20, 6))
        assert np.allclose(arm.fk(q), frames(robot, q)[robot.n_frames], atol=1e-12)


def _krl_two_poses(tmp_path, arm, q, tool_line="$TOOL={X 0,Y 0,Z 200,A 0,B 0,C 0}"):
    """A KRL program moving to the pose of each posture q (K, 6) rad, written in the motion, with
    the tool set in the program itself."""
    config = kuka.config(arm)
    lines = ["DEF two( )", tool_line, "$BASE=$NULLFRAME"]
    for qk in q:
        tcp = arm.fk(qk)[0] @ kuka.pose((0, 0, 200, 0, 0, 0))
        values = trial.pose_values(kuka.FORMAT, tcp, ("mm",) * 3 + ("deg",) * 3)
        s, t = config(qk[None])[0]
        lines.append("PTP {" + ",".join(f"{k} {v:.4f}" for k, v in zip(kuka.POSE_KEYS, values)) + f",S {s},T {t}}}")
    (tmp_path / "two.src").write_text("\n".join(lines + ["END", ""]))
    return tmp_path / "two.src"


def test_a_correction_that_would_flip_a_turn_bit_is_kept(kuka_cal, tmp_path):
    """A4 0.06 deg either side of zero: the correction (0.27 deg on A4 here) moves it the same way at
    both, so at one of the two it crosses zero, T changes, and the controller would solve the written
    pose in another configuration; that target is kept, the other corrected."""
    cal, robot, _ = kuka_cal
    arm = arm_of(robot, np.eye(4))
    q = np.radians([[20.0, -70.0, -60.0, 0.0, 40.0, 30.0]] * 2)
    q[:, 3] = [1e-3, -1e-3]
    assert abs(cal.compensate(q).q[0, 3] - q[0, 3]) > 2e-3
    outcome = correct(kuka.FORMAT, kuka.parse(_krl_two_poses(tmp_path, arm, q)), cal,
                      read_frames(None, kuka.FORMAT))
    reasons = sorted(c.reason for c in outcome.changes)
    assert reasons == ["corrected", "the corrected pose would bring the controller to another configuration"]


def test_krl_tool_set_in_the_program_and_a_pose_without_s_and_t(kuka_cal, tmp_path):
    cal, robot, _ = kuka_cal
    arm = arm_of(robot, np.eye(4))
    q = np.radians([[20.0, -70.0, -60.0, 30.0, 40.0, 30.0]])
    source = _krl_two_poses(tmp_path, arm, q)
    program = kuka.parse(source)
    assert program.targets[0].tool == "$TOOL line 2"
    assert np.allclose(program.tools["$TOOL line 2"], kuka.pose((0, 0, 200, 0, 0, 0)))
    assert correct(kuka.FORMAT, program, cal, read_frames(None, kuka.FORMAT)).corrected == 1
    text = source.read_text()
    source.write_text(text[:text.index(",S ")] + "}\nEND\n")
    outcome = correct(kuka.FORMAT, kuka.parse(source), cal, read_frames(None, kuka.FORMAT))
    assert outcome.changes[0].reason.startswith("names no configuration")


def test_ur_installation_tcp_comes_from_the_frames_file(ur_cal, tmp_path):
    program = tmp_path / "p.script"
    program.write_text("def p():\n  movej([0.3, -1.2, 1.6, -1.9, -1.57, 0.4])\n  movel(p[-0.8, -0.4, 0.1, 2.2, 2.2, 0.0])\n"
                       "end\n")
    with pytest.raises(ModelError, match="p.script:3: target movel line 3 is in tool installation, which neither the "
                                         "program nor a frames file describes; give its pose under tools: installation"):
        correct(ur.FORMAT, ur.parse(program), ur_cal[0], read_frames(None, ur.FORMAT))
    (tmp_path / "frames.yaml").write_text("tools:\n  installation: [0, 0, 0.18, 0, 0, 0]\n")
    assert ur.parse(program).targets[1].tool == "installation"
    frames = read_frames(tmp_path / "frames.yaml", ur.FORMAT)
    assert np.allclose(frames.tools["installation"], ur.pose((0, 0, 0.18, 0, 0, 0)))


@pytest.mark.parametrize("text, message", [
    ("tools:\n  1: [0, 0, 320]\n", "frames.yaml: tools: 1: give 6 numbers in the krl controller's pose convention"),
    ("tool:\n  1: [0, 0, 320, 0, 0, 0]\n", "frames.yaml: unknown key tool; give flange, tools and bases"),
])
def test_a_bad_frames_file_is_refused_naming_the_key(tmp_path, text, message):
    (tmp_path / "frames.yaml").write_text(text)
    with pytest.raises(ModelError, match=message):
        read_frames(tmp_path / "frames.yaml", kuka.FORMAT)


@given(st.integers(-10 ** 7, 10 ** 7), st.integers(0, 6), st.floats(-5.0, 5.0), st.sampled_from(["mm", "deg", "m"]),
       st.booleans())
def test_a_number_keeps_its_style_and_says_the_new_value(mantissa, digits, change, unit, pad):
    """A rewritten number has the original's decimals or the unit's minimum, whichever is more, and
    says the value to half its last digit; an unchanged value keeps its text."""
    from gecgen.deliver.programs.core import DECIMALS, Number, formatted

    text = f"{mantissa / 10 ** digits:.{digits}f}"
    number = Number(0, len(text) + 2 * pad, "  " * pad + text, unit, pad)
    assert formatted(number, number.value) == number.text
    new = formatted(number, number.value + change)
    kept = max(digits, DECIMALS[unit])
    assert abs(float(new) - (number.value + change)) <= 0.5 * 10.0 ** -kept * (1 + 1e-9) + 1e-12 * abs(float(new))
    if new != number.text:
        assert len(new.strip().split(".")[1]) == kept
    if pad:
        assert len(new) >= len(number.text) and new.strip() == new.lstrip()


def test_a_turned_flange_with_its_tool_turned_back_changes_nothing(kuka_cal, tmp_path):
    """`flange:` in the frames file: the controller's flange F in the robot file's frame n. The same
    TCP given as F^-1 T on that flange must give the same corrected program as T on frame n."""
    source = _copy_krl(tmp_path)
    plain = filter_program(kuka_cal[0], source, tmp_path / "a" / "palletize.src", tmp_path / "frames.yaml")[0]
    F = kuka.pose((0.0, 0.0, 50.0, 30.0, 10.0, 0.0))
    tool = np.linalg.inv(F) @ kuka.pose((0, 0, 320, 0, -90, 0))
    numbers = [*(1e3 * tool[:3, 3]), *Rotation.from_matrix(tool[:3, :3]).as_euler("ZYX", degrees=True)]
    (tmp_path / "turned.yaml").write_text(f"flange: [0, 0, 50, 30, 10, 0]\ntools:\n  1: {[float(v) for v in numbers]}\n"
                                          f"bases:\n  2: [1800, -400, 650, 90, 0, 0]\n")
    turned = filter_program(kuka_cal[0], source, tmp_path / "b" / "palletize.src", tmp_path / "turned.yaml")[0]
    assert [c.reason for c in plain.changes] == [c.reason for c in turned.changes]
    for x, y in zip(plain.changes, turned.changes):
        if x.after is not None and x.target.kind == "pose":
            assert np.allclose([float(v) for v in x.after], [float(v) for v in y.after], atol=2e-3)


def test_ur_movec_and_get_inverse_kin_targets_are_read(tmp_path):
    program = tmp_path / "c.script"
    program.write_text("def c():\n  movej(get_inverse_kin(p[0.5, -0.2, 0.3, 3.1, 0.1, 0.0], qnear=[0, -1.5, 1.5, -1.5, -1.5, 0]),"
                       " a=1.4, v=1.05)\n  movec(p[0.5, -0.1, 0.3, 3.1, 0.1, 0.0], Via_p, a=1.2, v=0.25, r=0.05, mode=1)\n"
                       "  movec(Via_p, p[0.4, 0.0, 0.3, 3.1, 0.1, 0.0], a=1.2, v=0.25)\nend\n")
    listed = [t for t in ur.parse(program).targets if t.kind == "motion"]
    assert [(t.name, t.line) for t in listed] == [("movec to Via_p (line 3)", 3), ("movec to Via_p (line 4)", 4)]
    program.write_text(program.read_text().replace("def c():\n", "def c():\n  global Via_p=p[0.45, -0.15, 0.3, 3.1, 0.1, 0.0]\n"))
    targets = ur.parse(program).targets
    assert [(t.name, t.kind, t.values[0]) for t in targets] == [
        ("Via_p", "pose", 0.45), ("movej line 3", "pose", 0.5), ("movec line 4", "pose", 0.5),
        ("movec line 5", "pose", 0.4)]


def test_ur_variables_set_again_or_named_like_a_parameter_are_not_targets(tmp_path):
    """A variable the program gives a literal and then sets again (element by element, or from a
    call), or a function's parameter of a literal's name, moves the robot to a value known only at run
    time: listed and kept, its initial literal never rewritten. A variable assigned once is a target."""
    program = tmp_path / "v.script"
    program.write_text("def v():\n  global home = [0.1, -1.5, 1.5, -1.5, -1.5, 0.2]\n  global q = [0, 0, 0, 0, 0, 0]\n"
                       "  q[0] = read_input_float_reg(0)\n  global p1 = p[0.5, -0.2, 0.3, 3.1, 0.1, 0.0]\n"
                       "  p1 = get_actual_tcp_pose()\n  def go(home):\n    movej(home)\n  end\n"
                       "  movej(home)\n  movej(q)\n  movel(p1)\nend\n")
    found = [(t.name, t.kind) for t in ur.parse(program).targets]
    assert found == [("movej to home (line 8)", "motion"), ("movej to home (line 10)", "motion"),
                     ("movej to q (line 11)", "motion"), ("movel to p1 (line 12)", "motion")]
    program.write_text(program.read_text().replace("  def go(home):\n    movej(home)\n  end\n", ""))
    assert [(t.name, t.kind) for t in ur.parse(program).targets][0] == ("home", "joint")


def test_krl_circ_and_spline_motions_name_their_targets(tmp_path):
    (tmp_path / "arc.src").write_text("DEF arc( )\n$TOOL=TOOL_DATA[1]\n$BASE=BASE_DATA[2]\n"
                                      "CIRC XAUX1, {X 10,Y 20,Z 30,A 0,B 90,C 0,S 2,T 10} CA 180 C_DIS\n"
                                      "SLIN XEND1 WITH $VEL = SVEL_CP(0.2, , LCPDAT1)\nSPTP {A1 1,A2 -90,A3 90,A4 0,A5 30,A6 0}\nEND\n")
    (tmp_path / "arc.dat").write_text("DEFDAT arc\nDECL E6POS XAUX1={X 1,Y 2,Z 3,A 4,B 5,C 6,S 2,T 10,E1 0}\n"
                                      "DECL E6POS XEND1={X 7,Y 8,Z 9,A 1,B 2,C 3,S 6,T 2,E1 0}\nDECL E6POS XUNUSED={X 7,Y 8,"
                                      "Z 9,A 1,B 2,C 3,S 6,T 2}\nENDDAT\n")
    found = {t.name: (t.kind, t.tool, t.base, t.config) for t in kuka.parse(tmp_path / "arc.src").targets}
    assert found == {"CIRC line 4": ("pose", "1", "2", (2, 10)), "SPTP line 6": ("joint", None, None, None),
                     "XAUX1": ("pose", "1", "2", (2, 10)), "XEND1": ("pose", "1", "2", (6, 2)),
                     "XUNUSED": ("motion", None, None, None)}



def test_krl_motion_to_a_frame_of_the_dat_names_the_frame(tmp_path):
    """`LIN P1` to a FRAME the .dat declares: listed with the declaration's line and why it is kept (no
    S and T to solve in); before, it read as 'declared outside the program'."""
    (tmp_path / "fr.src").write_text("DEF fr( )\n$TOOL=TOOL_DATA[1]\n$BASE=BASE_DATA[2]\nLIN P1\nPTP XP2 C_PTP\nEND\n")
    (tmp_path / "fr.dat").write_text("DEFDAT fr\nDECL FRAME P1={X 1500,Y 0,Z 1200,A 0,B 90,C 0}\n"
                                     "DECL POS XP2={X 1400,Y 100,Z 1100,A 0,B 90,C 0}\nENDDAT\n")
    found = {t.name: (t.kind, t.note) for t in kuka.parse(tmp_path / "fr.src").targets}
    assert found == {"P1 (line 4)": ("motion", "a FRAME (fr.dat:2): it names no configuration (S, T) to solve in, "
                                               "not corrected"),
                     "XP2": ("pose", None)}

def test_krl_partial_inline_targets_are_listed_and_kept(kuka_cal, tmp_path):
    """`SLIN {X 100}` inside a spline block: KRL takes the missing components from the position before
    it while the program runs, so the motion is listed with what it lacks and kept (it refused the
    whole program before); a complete inline target beside it is still corrected, every other byte kept."""
    source = tmp_path / "spl.src"
    source.write_text("def spl()\n$TOOL=TOOL_DATA[1]\n$BASE=BASE_DATA[2]\n"
                      "sptp {a1 10,a2 -80,a3 95,a4 5,a5 40,a6 -10} c_ptp\nSpline with $acc=100, $vel.cp=3\n"
                      "slin {x 100}\nscirc {x 110, y 110}, {x 120, y 90}\nslin {y 200} c_dis\nEndSpline\n"
                      "PTP_Spline with $vel.ptp=100\nsptp {a1 90}\nEndSpline c_spl\nend\n")
    outcome, _, _ = filter_program(kuka_cal[0], source, tmp_path / "out" / "spl.src", DATA / "krl" / "frames.yaml")
    kept = {c.target.name: c.reason for c in outcome.kept}
    assert outcome.corrected == 1 and outcome.changes[0].target.name == "SPTP line 4"
    assert kept == {"SLIN line 6": "a partial target (Y, Z, A, B, C from the position before it while the program "
                                   "runs): not corrected",
                    "SCIRC line 7": "a partial target (Z, A, B, C from the position before it while the program runs): "
                                    "not corrected",
                    "SLIN line 8": "a partial target (X, Z, A, B, C from the position before it while the program "
                                   "runs): not corrected",
                    "SPTP line 11": "a partial target (A2, A3, A4, A5, A6 from the position before it while the "
                                    "program runs): not corrected"}
    before, after = source.read_text().splitlines(), (tmp_path / "out" / "spl.src").read_text().splitlines()
    assert [k for k, (a, b) in enumerate(zip(before, after), 1) if a != b] == [4] and len(before) == len(after)

# -- public programs (tests/data/programs/README.md names their sources and licences) ----------------

#: a motion instruction's line, found independently of the parsers: every one must be a target or name one
MOTION_LINES = {"krl": r"^[ \t]*(?:S?PTP|S?LIN|S?CIRC)\b", "rapid": r"^[ \t]*(?:Move\w*|Trigg[JLC]|EGMMove[LC])\b",
                "tp": r"^[ \t]*\d*[ \t]*:[ \t]*[JLCA][ \t]+P", "ur": r"\b(?:optimove[jl]|move[jlpc])\("}
COMMENT = {"krl": r";.*", "rapid": r"!.*", "tp": r"!.*", "ur": r"#.*|\"[^\"]*\""}


def _motion_lines(fmt, path: Path) -> list[int]:
    import re

    return [k for k, line in enumerate(path.read_text().splitlines(), 1)
            if re.search(MOTION_LINES[fmt.name], re.sub(COMMENT[fmt.name], "", line), re.I)]


@pytest.mark.parametrize("fmt, source, cal, n_kept", [
    (ur.FORMAT, "ur/ur_rtde/rtde_control.script", "ur_cal", 9),
    (fanuc.FORMAT, "tp/fanex/fanex_mj.ls", "fanuc_cal", 1),
    (fanuc.FORMAT, "tp/fanex/fanex_ml.ls", "fanuc_cal", 1),
    (fanuc.FORMAT, "tp/fanex/fanex.ls", "fanuc_cal", 0),
    (fanuc.FORMAT, "tp/airo_fanuc/GRPRUN.LS", "fanuc_cal", 0),
    (abb.FORMAT, "rapid/abbrobotegm/MainModule.mod", "abb_cal", 3),
    (kuka.FORMAT, "krl/kuka_experimental/ros_krlptp.src", "kuka_cal", 2),
])
def test_public_driver_programs_round_trip_and_name_every_motion(fmt, source, cal, n_kept, request, tmp_path):
    """Drivers and examples their packages publish: ur_rtde's control script (every motion to a target
    set while the program runs, some to variables the program first gives a literal value and then
    sets again from registers, or to a function's parameter named like one); fanex's TP moves to a
    position register at a speed from a register, its and airo-fanuc's launchers without a motion;
    abbrobotegm's RAPID module moving to a robtarget and through EGM to an offset of it, both declared
    outside the module; the KRL program KUKA's ROS driver runs (a .src and the .dat a controller saved)
    moving to a global point and to a point of its .dat it sets from the robot's readings. Zero and real calibrations leave every byte; each motion is listed with its
    line and why it is not corrected, none is dropped."""
    source = DATA / source
    outcome = _round_trips(fmt, request.getfixturevalue(cal)[0], source, tmp_path / source.name)
    assert all(out.read_bytes() == src.read_bytes() for src, out in
               [(p, tmp_path / p.name) for p in fmt.parse(source).texts])
    kept = outcome.kept
    assert outcome.corrected == 0 and len(kept) == n_kept == len(outcome.changes)
    assert sorted({c.target.line for c in kept}) == _motion_lines(fmt, source)
    assert all(c.reason.startswith(("declared without a value", "a target computed at run time",
                                     "a position register", "a target computed or declared elsewhere",
                                     "declared outside the program", "set while the program runs")) for c in kept)


def test_public_krl_program_with_inline_joint_targets_is_corrected_and_keeps_every_other_byte(kuka_cal, tmp_path):
    """The RSI program of ROS-Industrial's KUKA driver, as written for a KR C4 (no .dat: its two motions
    go to the same inline axis target, {A1 0, A2 -90, A3 90, A4 0, A5 90, A6 0}): a zero calibration
    leaves every byte, a real one rewrites only the twelve numbers, both motions alike, by what
    compensate gives for that posture."""
    source = DATA / "krl" / "kuka_experimental" / "ros_rsi.src"
    outcome = _round_trips(kuka.FORMAT, kuka_cal[0], source, tmp_path / "ros_rsi.src")
    assert outcome.corrected == 2 == len(outcome.changes) and outcome.changes[0].after == outcome.changes[1].after
    q = np.radians([[0.0, -90.0, 90.0, 0.0, 90.0, 0.0]])
    expected = np.degrees(kuka_cal[0].compensate(q).q[0])
    assert np.allclose([float(v) for v in outcome.changes[0].after], expected, atol=0.51e-4)
    assert outcome.changes[0].position_mm > 0.1


@pytest.mark.parametrize("name, n_corrected", [("EXAMPLE.LS", 4), ("EXAMPLE_COOR.LS", 2)])
def test_public_tp_programs_with_taught_positions_round_trip_and_are_corrected(fanuc_cal, tmp_path, name,
                                                                               n_corrected):
    """Two TP programs as a FANUC controller (or its simulator) writes them, with positions taught on its
    arm (a circular move over two lines; a coordinated motion whose group 2 is a second robot, left as
    it is): a zero
    calibration leaves every byte, a real one rewrites only group 1's numbers and keeps every CONFIG
    (landing nearer on the truth robot is shown on the programs written here). Taught on a smaller arm
    than the test robot, P[5] (N D B) and P[6] of EXAMPLE.LS are out of its reach: kept and listed."""
    folder = DATA / "tp" / "fanuc_motion_program_exec"
    source, out = folder / name, tmp_path / name
    outcome = _round_trips(fanuc.FORMAT, fanuc_cal[0], source, out, folder / "frames.yaml")
    assert outcome.corrected == n_corrected
    assert all(c.reason.startswith("unreachable by the nominal model") for c in outcome.kept)
    if name == "EXAMPLE_COOR.LS":  # group 2's lines are byte for byte those of the original
        assert [line for line in out.read_text().splitlines() if "1512.343" in line or "-150.909" in line] == \
            [line for line in source.read_text().splitlines() if "1512.343" in line or "-150.909" in line] != []
    assert all(0.01 < c.position_mm < 20.0 for c in outcome.changes if c.after is not None)


def test_irb2600_robot_file_is_the_urdf_chain_to_tool0(rng):
    """tests/data/programs/robots/irb2600.yaml against the chain of ROS-Industrial's IRB 2600-12/1.65
    URDF built here joint by joint (origins, axes, and tool0 turned 90 deg about the flange's y)."""
    arm = arm_of(load_robot(DATA / "robots" / "irb2600.yaml"), np.eye(4))
    origins = [(0, 0, 0.445), (0.15, 0, 0), (0, 0, 0.7), (0, 0, 0.115), (0.795, 0, 0), (0.085, 0, 0)]
    axes = [(0, 0, 1), (0, 1, 0), (0, 1, 0), (1, 0, 0), (0, 1, 0), (1, 0, 0)]
    for q in rng.uniform(-2.5, 2.5, (6, 6)):
        T = np.eye(4)
        for origin, axis, angle in zip(origins, axes, q):
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = Rotation.from_rotvec(angle * np.array(axis)).as_matrix(), origin
            T = T @ step
        T[:3, :3] = T[:3, :3] @ _ry(np.pi / 2)
        assert np.allclose(arm.fk(q[None])[0], T, atol=1e-12)


def test_public_rapid_module_with_taught_robtargets_round_trips_and_is_corrected(tmp_path):
    """A RAPID module with five robtargets taught with tool0 in wobj0 on an IRB 2600-12/1.65 (a TCP
    calibration's approach points as the controller keeps them: ten-digit quaternions, cf1 cf4 cf6 cfx
    each its own), moved to in syncRS and read by name at run time. gecgen's confdata rules find every
    one reachable on the arm's nominal model in the configuration it names; a zero calibration leaves
    every byte, a real one rewrites only the five targets' numbers (by 0.01 to 20 mm), every confdata
    kept."""
    source = DATA / "rapid" / "rapid_scripts_demos" / "ToolCenterCalculations.mod"
    cal = _calibrated(DATA / "robots" / "irb2600.yaml", DATA / "robots" / "irb2600.truth.yaml",
                      str(ROOT / "robots" / "constant.errors.yaml"))
    outcome = _round_trips(abb.FORMAT, cal[0], source, tmp_path / source.name)
    assert outcome.corrected == 5 == len(outcome.changes)
    assert all(0.01 < c.position_mm < 20.0 for c in outcome.changes)


def test_krl_points_the_program_sets_while_it_runs_are_listed_not_corrected(tmp_path):
    """A .dat point the .src assigns (whole, or a component) goes where the running program puts it:
    its motions are listed with the line that sets it and its declared value is not a target; a point
    only compared (`==`) is still one."""
    (tmp_path / "run.src").write_text("DEF run( )\n$TOOL=TOOL_DATA[1]\n$BASE=BASE_DATA[2]\nXNEXT = $AXIS_ACT_MEAS\n"
                                      "XP2.X = 100\nIF XP3 == XP3 THEN\nENDIF\nPTP XNEXT\nLIN XP2\nLIN XP3\nEND\n")
    (tmp_path / "run.dat").write_text("DEFDAT run\nE6AXIS XNEXT={A1 1,A2 -90,A3 90,A4 0,A5 30,A6 0}\n"
                                      "DECL E6POS XP2={X 1,Y 2,Z 3,A 4,B 5,C 6,S 2,T 10}\n"
                                      "DECL E6POS XP3={X 7,Y 8,Z 9,A 1,B 2,C 3,S 6,T 2}\nENDDAT\n")
    found = [(t.name, t.kind, t.note) for t in kuka.parse(tmp_path / "run.src").targets]
    assert found == [
        ("XNEXT (line 8)", "motion", "set while the program runs (run.src:4): its declared value is not where the "
                                     "robot goes, not corrected"),
        ("XP2 (line 9)", "motion", "set while the program runs (run.src:5): its declared value is not where the robot "
                                   "goes, not corrected"),
        ("XP3", "pose", None)]


def test_cli_names_a_public_programs_first_kept_target_by_file_and_line(ur_cal, tmp_path):
    cal = tmp_path / "cal.json"
    ur_cal[0].save(cal)
    source = DATA / "ur" / "ur_rtde" / "rtde_control.script"
    code, out, err = _cli("filter", cal, source, "-o", tmp_path / "out.script")
    assert code != 0 and f"{source}:167: movej to move_q (line 167) kept as written (a target computed at run time" \
        in err
    assert (tmp_path / "out.script").read_bytes() == source.read_bytes()
    assert json.loads(out)["corrected"] == 0 and len(json.loads(out)["kept"]) == 9


# -- the Python API and the robots the filters speak for ---------------------------------------------

def test_api_filter_program_returns_every_target_typed(kuka_cal, tmp_path):
    """gecgen.filter_program without an output writes nothing and returns the corrected texts; each
    target's before and after are the numbers in the input and output texts, and a joint target's
    correction (mm) is the nominal flange's move between them, computed here from the written numbers."""
    import gecgen

    source = _copy_krl(tmp_path)
    before = sorted(tmp_path.iterdir())
    done = gecgen.filter_program(kuka_cal[0], source, frames=tmp_path / "frames.yaml")
    assert sorted(tmp_path.iterdir()) == before and done.written == {} and done.log is None
    assert done.format == "krl" and isinstance(done.targets[0], gecgen.ProgramTarget)
    original = kuka.parse(source)
    out = tmp_path / "out"
    out.mkdir()
    for path, text in done.texts.items():
        (out / path.name).write_bytes(text.encode("latin-1"))
    filtered = kuka.parse(out / "palletize.src")
    assert [t.before for t in done.targets] == [tuple(n.text for n in t.numbers) for t in original.targets]
    assert [t.after or t.before for t in done.targets] == [tuple(n.text for n in t.numbers) for t in filtered.targets]
    assert done.corrected == sum(t.corrected for t in done.targets) >= 10
    assert {t.name: t.reason.split(":")[0] for t in done.kept} == {
        "XHOME (line 14)": "declared outside the program", "XHOME (line 39)": "declared outside the program",
        "LIN_REL line 25": "a relative motion"}
    assert sum(done.counts.values()) == len(done.targets)
    arm = arm_of(kuka_cal[1], np.eye(4))
    joints = [t for t in done.targets if t.kind == "joint" and t.corrected]
    assert joints
    for t in joints:
        q0, q1 = (np.radians([float(v) for v in values]) for values in (t.before, t.after))
        moved = 1e3 * np.linalg.norm(arm.fk(q1)[0][:3, 3] - arm.fk(q0)[0][:3, 3])
        assert abs(moved - t.position_mm) < 0.01  # the written joints are rounded to 1e-4 deg


def test_api_filter_program_takes_a_calibration_file_and_writes_program_dat_and_log(kuka_cal_file, tmp_path):
    import gecgen

    source = _copy_krl(tmp_path)
    done = gecgen.filter_program(kuka_cal_file, source, tmp_path / "out" / "palletize.src",
                                 frames=tmp_path / "frames.yaml")
    assert sorted(p.name for p in done.written.values()) == ["palletize.dat", "palletize.src"]
    assert all(done.texts[src].encode("latin-1") == dst.read_bytes() for src, dst in done.written.items())
    assert len(done.log.read_text().splitlines()) == 1 + len(done.targets)


def test_api_filter_program_refuses_what_is_not_a_calibration_in_one_line():
    import gecgen

    source = DATA / "ur" / "pick_place.script"
    with pytest.raises(ModelError, match=r"^calibrator: None is neither a Calibrator nor a calibration file's path"):
        gecgen.filter_program(None, source)
    with pytest.raises(ModelError, match=r"not fitted yet"):
        gecgen.filter_program(gecgen.Calibrator(), source)


@pytest.mark.parametrize("robot, why", [
    ("panda", "it has 7 axes"), ("pps", "joint lateral is prismatic"), ("tiago", "joint torso_lift_joint is prismatic"),
    ("humanoid", "it branches into 2 tools"),
])
def test_a_robot_that_is_not_a_six_axis_revolute_arm_is_refused_naming_why(robot, why):
    from gecgen.deliver.programs.core import require_six_axis_arm

    with pytest.raises(ModelError) as err:
        require_six_axis_arm(load_robot(ROOT / "robots" / f"{robot}.yaml"))
    assert str(err.value).startswith(f"robot {robot}: program filters correct serial arms of six revolute joints")
    assert f", and {why}; correct this robot's commands with gecgen compensate" in str(err.value)
    assert "\n" not in str(err.value)


# -- the controller a calibration's robot runs on ------------------------------------------------------

def test_a_program_of_another_controller_is_refused_naming_both(ur_cal, tmp_path):
    """A FANUC TP program filtered with the calibration of a robot whose file names controller ur (the
    UR10's): refused in one line naming the program's controller and the robot's, nothing written; the
    calibration file records the controller and the command names it."""
    cal = tmp_path / "cal.json"
    ur_cal[0].save(cal)
    assert json.loads(cal.read_text())["controller"] == "ur"
    source = _copy_tp(tmp_path)
    code, out, err = _cli("filter", cal, source, "-o", tmp_path / "out" / "weld_seam.ls", "--frames",
                          tmp_path / "frames.yaml")
    assert code == 2 and out == "" and not (tmp_path / "out").exists()
    assert err.strip() == (f"gecgen filter: {source}: a FANUC TP program, and the calibration is of robot ur10, whose "
                           f"ur10.yaml names controller ur; filter it with a calibration of the robot that runs it")
    code, out, err = _cli("filter", cal, DATA / "ur" / "pick_place.script", "-o", tmp_path / "p.script")
    assert json.loads(out)["controller"] == "ur" and "warning" not in err


def test_a_robot_file_without_a_controller_filters_with_a_warning_naming_the_key(fanuc_cal, tmp_path):
    source = _copy_tp(tmp_path)
    with pytest.warns(UserWarning) as caught:
        outcome, _, _ = filter_program(fanuc_cal[0], source, tmp_path / "out" / "weld_seam.ls", tmp_path / "frames.yaml")
    assert outcome.corrected == 8
    messages = [str(w.message) for w in caught if "controller" in str(w.message)]
    assert messages == ["robot fanuc: fanuc.yaml names no controller, so nothing checks that this FANUC TP program was "
                        "written for it; add 'controller: fanuc' to fanuc.yaml if it runs on it (then identify again: a "
                        "calibration holds to its robot file as it was)"]


def test_a_robot_files_controller_must_be_one_the_filters_know(tmp_path):
    text = (DATA / "robots" / "ur10.yaml").read_text()
    (tmp_path / "r.yaml").write_text(text.replace("controller: ur", "controller: UR10 CB3"))
    with pytest.raises(ModelError) as err:
        load_robot(tmp_path / "r.yaml")
    assert str(err.value) == (f"{tmp_path / 'r.yaml'}: controller: 'UR10 CB3'; give one of kuka, abb, fanuc, ur (the "
                              f"controller whose programs gecgen filter corrects for this robot), or leave the key out")
    assert load_robot(DATA / "robots" / "ur10.yaml").controller == "ur"
    assert load_robot(ROOT / "robots" / "fanuc.yaml").controller == ""
