"""`gecgen check`: a short QA measurement against a calibration (gecgen/verify/drift.py): pass or fail,
beyond noise or not, and what a change looks like - a moved tracker, a joint that slipped."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from conftest import run_json
import pytest
from scipy.spatial.transform import Rotation

from gecgen.model import load_robot
from gecgen.model.measurements import write_measurements
from gecgen.model.validation import read_yaml
from gecgen.simulate import load_truth, random_design, simulate

ROBOT = "robots/industrial6r.yaml"




@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """industrial6r calibrated with its default model on 120 poses; the same robot (one truth draw) then
    measured 8 times for each check."""
    t = tmp_path_factory.mktemp("check")
    robot = load_robot(ROBOT)
    truth = load_truth(read_yaml("robots/industrial6r.truth.yaml", "truth"), robot)
    write_measurements(t / "train.csv", robot, simulate(robot, truth, random_design(robot, 120, np.random.default_rng(1)),
                                                        np.random.default_rng(2)))
    fit = run_json("identify", ROBOT, t / "train.csv", "-o", t / "c.json")
    assert fit["train"]["rms_mm"] < fit["before"]["rms_mm"] / 5
    return t, robot, truth


def _check_data(path, robot, truth, seed, move=None, noise_seed=None):
    """8 random poses (from seed) measured on truth (noise from noise_seed, default seed + 1)."""
    data = simulate(robot, truth, random_design(robot, 8, np.random.default_rng(seed)),
                    np.random.default_rng(seed + 1 if noise_seed is None else noise_seed))
    if move is not None:
        R, t = move
        data = replace(data, xyz=data.xyz @ R.T + t)
    write_measurements(path, robot, data)
    return path


def test_the_robot_as_calibrated_passes(calibrated):
    t, robot, truth = calibrated
    out = run_json("check", t / "c.json", _check_data(t / "same.csv", robot, truth, 10), "--tolerance-mm", 1.0,
               "--history", t / "h.csv", "--label", "monday")
    assert out["verdict"] == "pass" and not out["beyond_noise"] and out["looks_like"]["kind"] == "as calibrated"
    assert out["max_mm"] < 1.0 and out["p_value"] >= 0.01
    again = run_json("check", t / "c.json", t / "same.csv", "--history", t / "h.csv")
    lines = (t / "h.csv").read_text().splitlines()
    assert len(lines) == 3 and lines[1].split(",")[1] == "monday" and lines[2].split(",")[1] == "same.csv"
    assert again["history"]["checks"] == 2 and (t / "h.png").stat().st_size > 1000


def test_a_moved_tracker_looks_like_a_rigid_motion(calibrated):
    t, robot, truth = calibrated
    turn = Rotation.from_rotvec([0.0, 0.0, np.radians(0.2)]).as_matrix()
    out = run_json("check", t / "c.json", _check_data(t / "moved.csv", robot, truth, 20, (turn, [0.002, 0.0, 0.0])),
               "--tolerance-mm", 1.0)
    assert out["verdict"] == "fail" and out["beyond_noise"]
    assert out["looks_like"]["kind"] == "rigid motion"
    assert abs(out["looks_like"]["rotation_deg"] - 0.2) < 0.01


def test_a_joint_that_slipped_is_named(calibrated):
    t, robot, truth = calibrated
    slipped = replace(truth, joint_offsets=truth.joint_offsets + np.array([0, 0, 1e-3, 0, 0, 0]))
    out = run_json("check", t / "c.json", _check_data(t / "slip.csv", robot, slipped, 30))
    assert out["verdict"] == "no tolerance given" and out["beyond_noise"]
    looks = out["looks_like"]
    assert looks["kind"] == "joint" and looks["joint"] == "q3" and abs(looks["offset"] - 1e-3) < 1e-4


def test_against_a_baseline_the_models_misfit_cancels(calibrated, tmp_path):
    """The same 8 poses measured right after the calibration and on a later day: judged against the
    baseline with the instrument's noise (0.042 mm per coordinate, well under the calibration's 0.19
    mm sigma, which holds the default model's misfit), the unchanged robot is as at the baseline and
    a 0.1 mrad slip of q3 is found and named; against the model, whose misfit at these poses is
    larger than the slip, it is not named."""
    t, robot, truth = calibrated
    base = _check_data(tmp_path / "base.csv", robot, truth, 40)
    noise = str(1e3 * np.hypot(3e-5, 3e-5))
    same = run_json("check", t / "c.json", _check_data(tmp_path / "day.csv", robot, truth, 40, noise_seed=100),
                    "--baseline", base, "--noise-mm", noise)
    assert not same["beyond_noise"] and same["looks_like"]["kind"] == "as at the baseline"
    assert same["baseline"] == str(base) and abs(same["noise_mm"] - float(noise)) < 1e-12
    slipped = replace(truth, joint_offsets=truth.joint_offsets + np.array([0, 0, 1e-4, 0, 0, 0]))
    day = _check_data(tmp_path / "slip.csv", robot, slipped, 40, noise_seed=200)
    found = run_json("check", t / "c.json", day, "--baseline", base, "--noise-mm", noise)
    assert found["beyond_noise"] and found["looks_like"]["kind"] == "joint" and found["looks_like"]["joint"] == "q3"
    assert run_json("check", t / "c.json", day)["looks_like"]["kind"] != "joint"


def _refused(capsys, *args) -> str:
    """The one line a refused check prints (exit 2)."""
    from gecgen.cli import main

    capsys.readouterr()
    assert main([str(a) for a in args]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_a_baseline_of_other_joints_is_refused_and_a_near_one_carried_across(calibrated, tmp_path, capsys):
    """A baseline whose pose ids are the check's but whose joints are 0.05 rad off is not the same pose
    (it was "as at the baseline"); one read 2e-4 rad apart, as a servo may stand, is carried to the
    check's readings by the model and compares like for like."""
    t, robot, truth = calibrated
    noise = str(1e3 * np.hypot(3e-5, 3e-5))
    day = _check_data(tmp_path / "day.csv", robot, truth, 40, noise_seed=100)
    for offset, name in ((0.05, "far.csv"), (2e-4, "near.csv")):
        design = random_design(robot, 8, np.random.default_rng(40))
        design = replace(design, q=design.q + np.array([0, offset, 0, 0, 0, 0]))
        write_measurements(tmp_path / name, robot, simulate(robot, truth, design, np.random.default_rng(41)))
    line = _refused(capsys, "check", t / "c.json", day, "--baseline", tmp_path / "far.csv", "--noise-mm", noise)
    assert "day.csv: row 2: pose 0 has q2 = " in line and "(0.05 apart, more than 0.001 rad or m): not the same pose" \
        in line, line
    near = run_json("check", t / "c.json", day, "--baseline", tmp_path / "near.csv", "--noise-mm", noise)
    assert not near["beyond_noise"] and near["looks_like"]["kind"] == "as at the baseline", near


def test_a_history_is_a_csv_of_checks_and_a_failed_check_is_not_in_it(calibrated, tmp_path, capsys):
    """--history H.png would be replaced by its own plot; a history that is not UTF-8 is one line; a
    check that fails on the way (its plot cannot be written) leaves the history as it was."""
    t, robot, truth = calibrated
    data = _check_data(tmp_path / "same.csv", robot, truth, 10)
    line = _refused(capsys, "check", t / "c.json", data, "--history", tmp_path / "H.png")
    assert "--history" in line and "give a .csv file" in line and not (tmp_path / "H.png").exists()
    (tmp_path / "latin.csv").write_bytes(b"caf\xe9\n")
    line = _refused(capsys, "check", t / "c.json", data, "--history", tmp_path / "latin.csv")
    assert "latin.csv" in line and "not UTF-8" in line, line
    run_json("check", t / "c.json", data, "--history", tmp_path / "h.csv")
    before = (tmp_path / "h.csv").read_text()
    (tmp_path / "h.png").unlink()
    (tmp_path / "h.png").mkdir()  # the plot cannot be written
    _refused(capsys, "check", t / "c.json", data, "--history", tmp_path / "h.csv")
    assert (tmp_path / "h.csv").read_text() == before
    (tmp_path / "h.csv").write_text(before + "2026-11-27T10:00:00+00:00,x,8,abc,1,,pass,false,0.5,as calibrated\n")
    line = _refused(capsys, "check", t / "c.json", data, "--history", tmp_path / "h.csv")
    assert "h.csv: row 3: not a check as gecgen check writes it" in line, line
