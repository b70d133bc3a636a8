"""diagnose finds the elastic effects of real arms from the chain's physics (issue 11's acceptance):
joints that twist under gravity on a 7-joint arm measured without a force sensor and calibrated
without its masses, compliance under a measured payload on a 6R arm, and free play on top of
compliance; each down to the noise floor, from constant errors.

Noise floor: the RMS point error of pure noise, sqrt(3 (tracker^2 + repeatability^2))."""
import re

import numpy as np
import pytest
from conftest import ROBOTS

from gecgen.loop.diagnose import diagnose
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.validation import read_yaml
from gecgen.simulate import load_truth, random_design, simulate


def floor_mm(truth) -> float:
    return 1e3 * np.sqrt(3 * (truth.tracker ** 2 + truth.repeatability ** 2))


def datasets(robot, truth, n_train, n_val, payloads=(0.0,)):
    out = []
    for n, seed in ((n_train, 1), (n_val, 2)):
        rng = np.random.default_rng(seed)
        out.append(simulate(robot, truth, random_design(robot, n, rng, payloads), rng))
    return out


@pytest.fixture(scope="module")
def massless_panda(tmp_path_factory):
    """The Panda's kinematics without its masses: what a user who knows nothing of the links has."""
    folder = tmp_path_factory.mktemp("panda")
    urdf = (ROBOTS / "panda" / "panda.urdf").read_text()
    (folder / "panda.urdf").write_text(re.sub(r"<inertial>.*?</inertial>", "", urdf, flags=re.S))
    (folder / "panda.yaml").write_text((ROBOTS / "panda.yaml").read_text().replace("panda/panda.urdf", "panda.urdf"))
    return load_robot(folder / "panda.yaml")


def panda_truth(robot, extra=()):
    spec = read_yaml(ROBOTS / "panda.truth.yaml", "truth")
    spec["sources"] = spec["sources"] + list(extra)
    return load_truth(spec, robot)


def test_joints_twisting_under_gravity_without_masses_or_force_sensor(massless_panda):
    panda = load_robot(ROBOTS / "panda.yaml")
    truth = panda_truth(panda)
    train, val = datasets(panda, truth, 200, 100)
    diag = diagnose(massless_panda, load_error_model(None, massless_panda), train, val)
    traced = {e.error for e in diag.effects if e.family == "joint compliance"}
    assert {"2.er", "4.er"} <= traced, [e.to_dict() for e in diag.effects]  # the two stiffest-loaded joints
    assert all("gravity_torque" not in t for e in diag.effects for t in e.terms)  # no masses were known
    assert diag.before["val_rms_mm"] > 3 * floor_mm(truth)
    assert diag.after["val_rms_mm"] < 1.3 * floor_mm(truth), (diag.after, floor_mm(truth))


def test_free_play_on_top_of_compliance():
    panda = load_robot(ROBOTS / "panda.yaml")
    truth = panda_truth(panda, [{"type": "play", "joint": 5, "width": 1.0e-3}])  # 0.5 mrad either side
    train, val = datasets(panda, truth, 200, 100)
    diag = diagnose(panda, load_error_model(None, panda), train, val)
    play = [e for e in diag.effects if e.family == "free play"]
    assert [(e.error, e.terms) for e in play] == [("5.er", ["sign(gravity_torque(q5))"])], \
        [e.to_dict() for e in diag.effects]
    assert diag.after["val_rms_mm"] < 1.5 * floor_mm(truth), (diag.after, floor_mm(truth))


@pytest.mark.parametrize("declared", [None, "industrial6r.errors.yaml"], ids=["constant", "default"])
def test_compliance_under_a_measured_payload(declared):
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    truth = load_truth(read_yaml(ROBOTS / "industrial6r.truth.yaml", "truth"), robot)
    train, val = datasets(robot, truth, 200, 100, payloads=(0.0, 100.0, 200.0))
    model = load_error_model(ROBOTS / declared if declared else None, robot)
    diag = diagnose(robot, model, train, val)
    assert diag.after["val_rms_mm"] < 1.3 * floor_mm(truth), (diag.after, floor_mm(truth),
                                                              [e.to_dict() for e in diag.effects])
