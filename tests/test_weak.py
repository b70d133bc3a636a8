"""Weakly determined directions (gecgen/fit/weak.py): what the data and the noise cannot hold is
found, held and named, and the fit converges on what they determine.

The measurement designs are those that leave such directions (gecgen/simulate/designs.py): a laser
tracker measuring one reflector while the tool keeps its orientation (a grid in space, or a plane),
a joint that barely moves, sockets without a known distance; and a tool that turns by only a few
mrad, which places its target weakly (gecgen/fit/placement.py).
"""
from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import run_json
from scipy.spatial.transform import Rotation

from gecgen import api
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.validation import read_yaml
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import _fit_failures, absurd_error, identify
from gecgen.fit.inputs import placed
from gecgen.fit.registration import register
from gecgen.fit.weak import PLAUSIBLE_M, PLAUSIBLE_RAD, tool_turn
from gecgen.simulate import load_truth, simulate
from gecgen.simulate.designs import constant_orientation
from gecgen.simulate.fixtures import Fixtures, simulate_fixtures

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = ROOT / "robots"
#: industrial6r's home for a tool grid: the flange 2.2 m ahead, pointing down, the wrist bent 50 degrees
HOME_DEG = (0, -80, -60, 0, 50, 0)
SPACING_M = 0.15


def truth_of(name: str):
    robot = load_robot(ROBOTS / f"{name}.yaml")
    return robot, load_truth(read_yaml(ROBOTS / f"{name}.truth.yaml", "truth"), robot, f"{name}.truth.yaml")


def floor_mm(truth) -> float:
    """What repeatability and tracker noise alone leave of a held-out point's error (mm rms)."""
    return 1e3 * float(np.sqrt(3 * (truth.repeatability ** 2 + truth.tracker ** 2)))


@pytest.fixture(scope="module")
def grid():
    """industrial6r measured at its reflector over a 6 x 6 x 6 grid (those in reach) with the tool's
    orientation constant, and validated on the 5 x 5 x 5 grid between those points."""
    robot, truth = truth_of("industrial6r")
    rng = np.random.default_rng(0)
    home = np.radians(HOME_DEG)
    train = simulate(robot, truth, constant_orientation(robot, home, SPACING_M), rng)
    val = simulate(robot, truth, constant_orientation(robot, home, SPACING_M, (5, 5, 5), shift=(SPACING_M / 2,) * 3),
                   rng)
    return robot, truth, train, val


def test_the_design_keeps_the_tool_orientation(grid):
    robot, _, train, _ = grid
    assert train.n_poses > 100
    assert tool_turn(robot, train.q) < 1e-8


def test_a_constant_orientation_grid_converges_with_the_tool_turn_named(grid):
    """The default path once refused this ("Gauss-Newton did not converge in 30 iterations"): now the
    weakly determined coefficients are held and named, the held-out points reach the noise floor,
    and no generalized error is beyond a plausible size: twice the 1-sigma that makes a direction
    weak, as a kept coefficient also takes up what the held ones merge into (a base translation a
    wrist rotation's lever arm times it), which can be larger than any one error of the truth."""
    robot, truth, train, val = grid
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        cal = api.Calibrator().fit(robot, train)
    held = cal.report_["held"]
    assert held and all("the tool never turns" in h["reason"] for h in held)
    assert {h["param"] for h in held} <= {e["param"] for e in cal.report_["eliminated"] if e["reason"] == "held"}
    told = {str(w.message) for w in said if "tool never turns" in str(w.message)}
    assert len(told) == 1 and next(iter(told)).startswith("not determined, held at zero: ")  # one line, one cause
    assert all(h["param"] in next(iter(told)) for h in held)
    assert cal.report_["converged"]
    assert cal.score(val).after.rms_mm <= 1.1 * floor_mm(truth)
    eps = np.abs(cal.cm_.eps(train.q, train.w, train.aux_columns(()), cal.fit_.c))
    assert eps.reshape(len(eps), -1, 6)[..., :3].max() < 2 * PLAUSIBLE_M
    assert eps.reshape(len(eps), -1, 6)[..., 3:].max() < 2 * PLAUSIBLE_RAD


def test_without_holding_the_same_fit_does_not_converge(grid):
    """What the holding prevents: the check above can fail."""
    robot, _, train, _ = grid
    cm = CompiledModel(robot, load_error_model(ROBOTS / "industrial6r.errors.yaml", robot))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loose = identify(cm, train, hold_weak=False)
        held = identify(cm, train)
    assert not loose.trustworthy and not loose.held
    assert held.trustworthy and held.held and held.iterations < 10


def test_a_refusal_says_that_no_determined_subspace_lets_the_fit_stand(grid):
    """Data no subspace of the model explains (the world mirrored: no robot and registration give
    it) are refused, and the refusal says that holding the weakly determined directions was tried,
    how many, and why that fit fails too."""
    robot, _, train, _ = grid
    cm = CompiledModel(robot, load_error_model(ROBOTS / "industrial6r.errors.yaml", robot))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mirrored = identify(cm, replace(train, xyz=train.xyz * [1, -1, 1]))
    assert not mirrored.trustworthy
    said = [f for f in mirrored.failures if "no subspace the data determine lets the fit stand" in f]
    assert len(said) == 1 and "weakly determined coefficients held (" in said[0] and "the fit still fails" in said[0]
    assert any("robot file" in f for f in mirrored.failures)


def test_a_stated_noise_decides_what_is_held(grid):
    """The test is against the noise: a noise a hundred times the tracker's holds more."""
    robot, truth, train, _ = grid
    cm = CompiledModel(robot, load_error_model(ROBOTS / "industrial6r.errors.yaml", robot))
    noise = float(np.hypot(truth.repeatability, truth.tracker))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stated = identify(cm, train, noise_m=noise)
        noisy = identify(cm, train, noise_m=100 * noise)
    assert stated.trustworthy and len(noisy.held) > len(stated.held)


def test_a_fit_that_stands_with_an_implausible_value_holds_its_weak_directions():
    """The Panda on a constant-orientation grid converges with every coefficient fitted, a wrist
    rotation at 30 mrad and more (seed 0); with the noise stated, the directions that carry it are held
    at a cost the noise explains and every value is plausible, the held-out points no further from the
    floor. Without the noise stated the fit stands as it is (a residual holds what the model misses)."""
    robot, truth = truth_of("panda")
    home = np.array([0, -0.3, 0, -2.2, 0, 2.0, 0.8])
    rng = np.random.default_rng(0)
    train = simulate(robot, truth, constant_orientation(robot, home, 0.05, targets=("m1",)), rng)
    val = simulate(robot, truth, constant_orientation(robot, home, 0.05, (5, 5, 5), ("m1",), shift=(0.025,) * 3), rng)
    noise = float(np.hypot(truth.repeatability, truth.tracker))
    cm = CompiledModel(robot, load_error_model(None, robot))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        loose = identify(cm, train)
        held = identify(cm, train, noise_m=noise)

    def largest(fit):
        eps = np.abs(cm.eps(train.q, train.w, train.aux_columns(()), fit.c)).reshape(train.n_poses, -1, 6)
        return max(eps[..., :3].max() / PLAUSIBLE_M, eps[..., 3:].max() / PLAUSIBLE_RAD)

    assert loose.trustworthy and not loose.held and largest(loose) > 5
    assert held.trustworthy and held.held and largest(held) <= 1
    assert any("times a plausible size" in str(w.message) and "within the noise" in str(w.message) for w in said)

    def held_out_mm(fit):
        p = cm.model_targets(val.q, val.w, val.aux_columns(()), fit.c)
        return 1e3 * np.sqrt(np.mean(np.sum((fit.to_world(val) - p[val.pose, val.target]) ** 2, axis=1)))

    assert held_out_mm(held) <= 1.02 * held_out_mm(loose)


def test_a_planar_grid_converges_with_what_it_holds_named():
    robot, truth = truth_of("industrial6r")
    rng = np.random.default_rng(1)
    design = constant_orientation(robot, np.radians(HOME_DEG), SPACING_M, (8, 8, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = api.Calibrator().fit(robot, simulate(robot, truth, design, rng))
    assert cal.report_["converged"] and cal.report_["held"]
    assert all("the tool never turns" in h["reason"] for h in cal.report_["held"])


def test_a_joint_that_barely_moves_is_named(tmp_path):
    """`gecgen simulate --design barely-moving`: joint 4 within 1 mrad. identify converges, its
    errors that no other joint's motion tells apart are held, the reason naming the joint; the rest
    of the arm is fitted."""
    robot = ROBOTS / "industrial6r.yaml"
    data = tmp_path / "barely.csv"
    made = run_json("simulate", robot, "--design", "barely-moving", "--joint", 4, "--poses", 150, "--seed", 2,
                    "-o", data)
    q = pd.read_csv(data)["q4"]
    assert made["design"] == "barely-moving" and 0 < np.ptp(q) <= 1e-3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = run_json("identify", robot, data, "-o", tmp_path / "calib")
    assert fit["converged"] and fit["held"]
    assert all("joint 4 (a4) barely moves" in h["reason"] for h in fit["held"])
    assert {h["param"] for h in fit["held"]} <= {e["param"] for e in fit["eliminated"] if e["reason"] == "held"}


def test_sockets_without_a_distance_hold_the_scale_and_converge():
    """A ball in the sockets of three plate placements, the distance not declared: the scale's carrier
    is named as held, the fit converges, and the held-out consistency is within 1.1 times the fit's
    with the distance given."""
    robot = load_robot(ROBOTS / "panda_ball.yaml")
    truth = load_truth(read_yaml(ROBOTS / "panda.truth.yaml", "truth"), robot, "panda.truth.yaml")
    rng = np.random.default_rng(0)
    fixtures = Fixtures("ball", plates=3)
    measured, _ = simulate_fixtures(robot, truth, fixtures, rng)
    val, _ = simulate_fixtures(robot, truth, fixtures, rng)
    # the same seats without the distance declared (solving the configurations is what takes time)
    unknown = replace(measured, relative=replace(measured.relative, distances=()))
    out = {}
    for known, train in ((True, measured), (False, unknown)):
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            cal = api.Calibrator().fit(robot, train)
        out[known] = cal, cal.score(val).after.consistency_mm, said
    cal, consistency, said = out[False]
    assert [h["param"] for h in cal.report_["held"]] == ["6.ex:1"]
    assert "the scale is not determined" in cal.report_["held"][0]["reason"]
    assert any("the scale is not determined" in str(w.message) for w in said)
    assert not any("scale" in h["reason"] for h in out[True][0].report_["held"])
    assert consistency <= 1.1 * out[True][1]


def test_a_placement_the_data_barely_support_is_held():
    """The tool's orientation off its hold by 0.5 mrad per axis: the nominal tool turns so little
    that the placement would move the given reflector by about 90 mm (what the robot's own errors
    push along the weak direction); it is held where the robot file puts it, and said so. With a
    larger turn (2 mrad) the placement moves it less than the hold limit, and it stands."""
    robot, truth = truth_of("industrial6r")
    found = {}
    for wobble in (5e-4, 2e-3):
        rng = np.random.default_rng(0)
        design = constant_orientation(robot, np.radians(HOME_DEG), SPACING_M, wobble_rad=wobble, rng=rng)
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            found[wobble] = placed(robot, simulate(robot, truth, design, rng)), said
    (fitted, placement), said = found[5e-4]
    assert fitted.targets == robot.targets
    assert "further than they support" in placement.to_dict()["held"]["smr"]
    assert any("held where the robot file puts it" in str(w.message) for w in said)
    (fitted, placement), _ = found[2e-3]
    assert not placement.held and fitted.targets["smr"] != robot.targets["smr"]


def test_a_registration_the_data_barely_support_is_held():
    """Points on two lines 22 mm apart, in the robot's world shifted 30 mm along them and turned 0.1
    rad about them, with 2 mm of the robot's own errors: the turn about the lines is known only to
    about 60 mm at the workspace, so the fitted frame's turn (over 100 mm there) is held at the world
    frame, said and reported; the shift, which the points determine, is applied. The same turn of a
    grid spread in space is fitted."""
    rng = np.random.default_rng(0)
    x = np.linspace(0.6, 1.6, 10)
    lines = np.concatenate([np.c_[x, np.full(10, s), np.ones(10)] for s in (0.011, -0.011)])
    grid = np.stack(np.meshgrid(np.linspace(0.6, 1.6, 5), np.linspace(-0.5, 0.5, 5), np.linspace(0.5, 1.5, 3)),
                    -1).reshape(-1, 3)
    turn = Rotation.from_rotvec([0.1, 0, 0]).as_matrix()

    def measured(p):
        return (p - p.mean(0)) @ turn.T + p.mean(0) + [0.03, 0, 0] + rng.normal(0, 0.002, p.shape)

    y = measured(lines)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        frame = register(lines, y, "auto")
    free = register(lines, y, "always")
    assert np.linalg.norm(Rotation.from_matrix(free.R).as_rotvec()) > 0.03  # what the data alone would do
    assert frame.applied and len(frame.held) == 1 and "rotation about (1.00" in frame.held[0].replace("-1.00", "1.00")
    assert "further than the data support" in frame.to_dict()["held"][0]
    assert any("registration: the rotation about" in str(w.message) for w in said)
    assert abs(Rotation.from_matrix(frame.R).as_rotvec()[0]) < 1e-3
    assert np.allclose(frame.R @ lines.mean(0) + frame.t - lines.mean(0), [0.03, 0, 0], atol=2e-3)
    spread = register(grid, measured(grid), "auto")
    assert not spread.held and abs(Rotation.from_matrix(spread.R).as_rotvec()[0] - 0.1) < 5e-3


def test_an_absurd_value_blames_the_robot_file_only_when_determined():
    """The message says the robot file does not describe the robot only when the absurd error's
    coefficients are determined (|value| over two std); else it names the data."""
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    cm = CompiledModel(robot, load_error_model(ROBOTS / "constant.errors.yaml", robot))
    names = cm.model.coefficient_names(robot)
    j = names.index("6.er:1")
    c = np.zeros(cm.dims.nc)
    c[j] = 0.9
    q = np.zeros((3, robot.n))
    data = replace(simulate(robot, load_truth({}, robot, "none"),
                            constant_orientation(robot, np.radians(HOME_DEG), SPACING_M, (3, 1, 1)),
                            np.random.default_rng(0)))
    assert absurd_error(cm, q, None, None, c)
    kept = np.arange(cm.dims.nc)
    undetermined = _fit_failures(cm, data, c, np.full(cm.dims.nc, 1.0), kept, True, "")
    determined = _fit_failures(cm, data, c, np.full(cm.dims.nc, 0.01), kept, True, "")
    assert "robot file" not in undetermined[0] and "the data do not determine" in undetermined[0]
    assert "robot file" in determined[0]


def test_the_verdict_names_why_the_data_leave_coefficients_weak(grid, tmp_path):
    """identify's verdict says what limits it in the data's own terms: the tool that never turns,
    once for every coefficient it holds, and the next steps include its fix."""
    from gecgen.model.measurements import write_measurements

    robot, _, train, _ = grid
    write_measurements(tmp_path / "grid.csv", robot, train, wrench=False)
    out = run_json("identify", ROBOTS / "industrial6r.yaml", tmp_path / "grid.csv", "--noise-mm", "0.05", "-o",
                   tmp_path / "c.json")
    turned = [line for line in out["assessment"]["limits"] if "the tool never turns" in line]
    assert len(turned) == 1 and turned[0].startswith(f"{len(out['held'])} coefficients are held at zero"), turned
    assert "measure poses that turn the tool, or a second target" in out["assessment"]["next_step"]


def test_coefficients_held_for_their_plausible_size_are_said_together():
    """Each such coefficient's reason states its own times a plausible size: the verdict says them in
    one line with their range, and their fix once."""
    from gecgen.report.verdict import Commands, assess

    why = ("the data determine its direction only to {} times a plausible size (1-sigma against 5 mm, 5 mrad); "
           "held at zero (measure poses that move it)")
    weak = [{"param": p, "beyond_plausible": b, "reason": why.format(b)} for p, b in (("1.ex:1", 1.5), ("2.ey:1", 3.25))]
    said = assess(after={"rms_mm": 0.1, "max_mm": 0.2}, before=None, held_out=False, n_poses=50, tolerance_mm=None,
                  noise=None, held=None, n_train_poses=50, extrapolation={}, inside=None, relative=False,
                  commands=Commands("d", "m", "s", "e"), weak=weak)
    lines = [line for line in said.limits if "plausible size" in line]
    assert lines == ["2 coefficients are held at zero as the data determine them too weakly: their directions are "
                     "known only to 1.5 to 3.25 times a plausible size."]
    assert said.next_step.count("measure poses that move it") == 1
