"""Issue 12's acceptance path, with command-line calls only: the UR10's URDF and its measured tool
poses (tests/data/ur10: figaroh's data) -> import -> identify -> export --c -> a compiled C
program that compensates a command exactly as `gecgen compensate` does."""
import json
import shlex
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

from gecgen.runtime.compiled import STATUS_NAMES, compiler

UR10 = ROOT / "tests" / "data" / "ur10"


def gecgen(*args) -> dict:
    run = subprocess.run([sys.executable, "-m", "gecgen.cli", *map(str, args), "--json"], capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


@pytest.mark.skipif(compiler() is None, reason="needs a C compiler")
def test_from_urdf_and_pose_csv_to_a_compiled_compensation(tmp_path):
    robot = UR10 / "ur10_probe.yaml"
    poses = tmp_path / "poses.csv"
    imported = gecgen("import", robot, UR10 / "calibration.csv", "--mapping", UR10 / "calibration.mapping.yaml",
                      "-o", poses)
    assert imported["orientations"] == 23
    fit = gecgen("identify", robot, poses, "-o", tmp_path / "ur10.calib.json")
    assert fit["train"]["rms_mm"] < 0.5 * fit["before"]["rms_mm"]
    assert fit["train"]["rot_rms_mrad"] < 0.6 * fit["before"]["rot_rms_mrad"]
    c = gecgen("export", tmp_path / "ur10.calib.json", "--c", tmp_path / "controller")["c"]
    assert subprocess.run(shlex.split(c["compile"]), capture_output=True, text=True).returncode == 0
    printed = subprocess.run(shlex.split(c["run"]), capture_output=True, text=True, check=True).stdout
    status, *joints = printed.splitlines()
    corrected = np.array([float(line.split()[1]) for line in joints])
    command = c["example_command"]["q"]
    (tmp_path / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n" + ",".join(map(repr, command)) + "\n")
    subprocess.run([sys.executable, "-m", "gecgen.cli", "compensate", tmp_path / "ur10.calib.json", tmp_path / "cmd.csv",
                    "-o", tmp_path / "out.csv"], capture_output=True)
    *python, code, _ = (tmp_path / "out.csv").read_text().splitlines()[1].split(",")
    assert np.abs(corrected - np.array(python, float)).max() < 1e-9
    assert status.split()[1:3] == [code, STATUS_NAMES[int(code)]]  # the C and the Python say the same
    assert np.abs(corrected - command).max() > 1e-3  # a real correction, not the command echoed
