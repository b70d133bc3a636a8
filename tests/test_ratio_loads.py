"""Coupling ratios that stand in for loads (`loop.confounding`): the simulated humanoid's passive
torso joint gives under the chest's weight; a constant model's ratio coefficients absorb it and are
said to, a model with the load carries the ratio near its true zero, and a real ratio error on a
rigid robot is fitted and not flagged."""
import warnings
from pathlib import Path

import numpy as np
import pytest

import gecgen
from gecgen.model import load_robot
from gecgen.symbolic.terms import error_model_from_dict
from gecgen.model.validation import read_yaml
from gecgen.report.content import coefficient_section
from gecgen.simulate import load_truth, random_design, simulate

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
RATIOS = ("4.es:q2", "4.es:q3")


@pytest.fixture(scope="module")
def humanoid():
    return load_robot(ROBOTS / "humanoid.yaml")


def _data(robot, **changes):
    spec = read_yaml(ROBOTS / "humanoid.truth.yaml", "truth") | changes
    rng = np.random.default_rng(3)
    return simulate(robot, load_truth(spec, robot), random_design(robot, 300, rng), rng)


def _fit(robot, data, frames=None):
    """A plain least-squares fit of constant errors (and `frames`' terms): the calibrator, the ratio
    coefficients' values and what it said."""
    model = error_model_from_dict({"default": ["1"], "frames": frames or {}}, robot, "<test>")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        cal = gecgen.Calibrator(errors=model, loss="l2", keep_insignificant=True).fit(robot, data)
    names = cal.calibration_.model.coefficient_names(cal.robot_)
    return cal, {n: cal.calibration_.c[names.index(n)] for n in RATIOS}, [str(w.message) for w in said]


@pytest.fixture(scope="module")
def passive(humanoid):
    """Only the passive torso joint is compliant (about its own axis), and no ratio is wrong."""
    spec = read_yaml(ROBOTS / "humanoid.truth.yaml", "truth")
    source = dict(spec["sources"][0], compliance={"es": 1.5e-4})
    data = _data(humanoid, sources=[source])
    return data, _fit(humanoid, data), _fit(humanoid, data, {4: {"es": ["1", "gravity_load(4,my)"]}})


def test_a_ratio_fitted_without_the_load_is_said_to_absorb_it(passive):
    _, (cal, ratios, said), _ = passive
    found = {r["coefficient"]: r for r in cal.calibration_.report["ratio_loads"]}
    assert found, "the constant model's ratios absorb the passive joint's compliance and nothing says so"
    for name, r in found.items():
        assert not r["in_model"] and r["loads"] == ["gravity_load(4,my)"]
        assert r["without_loads"] == pytest.approx(ratios[name], abs=1e-3 * r["std"])  # the fit itself, converged
        # the truth's ratio error is zero: with the load its value is back within noise of it
        assert abs(r["with_loads"]) < 3 * r["std"] < abs(r["without_loads"])
        assert any(name in s and "absorbs load" in s for s in said)
    section = next(s for s in coefficient_section(cal.robot_, cal.calibration_) if s.title == "Coupling ratios and loads")
    assert {row[0] for row in section.blocks[1].rows} == {f"`{n}`" for n in found}


def test_the_shift_equals_the_fits_with_and_without_the_load(passive):
    """The constrained least-squares move, computed on one fit, against the other fit itself."""
    _, (plain, plain_ratios, _), (loaded, loaded_ratios, said) = passive
    without = {r["coefficient"]: r for r in plain.calibration_.report["ratio_loads"]}
    within = {r["coefficient"]: r for r in loaded.calibration_.report["ratio_loads"]}
    assert set(within) == set(without)
    for name in without:
        assert within[name]["in_model"] and "only as good as the load terms" in " ".join(said)
        assert without[name]["with_loads"] == pytest.approx(loaded_ratios[name], abs=0.05 * within[name]["std"])
        assert within[name]["without_loads"] == pytest.approx(plain_ratios[name], abs=0.05 * within[name]["std"])


def test_a_real_ratio_error_on_a_rigid_robot_is_not_flagged(humanoid):
    data = _data(humanoid, sources=[], couplings={"torso_4_joint": "-(1.003*torso_2_joint + torso_3_joint)"})
    cal, ratios, said = _fit(humanoid, data)
    assert cal.calibration_.report["ratio_loads"] == []
    assert not any("coupling ratio" in s for s in said)
    # the torso joint's error es turns against its axis: the ratio error shows with its sign turned
    assert abs(ratios["4.es:q2"]) == pytest.approx(0.003, rel=0.1)


def test_robots_without_couplings_record_nothing():
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    spec = read_yaml(ROBOTS / "industrial6r.truth.yaml", "truth")
    rng = np.random.default_rng(0)
    data = simulate(robot, load_truth(spec, robot), random_design(robot, 40, rng), rng)
    cal = gecgen.Calibrator(errors=error_model_from_dict({"default": ["1"]}, robot, "<t>")).fit(robot, data)
    assert "ratio_loads" not in cal.calibration_.report
