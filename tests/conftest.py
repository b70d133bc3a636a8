from pathlib import Path

import numpy as np
import pytest

from gecgen.model import load_error_model, load_robot

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ROOT / "robots"
SHIPPED = ["pps", "industrial6r", "puma560"]


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
