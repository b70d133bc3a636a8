"""Ctrl-C, SIGTERM and SIGKILL at several steps of calibrate and fleet, and two runs into one folder.

A run is held at a step by tests/hold.py, which writes a flag file when the run gets there: the
test polls for that file, then signals, so nothing here waits a fixed time or depends on how fast
the machine is. After the signal the output folder must be the old one, the new one or marked
incomplete, and no process of the run may be left (each run's processes carry a tag in their
environment, so they are found even after they lost their parent).
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from conftest import ROBOTS, ROOT
from gecgen.cli import main

HOLD = Path(__file__).with_name("hold.py")
PUMA = str(ROBOTS / "puma560.yaml")
EXIT = {"INT": 130, "TERM": 143, "KILL": -signal.SIGKILL}
SAID = {"INT": "interrupted", "TERM": "terminated"}


@pytest.fixture(scope="module")
def old(tmp_path_factory):
    """Training data, and a calibration folder of an earlier run (fold seed 1; the held runs use
    seed 2, so that the new folder differs from the old)."""
    root = tmp_path_factory.mktemp("interrupt")
    assert main(["simulate", PUMA, "--poses", "30", "--seed", "1", "-o", str(root / "train.csv"), "--json"]) == 0
    assert main(_calibrate(root / "train.csv", root / "old", seed=1)) == 0
    return root


def _calibrate(train, out, seed=2) -> list[str]:
    return ["calibrate", PUMA, str(train), "--holdout", "0.2", "--models", "geometric", "--seed", str(seed),
            "-o", str(out), "--json"]


def _start(argv: list[str], step: str, flags: Path, runs: list) -> tuple[subprocess.Popen, str]:
    """`gecgen ARGV` in a session of its own, held at `step` (tests/hold.py): returns once a process
    of the run has reached the step, with the run's tag; the run is added to `runs`."""
    tag = uuid.uuid4().hex
    env = dict(os.environ, GECGEN_TEST_HOLD=f"{step}:{flags / 'held'}", GECGEN_TEST_TAG=tag, GECGEN_WORKERS="2",
               DASK_DISTRIBUTED__WORKER__PRELOAD=json.dumps([str(HOLD)]))
    proc = subprocess.Popen([sys.executable, str(HOLD), *argv], cwd=ROOT, env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    runs.append(proc)
    while not list(flags.glob("held.*")):  # polled: the run writes the flag when it is at the step
        if proc.poll() is not None:
            pytest.fail(f"the run ended before reaching {step}: {proc.communicate()}")
        time.sleep(0.05)
    return proc, tag


@pytest.fixture
def runs():
    """The held runs a test starts (`_start`): killed, with their process group, if the test fails
    before it signals them, so that a failing test leaves nothing behind."""
    started: list[subprocess.Popen] = []
    yield started
    for proc in started:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()


def _signal(proc: subprocess.Popen, how: str) -> tuple[int, str]:
    """Ctrl-C as a terminal sends it (to every process of the command), SIGTERM and SIGKILL as
    `kill` sends them (to the command only); the exit code and stderr."""
    if how == "INT":
        os.killpg(proc.pid, signal.SIGINT)
    else:
        os.kill(proc.pid, getattr(signal, f"SIG{how}"))
    _, err = proc.communicate(timeout=600)  # a bound on a hang, not a time the test relies on
    return proc.returncode, err


def _survivors(tag: str) -> list[str]:
    """The processes of the tagged run still alive, polled until none is left or for at most 2
    minutes (a bound on failure: processes that die with their parent are gone in milliseconds)."""
    deadline = time.monotonic() + 120
    while True:
        alive = []
        for proc in Path("/proc").glob("[0-9]*"):
            try:
                if f"GECGEN_TEST_TAG={tag}".encode() in (proc / "environ").read_bytes() and \
                        (proc / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z":
                    alive.append(" ".join((proc / "cmdline").read_text().split("\0")))
            except OSError:  # gone meanwhile, or not ours to read
                continue
        if not alive or time.monotonic() > deadline:
            return alive
        time.sleep(0.1)


def _refused(argv: list[str], out: Path, what: str):
    """`gecgen ARGV` into `out` while another run holds it: refused at once, one line naming it."""
    second = subprocess.run([sys.executable, "-m", "gecgen.cli", *argv], cwd=ROOT, capture_output=True, text=True)
    assert second.returncode == 2 and second.stdout == ""
    assert second.stderr == f"gecgen {argv[0]}: {out}: another gecgen run is writing this {what} now; wait for it " \
                            f"to finish, or give another folder\n"


def _snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _hidden(folder: Path) -> list[str]:
    """What gecgen leaves beside an output folder while it works on it."""
    return sorted(p.name for p in folder.parent.glob(f".{folder.name}.gecgen-*"))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="worker processes are forked on Linux only")
@pytest.mark.parametrize("step", ["start", "folds", "report"])
@pytest.mark.parametrize("how", ["INT", "TERM", "KILL"])
def test_an_interrupted_calibrate_leaves_the_old_folder_and_no_process(old, tmp_path, runs, step, how):
    out = tmp_path / "cal"
    shutil.copytree(old / "old", out)
    before = _snapshot(out)
    proc, tag = _start(_calibrate(old / "train.csv", out), step, tmp_path, runs)
    if step == "folds" and how == "TERM":  # a second run into the folder meanwhile is refused, naming it
        _refused(_calibrate(old / "train.csv", out), out, "calibration folder")
    code, err = _signal(proc, how)
    assert code == EXIT[how], err
    assert _survivors(tag) == []
    assert _snapshot(out) == before  # the old folder, whole
    if how != "KILL":
        assert err == f"gecgen calibrate: {SAID[how]}; {out} is as it was before this run\n"
        assert _hidden(out) == []
    else:  # what a killed run left beside the folder goes with the next run, which writes the new folder
        assert main(_calibrate(old / "train.csv", out)) == 0
        new = _snapshot(out)
        assert new.keys() == before.keys() and new["calibration.json"] != before["calibration.json"]
        assert _hidden(out) == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="worker processes are forked on Linux only")
def test_a_first_calibrate_interrupted_leaves_no_folder(old, tmp_path, runs):
    out = tmp_path / "cal"
    proc, tag = _start(_calibrate(old / "train.csv", out), "report", tmp_path, runs)
    code, err = _signal(proc, "TERM")
    assert code == 143 and _survivors(tag) == []
    assert not out.exists() and _hidden(out) == []


@pytest.fixture(scope="module")
def manifest(old):
    path = old / "fleet.csv"
    path.write_text(f"name,robot,train,holdout,models\none,{PUMA},train.csv,0.2,geometric\n")
    return path


@pytest.mark.parametrize("step", ["fleet", "folds", "summary"])
@pytest.mark.parametrize("how", ["INT", "TERM", "KILL"])
def test_an_interrupted_fleet_is_marked_incomplete_and_leaves_no_process(manifest, tmp_path, runs, step, how):
    pytest.importorskip("dask.distributed")
    out = tmp_path / "fleet"
    out.mkdir()
    for name in ("fleet.json", "fleet.csv"):  # an earlier run's summary
        (out / name).write_text("earlier\n")
    argv = ["fleet", str(manifest), "-o", str(out), "--workers", "1", "--json"]
    proc, tag = _start(argv, step, tmp_path, runs)
    if how == "TERM" and step == "folds":  # a second fleet into the folder meanwhile is refused, naming it
        _refused(argv, out, "fleet folder")
    code, err = _signal(proc, how)
    assert code == EXIT[how], err
    assert _survivors(tag) == []
    if step == "fleet":  # before the cluster ran anything: the folder as it was
        assert sorted(p.name for p in out.iterdir()) == ["fleet.csv", "fleet.json"]
        state = "is as it was before this run"
    else:  # the robots ran (the earlier summary gone); while the summary is written: its JSON, not its table
        assert (out / "fleet.incomplete").is_file()
        assert (out / "fleet.json").exists() == (step == "summary") and not (out / "fleet.csv").exists()
        state = f"is marked incomplete ({out / 'fleet.incomplete'})"
    if how != "KILL":  # one line, no traceback of Dask's
        assert err == f"gecgen fleet: {SAID[how]}; {out} {state}: run the fleet again\n"
