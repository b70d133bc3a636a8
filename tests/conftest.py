import contextlib
import functools
import io
import json
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# The suite starts many gecgen processes. Where the environment asks Python not to write bytecode
# (PYTHONDONTWRITEBYTECODE), every one of them would compile gecgen's sources anew, and every worker
# rewrite the tests' assertions anew: the suite writes both once, before it imports them.
sys.dont_write_bytecode = False

from gecgen.cli import main  # noqa: E402 (after the line above, which speeds up its import)
from gecgen.model import load_robot  # noqa: E402
from gecgen.symbolic.terms import load_error_model  # noqa: E402

# the tests run the compiled C: "auto" would run a model new to the cache in numpy and leave a build
# of its C running in the background. Every command a test starts inherits it; the tests of that
# first run set GECGEN_BACKEND themselves.
os.environ.setdefault("GECGEN_BACKEND", "c")
# The suite already runs a test per core (-n 2): a command forking a process per core besides only
# adds forks (test_calibrate.py and test_interrupt.py set it themselves to test those processes,
# whose results test_calibrate.py checks are the same as one process's).
os.environ.setdefault("GECGEN_WORKERS", "1")

# The property tests draw the same examples on every run, so a red run is the change's, not a new
# draw's; GECGEN_HYPOTHESIS=explore draws new ones (what finds new bugs: run it now and then).
settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("GECGEN_HYPOTHESIS", "repeatable"))

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ROOT / "robots"
#: two fixed cameras (a cameras file) 1280 x 960 px with the distortion the camera tests simulate
FIXED_CAMERAS = """cameras:
  cam1: {mount: world, fx: 1800, fy: 1800, cx: 640, cy: 480, distortion: [-0.12, 0.08, 0.0008, -0.0005, 0.0],
         width: 1280, height: 960}
  cam2: {mount: world, fx: 1800, fy: 1800, cx: 640, cy: 480, distortion: [-0.12, 0.08, 0.0008, -0.0005, 0.0],
         width: 1280, height: 960}
"""
SHIPPED = ["pps", "industrial6r", "puma560"]
#: an error model of the Panda with joint load terms (shared: its code is compiled once per run)
JOINT_LOADS = {"default": ["1"], "frames": {6: {"er": ["1", "sign(gravity_torque(q6))", "gravity(panda_joint6)",
                                                    "q3*wrench_torque(q2)", "abs(gravity(panda_joint4, 2))"]}}}
#: an error model of the humanoid tree with frame load terms
FRAME_LOADS = {"default": ["1"], "frames": {
    4: {"es": ["1", "gravity_load(torso_4_joint, my)"]},
    2: {"ep": ["1", "gravity(torso_2_joint, mx)"], "er": ["q1*wrench_load(2, mz)"]},
    5: {"ep": ["1", "sign(gravity(arm_left_1_joint, mx, 1))"]}}}


@functools.cache
def _builds_a_fixture_once(module: str) -> bool:
    """Whether a test module (its path from the checkout's root) defines a fixture built once for
    the module or the run: a simulated data set and its calibrations, rendered images, sanitized builds."""
    return re.search(r'@pytest\.fixture\([^)]*scope="(module|session)"', (ROOT / module).read_text()) is not None


@pytest.hookimpl(tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    """With -n, the tests of a module that builds a fixture once run on one worker, which builds it
    once: handed out one by one (xdist's default), they reached both workers, and each built it
    again. The other tests are handed out one by one after those modules, and even out the
    workers' ends. (xdist's own `--dist loadgroup` groups nothing under pytest 9.2: it renames a
    test through an attribute pytest no longer reads.)"""
    if config.getvalue("dist") != "load":  # another distribution asked for by name
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ByModuleFixtures(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::")[0]
            return module if _builds_a_fixture_once(module) else nodeid

    return ByModuleFixtures(config, log)


def random_q(robot, rng, n=None):
    lo = np.array([max(j.lower, -np.pi) for j in robot.joints])
    hi = np.array([min(j.upper, np.pi) for j in robot.joints])
    return rng.uniform(lo, hi, (n, robot.n) if n else robot.n)


@pytest.fixture(params=SHIPPED)
def shipped(request):
    robot = load_robot(ROBOTS / f"{request.param}.yaml")
    return robot, load_error_model(ROBOTS / f"{request.param}.errors.yaml", robot)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def run_json(*args) -> dict:
    """A command's JSON, run in this process (as `gecgen ARGS --json`); its stderr shown if it fails."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main([*map(str, args), "--json"]) == 0, err.getvalue()
    return json.loads(out.getvalue())
