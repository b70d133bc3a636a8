"""Long commands say how far they are on a terminal (a rich status line on stderr, cleared at the
end) and nothing when stderr is a file or a pipe, where it holds only warnings and a failure's reason."""
from __future__ import annotations

import os
import pty
import subprocess
import sys

import pytest

from conftest import ROBOTS, ROOT
from gecgen.cli import main

PUMA = str(ROBOTS / "puma560.yaml")


def _gecgen(argv: list[str], terminal: bool) -> tuple[int, str]:
    """`gecgen ARGV` in its own process, stderr a terminal (a pseudo-terminal) or a pipe: (exit code, stderr)."""
    if not terminal:
        run = subprocess.run([sys.executable, "-m", "gecgen.cli", *argv], cwd=ROOT, capture_output=True, text=True)
        return run.returncode, run.stderr
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "gecgen.cli", *argv], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=slave)
    os.close(slave)
    chunks = []
    while True:
        try:
            chunk = os.read(master, 1 << 16)
        except OSError:  # the terminal's other end closed: the command ended
            break
        if not chunk:
            break
        chunks.append(chunk)
    os.close(master)
    return proc.wait(), b"".join(chunks).decode(errors="replace")


@pytest.fixture(scope="module")
def train(tmp_path_factory):
    path = tmp_path_factory.mktemp("progress") / "train.csv"
    assert main(["simulate", PUMA, "--poses", "30", "--seed", "1", "-o", str(path), "--json"]) == 0
    return path


@pytest.mark.parametrize("terminal", [True, False])
def test_calibrate_says_how_far_it_is_on_a_terminal_only(train, tmp_path, terminal):
    out = tmp_path / "cal"
    code, err = _gecgen(["calibrate", PUMA, str(train), "--holdout", "0.2", "--models", "geometric", "-o", str(out)],
                        terminal)
    assert code == 0
    if terminal:  # each step after the candidates' folds is said, up to the last
        for step in ("cross-validating the geometric model on the training poses",
                     "fitting the chosen geometric model on all 24 training poses",
                     "testing which of the geometric model's coefficients the data determine",
                     "scoring the calibration on the held-out poses",
                     "writing the calibration, its code and the report into"):
            assert step in err, step
    else:
        lines = err.splitlines()
        assert lines and all(line.startswith("gecgen calibrate: warning: ") for line in lines), err


@pytest.mark.parametrize("terminal", [True, False])
def test_fleet_counts_the_robots_done_on_a_terminal_only(tmp_path, terminal):
    pytest.importorskip("dask.distributed")
    (tmp_path / "m.csv").write_text(f"name,robot,train\ngone,{PUMA},missing.csv\n")
    code, err = _gecgen(["fleet", str(tmp_path / "m.csv"), "-o", str(tmp_path / "out"), "--workers", "1"], terminal)
    assert code == 1
    assert ("1 of 1 robots done (1 failed)" in err) == terminal
    if not terminal:
        assert err.splitlines() == [f"gecgen fleet: gone: {tmp_path}/missing.csv: no such measurement file",
                                    "gecgen fleet: 1 of 1 robots failed: gone"]


@pytest.mark.parametrize("terminal", [True, False])
def test_simulate_plates_says_what_it_is_doing_on_a_terminal_only(tmp_path, terminal):
    code, err = _gecgen(["simulate", str(ROBOTS / "panda_ball.yaml"), "--plates", "1", "-o", str(tmp_path / "s.csv")],
                        terminal)
    assert code == 0
    assert ("placing the fixtures and solving the robot's configurations" in err) == terminal
    if not terminal:  # the one warning: no truth file
        assert [ln.split(":")[1] for ln in err.splitlines()] == [" warning"], err


@pytest.mark.parametrize("terminal", [True, False])
def test_accuracy_says_what_it_is_doing_on_a_terminal_only(train, tmp_path, terminal):
    assert main(["identify", PUMA, str(train), "-o", str(tmp_path / "c.json"), "--json"]) == 0
    (tmp_path / "v.yaml").write_text("angle_unit: deg\nsamples: 5\n")
    code, err = _gecgen(["accuracy", str(tmp_path / "c.json"), str(tmp_path / "v.yaml"), str(train), "--draws", "400",
                         "--plot", str(tmp_path / "map.png")], terminal)
    assert code == 0
    assert ("drawing the map of the bound over the volume" in err) == terminal
    if not terminal:
        assert all(line.startswith("gecgen accuracy: warning: ") for line in err.splitlines()), err


@pytest.mark.parametrize("terminal", [True, False])
def test_design_says_what_it_is_doing_on_a_terminal_only(tmp_path, terminal):
    code, err = _gecgen(["design", PUMA, "--poses", "8", "-o", str(tmp_path / "d.csv")], terminal)
    assert code == 0
    assert ("choosing 8 poses of" in err) == terminal
    if not terminal:
        assert err == "", err


@pytest.mark.parametrize("terminal", [True, False])
def test_evaluate_compensate_and_the_iso9283_plan_say_what_they_are_doing_on_a_terminal_only(train, tmp_path,
                                                                                              terminal):
    assert main(["identify", PUMA, str(train), "-o", str(tmp_path / "c.json"), "--json"]) == 0
    code, err = _gecgen(["evaluate", str(tmp_path / "c.json"), str(train)], terminal)
    assert code == 0 and ("before and after the calibration" in " ".join(err.split())) == terminal
    if not terminal:
        assert err == "", err
    (tmp_path / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n0.1,-0.4,0.3,0.2,0.5,-0.1\n")
    code, err = _gecgen(["compensate", str(tmp_path / "c.json"), str(tmp_path / "cmd.csv"), "-o",
                         str(tmp_path / "out.csv")], terminal)
    assert code == 0 and ("correcting 1 commands" in " ".join(err.split())) == terminal
    if not terminal:  # the one warning: q3 outside the training ranges
        assert [ln.split(":")[1] for ln in err.splitlines()] == [" warning"], err
    code, err = _gecgen(["iso9283", PUMA, "-o", str(tmp_path / "plan.csv"), "--cycles", "2"], terminal)
    assert code == 0 and ("searching for the largest cube" in " ".join(err.split())) == terminal
    if not terminal:
        assert err == "", err
