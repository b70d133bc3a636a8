"""`gecgen check`: a short QA measurement against a calibration (gecgen/runtime/drift.py): pass or fail,
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


def _check_data(path, robot, truth, seed, move=None):
    data = simulate(robot, truth, random_design(robot, 8, np.random.default_rng(seed)), np.random.default_rng(seed + 1))
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
