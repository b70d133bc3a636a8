"""Accuracy over a declared volume (`gecgen accuracy`, gecgen/verify/volume.py): the volume file, its
sampling, the rows of a tool-box point, the Monte Carlo bound against a closed form, the unmodelled
error read as a tool motion, and the statement against the true worst error of simulated robots."""
from __future__ import annotations

import dataclasses
import re
import warnings

import numpy as np
import pytest
from conftest import ROBOTS, run_json
from scipy import stats

from gecgen.api import Calibrator
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import tool_pose
from gecgen.model.measurements import write_measurements
from gecgen.model.validation import read_yaml
from gecgen.model.volume import load_volume
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import to_world
from gecgen.verify.volume import (Unmodelled, _placed, accuracy, affine_model, measured, order_statistic,
                                   point_rows, poses_needed, random_poses, sample, state, unmodelled,
                                   worst_over_draws)
from gecgen.simulate import (Design, joined, load_truth, one_at_a_time, paper_data, paper_pps, paper_split, simulate,
                             true_tool_points)

PPS = ROBOTS / "pps.yaml"
VOLUME = ROBOTS / "pps.volume.yaml"
TRACKER, REPEATABILITY = 4e-5, 5e-5  # robots/pps.truth.yaml's noise, m per coordinate




@pytest.fixture(scope="module")
def pps():
    return load_robot(PPS)


@pytest.fixture(scope="module")
def geometric(pps):
    """The PPS with only geometric errors (the truth file's constant errors and joint offsets) on the
    paper's design, calibrated with constant errors: a model that describes the robot."""
    spec = read_yaml(ROBOTS / "pps.truth.yaml", "truth")
    truth = load_truth({**spec, "sources": [], "seed": 7}, pps)
    train, val = paper_data(pps, truth, np.random.default_rng(7))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = Calibrator(ROBOTS / "constant.errors.yaml").fit(pps, train)
    return truth, train, val, cal


@pytest.mark.parametrize("text, says", [
    ("samples: 10\n", "missing key 'angle_unit'"),
    ("angle_unit: deg\njoints: {thetta: [0, 10]}\n", "did you mean 'theta'"),
    ("angle_unit: deg\njoints: {theta: [-100, 10]}\n", "leaves the joint's limits [-90, 90]"),
    ("angle_unit: deg\njoints: {theta: [10, 0]}\n", "swap them"),
    ("angle_unit: deg\nplace_at: isocentre\ntool_box: {min: [0, 0, 0], max: [1, 1, 1]}\n", "did you mean 'isocenter'"),
    ("angle_unit: deg\nplace_at: [0, 0.8, 0.4]\njoints: {theta: 0}\ntool_box: {min: [0, 0, 0], max: [1, 1, 1]}\n",
     "exactly 3 must be left free; 5 are"),
    ("angle_unit: deg\nplace_at: [0, 0.8, 0.4]\n", "give one target, or a tool_box"),
    ("angle_unit: deg\ntargets: [t1]\ntool_box: {min: [0, 0, 0], max: [1, 1, 1]}\n", "not both"),
    ("angle_unit: deg\ntool_box: {min: [0, 0, 1], max: [1, 1, 0]}\n", "min is above max"),
    ("angle_unit: deg\nsamples: 0\n", "samples: expected a whole number"),
    ("angle_unit: deg\npayload_kg: [-5]\n", "payload_kg: expected 1 to 20 masses >= 0 kg"),
])
def test_a_bad_volume_file_is_refused_in_one_line_naming_the_key(pps, tmp_path, text, says):
    path = tmp_path / "v.yaml"
    path.write_text(text)
    with pytest.raises(ModelError) as err:
        load_volume(path, pps)
    message = str(err.value)
    assert says in message and str(path) in message and "\n" not in message


def test_place_at_puts_every_tool_point_at_the_isocenter_within_the_declared_ranges(pps):
    volume = dataclasses.replace(load_volume(VOLUME, pps), samples=200)
    s = sample(pps, volume, np.random.default_rng(3))
    assert s.unreachable == 0 and len(s.q) == 2 * 200  # each configuration with both payloads
    assert np.abs(_placed(pps, s.q, s.point) - np.array(pps.points["isocenter"])).max() < 1e-9
    assert np.abs(np.degrees(s.q[:, 3])).max() <= 90 and not s.q[:, 4:].any()
    lo, hi = volume.tool_box
    assert ((s.point >= lo) & (s.point <= hi)).all()
    assert all(j.lower <= v.min() and v.max() <= j.upper for j, v in zip(pps.joints, s.q.T))


def test_a_tool_box_point_has_the_rows_of_a_target_placed_there(pps):
    """The affine combination of the four basis points' H_e rows is the point's own (independent
    computation: the robot compiled with the point as its target)."""
    model = load_error_model(ROBOTS / "pps.errors.yaml", pps)
    volume = dataclasses.replace(load_volume(VOLUME, pps), samples=5)
    s = sample(pps, volume, np.random.default_rng(4))
    c = np.random.default_rng(5).normal(0, 1e-4, len(model.coefficients))
    kept = list(range(0, len(c), 3))
    G = point_rows(CompiledModel(affine_model(pps, volume), model), s, c, kept)
    k = 3
    alone = dataclasses.replace(pps, targets={"p": tuple(s.point[k])}, estimated=(), target_frames={})
    _, H = CompiledModel(alone, model).model_targets(s.q[k:k + 1], s.w[k:k + 1], None, c, with_H=True)
    assert np.allclose(G[k], H[0][:, kept], rtol=1e-9, atol=1e-12)


def test_the_monte_carlo_worst_of_one_point_is_the_chi_quantile():
    """One sample, its error N(0, sigma^2 I3) from either part: the 95 % bound is sigma times the 95 %
    quantile of a chi law with 3 degrees of freedom."""
    sigma, rng = 2e-4, np.random.default_rng(6)
    expected = sigma * stats.chi(3).ppf(0.95)
    unmodelled_only = worst_over_draws(np.zeros((1, 3, 1)), np.zeros((1, 1)), sigma * np.eye(3)[None], 20000, rng)
    parametric_only = worst_over_draws(np.eye(3)[None], sigma ** 2 * np.eye(3), np.zeros((1, 3, 3)), 20000, rng)
    for worst in (unmodelled_only[0], parametric_only[0]):
        assert np.quantile(worst, 0.95) == pytest.approx(expected, rel=0.03)


def test_the_unmodelled_error_is_read_as_the_tool_motion_the_residuals_show(pps):
    """Residuals made of known random tool motions plus tracker noise and repeatability: the motions'
    covariance comes back at its upper confidence limit; with noise alone, that limit is small."""
    model = load_error_model(ROBOTS / "constant.errors.yaml", pps)
    cm = CompiledModel(pps, model)
    design = paper_pps(pps)
    data = simulate(pps, load_truth({}, pps), design, np.random.default_rng(8))  # the nominal robot, no noise
    rng = np.random.default_rng(9)
    R = tool_pose(pps, data.q)[:, :3, :3][data.pose]
    t = np.array(list(pps.targets.values()))[data.target]
    noise = rng.normal(0, TRACKER, data.xyz.shape) + rng.normal(0, REPEATABILITY, (data.n_poses, 3))[data.pose]
    c = np.zeros(len(model.coefficients))
    tilt = 3e-4  # rad, about the tool's x axis: 0.12 mm at 40 cm, inside the noise at the targets
    quiet = np.sqrt(np.diag(unmodelled(cm, data, data.xyz + noise, c, TRACKER, REPEATABILITY).twist_cov))
    assert (quiet[:3] < REPEATABILITY).all() and (quiet[3:] < tilt / 4).all()
    xi = np.zeros((data.n_poses, 6))
    xi[:, 3] = rng.normal(0, tilt, data.n_poses)
    move = np.einsum("rij,rj->ri", R, xi[data.pose, :3] + np.cross(xi[data.pose, 3:], t))
    seen = unmodelled(cm, data, data.xyz + move + noise, c, TRACKER, REPEATABILITY)
    assert tilt <= np.sqrt(seen.twist_cov[3, 3]) <= 1.25 * tilt
    assert np.sqrt(seen.twist_cov[4, 4]) < tilt / 4 and np.sqrt(seen.twist_cov[5, 5]) < tilt / 4


def test_the_bound_holds_the_true_worst_error_of_a_robot_the_model_describes(pps, geometric):
    """The truth robot commanded to the compensated joints of every sample: its worst true error lies
    within the stated bound. From the training residuals alone the bound is close to it but cannot be
    signed; with the held-out poses (the paper's validation half) the bound is looser, as 56 poses pin
    the unmodelled error's upper limit less tightly, and still not signed: the paper's design never
    moves roll and pitch, which compensation moves at every sample, and 56 poses inside the volume are
    fewer than the 59 a measured statement of 95 % of it at 95 % confidence needs."""
    truth, _, val, cal = geometric
    calib = cal.calibration_
    volume = dataclasses.replace(load_volume(VOLUME, pps), samples=300)
    world = cal.data_, to_world(calib.frames, cal.data_)
    statements = {}
    for label, held_out in (("training", None), ("held out", (val, to_world(calib.frames, val)))):
        samples, statements[label], cm = accuracy(calib, volume, *world, held_out, TRACKER, REPEATABILITY, 0.5,
                                                  0.95, 2000, np.random.default_rng(10))
    q_c, _ = cm.compensate(samples.q, samples.w, None, calib.c)
    true, _ = true_tool_points(pps, truth, q_c, samples.payload_kg, volume.payload_at, samples.point)
    worst = 1e3 * np.linalg.norm(true - samples.world, axis=1).max()
    training, held = statements["training"], statements["held out"]
    assert worst <= training.bound_mm <= 4 * worst and training.verdict == "cannot tell"
    assert worst <= held.bound_mm < 0.5 and held.unmodelled_as == "rigid tool motion"
    assert held.verdict == "cannot tell" and (held.measured.poses, held.measured.outside) == (56, 0)
    said = " ".join(held.reasons)
    assert "per input: q4 (theta) 2, q5 (roll) 600, q6 (pitch) 600 (of 600)" in said and "measure with them moving" in said
    assert "needs at least 59" in said and "measure 3 more held-out poses inside the volume" in said


def test_the_statement_is_signed_with_roll_and_pitch_measured_and_poses_held_out_over_the_volume(pps):
    """The paper's design with roll and pitch swept as well, and 120 held-out poses drawn at random over
    the volume: both statements hold the truth and the verdict is signed. The measured statement's
    share is checked against the truth robot's errors at the samples."""
    spec = read_yaml(ROBOTS / "pps.truth.yaml", "truth")
    truth = load_truth({**spec, "sources": [], "seed": 8}, pps)
    rng = np.random.default_rng(8)
    design = joined(paper_pps(pps), one_at_a_time(pps, {5: np.radians(1.0), 6: np.radians(1.0)}, (0.0, 70.0)))
    train = simulate(pps, truth, design, rng).subset(paper_split(design, rng)[0])
    volume = dataclasses.replace(load_volume(VOLUME, pps), samples=300)
    q, payload = random_poses(pps, volume, 120, rng)
    val = simulate(pps, truth, Design(q, payload, volume.payload_at, ("t1", "t2", "t3"), np.array(["v"] * len(q))),
                   rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = Calibrator(ROBOTS / "constant.errors.yaml").fit(pps, train)
    calib = cal.calibration_
    samples, st, cm = accuracy(calib, volume, cal.data_, to_world(calib.frames, cal.data_),
                               (val, to_world(calib.frames, val)), TRACKER, REPEATABILITY, 0.5, 0.95, 2000,
                               np.random.default_rng(11))
    q_c, _ = cm.compensate(samples.q, samples.w, None, calib.c)
    true, _ = true_tool_points(pps, truth, q_c, samples.payload_kg, volume.payload_at, samples.point)
    err = 1e3 * np.linalg.norm(true - samples.world, axis=1)
    m = st.measured
    assert st.verdict == "meets", st.reasons
    assert m.poses == len(q) and m.outside == 0 and m.rank >= 1 and m.achieved >= 0.95 and m.error_mm <= 0.5
    assert err.max() <= st.bound_mm and np.mean(err <= m.error_mm) >= m.share
    assert any(r.startswith("measured, without a model: 95% of the volume within") for r in st.reasons)


def test_the_order_statistic_against_hand_computation_and_simulation():
    """With n poses the largest error bounds the p-quantile with confidence 1 - p^n: 59 poses for 95 %
    at 95 %. With 100 poses the 2nd largest does (1 - p^100 - 100 p^99 (1 - p) = 0.963), the 3rd does
    not (0.882). Drawn many times, the 2nd largest of 100 passes the 95 % quantile that often."""
    assert poses_needed(0.95, 0.95) == 59 and 1 - 0.95 ** 58 < 0.95 <= 1 - 0.95 ** 59
    assert poses_needed(0.9, 0.99) == 44 and 1 - 0.9 ** 43 < 0.99 <= 1 - 0.9 ** 44
    errors = np.random.default_rng(12).uniform(0, 1, 100)
    k, error, achieved = order_statistic(errors, 0.95, 0.95)
    assert k == 2 and error == np.sort(errors)[-2]
    assert achieved == pytest.approx(1 - 0.95 ** 100 - 100 * 0.95 ** 99 * 0.05, rel=1e-12)
    assert 1 - 0.95 ** 100 - 100 * 0.95 ** 99 * 0.05 - 4950 * 0.95 ** 98 * 0.05 ** 2 < 0.95  # the 3rd: not enough
    assert order_statistic(errors[:58], 0.95, 0.95) is None
    draws = np.sort(np.random.default_rng(13).uniform(0, 1, (20000, 100)), axis=1)[:, -2]
    assert np.mean(draws >= 0.95) == pytest.approx(achieved, abs=0.01)


def _statement(held=None, blocks=(), doubts=(), scale=1e-4, tolerance=0.5):
    """A statement over 50 samples whose error is the coefficients' alone (sigma `scale` m per
    coordinate), or, with scale 0, an unmodelled error of 0.1 mm at sample 3 only."""
    N, rng = 50, np.random.default_rng(14)
    G = np.tile(np.eye(3), (N, 1, 1)) if scale else np.zeros((N, 3, 3))
    U = np.zeros((N, 3, 3))
    if not scale:
        U[3] = 1e-4 * np.eye(3)
    unmod = Unmodelled(0.0, 0.0, None)
    return state(G, scale ** 2 * np.eye(3), U, unmod, 4e-5, tolerance, 0.95, 1000, rng, list(blocks), list(doubts),
                 [], held)


def test_the_verdict_never_contradicts_its_reasons():
    """A statement the measured poses cannot support is "cannot tell" with the poses it needs; one
    whose covariance cannot be trusted is "cannot tell" even where the coefficients' uncertainty alone
    would fail the tolerance, and "does not meet" says why."""
    few = measured(np.full(20, 0.1), 3, 0.95, 0.95)
    st = _statement(few)
    assert st.verdict == "cannot tell" and few.rank is None and few.needed == 59
    assert any("20 held-out poses lie inside the volume (3 outside it)" in r and "needs at least 59" in r
               and "measure 39 more" in r for r in st.reasons)
    assert _statement(measured(np.full(59, 0.1), 0, 0.95, 0.95)).verdict == "meets"
    over = _statement(measured(np.r_[np.full(58, 0.1), 0.7], 0, 0.95, 0.95))
    assert over.verdict == "cannot tell" and any("0.7 mm, above the tolerance" in r for r in over.reasons)
    assert _statement(measured(np.full(59, 0.1), 0, 0.95, 0.95), doubts=["out of range"]).verdict == "cannot tell"
    # the coefficients alone put the worst past 0.5 mm: failure, unless the covariance is in doubt
    big = _statement(scale=1e-3)
    assert big.verdict == "does not meet" and big.lower_mm > 0.5
    assert any(r.startswith("the coefficients' uncertainty alone puts the worst error above the tolerance")
               for r in big.reasons)
    blocked = _statement(scale=1e-3, blocks=["10 poses for 12 coefficients: the covariance ... needs at least 24"])
    assert blocked.verdict == "cannot tell" and blocked.reasons[0].startswith("10 poses for 12 coefficients")
    # between the two quantiles: the bound above the tolerance is said (0.1 mm per coordinate: its 95 % chi
    # quantile 0.28 mm, its 5 % 0.035 mm)
    between = _statement(measured(np.full(59, 0.1), 0, 0.95, 0.95), tolerance=0.2)
    assert between.lower_mm < 0.2 < between.bound_mm and between.verdict == "cannot tell"
    assert any(r.startswith(f"the bound, {between.bound_mm:.3g} mm at 95%, is above the tolerance")
               for r in between.reasons)


def test_where_it_is_worst_is_where_the_bound_is_reached():
    """One sample carries all the unmodelled error: the bound is reached there in every draw."""
    st = _statement(scale=0.0)
    assert st.worst == 3 and st.worst_share == 1.0 and st.per_point_mm[3] == st.per_point_mm.max()


def test_accuracy_from_the_command_line(pps, geometric, tmp_path):
    _, train, val, cal = geometric
    cal.save(tmp_path / "c.json")
    write_measurements(tmp_path / "train.csv", pps, train)
    volume = tmp_path / "v.yaml"
    volume.write_text(VOLUME.read_text().replace("samples: 1000", "samples: 100"))
    out = run_json("accuracy", tmp_path / "c.json", volume, tmp_path / "train.csv", "--tolerance-mm", "0.01",
               "--noise-mm", "0.04", "--repeatability-mm", "0.05", "--draws", "500", "--plot", tmp_path / "map.png",
               "--report", tmp_path / "report")
    assert out["verdict"] == "does not meet" and out["lower_mm"] > 0.01
    assert out["samples"] == 200 and out["unreachable"] == 0 and out["held_out"] is False
    assert (tmp_path / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = (tmp_path / "report" / "report.md").read_text()
    assert f"{out['bound_mm']:.3g} mm at 95%" in text and "does not meet" in text and "Where it is worst" in text
    assert (tmp_path / "report" / "report.html").stat().st_size > 0
    # it opens with the verdict and a next step: where the bound is largest, or what the model misses
    assert text.index("## Verdict and next step") < text.index("## Statement")
    assert "**Verdict: does not meet.**" in text and "**Next step:** Measure poses where the bound is largest" in text
    assert out["next_step"] in text and re.findall(r"^- (.*)$", text[text.index("## Warnings"):
                                                               text.index("## Statement")], re.M) == out["warnings"]
    assert -90 <= out["worst_at"]["joints"]["theta"] <= 90 and len(out["worst_at"]["tool_point_m"]) == 3
    assert 0 < out["worst_at"]["worst_in_draws"] <= 1 and out["worst_at"]["bound_mm"] <= out["bound_mm"]
    assert f"the bound, {out['bound_mm']:.3g} mm, is the 95% quantile" in out["worst_at"]["explanation"]
    assert out["measured"] is None and out["reasons"][0].startswith("the coefficients' uncertainty alone")
    bare = run_json("accuracy", tmp_path / "c.json", volume, tmp_path / "train.csv", "--tolerance-mm", "0.5",
                "--draws", "500")
    assert bare["noise_mm"] is None and any("no measurement noise stated" in r for r in bare["reasons"])
    assert bare["bound_mm"] > out["bound_mm"]  # the whole residual counted as unmodelled error
    # training residuals alone cannot sign it
    assert bare["verdict"] == "cannot tell" and any("give them as --val" in r for r in bare["reasons"])
    assert "--noise-mm S --repeatability-mm R" in bare["next_step"]  # first, the noise it counted as error
    write_measurements(tmp_path / "val.csv", pps, val)
    held = run_json("accuracy", tmp_path / "c.json", volume, tmp_path / "train.csv", "--val", tmp_path / "val.csv",
                    "--tolerance-mm", "0.5", "--noise-mm", "0.04", "--repeatability-mm", "0.05", "--share", "0.9",
                    "--draws", "500")
    m = held["measured"]  # 90 % of the volume at 95 %: 29 poses at least (0.9^29 = 0.047), 56 given
    assert (m["n"], m["outside"], m["needed"], m["share"]) == (56, 0, 29, 0.9)
    assert m["achieved_confidence"] >= 0.95 > stats.binom.cdf(56 - m["rank"] - 1, 56, 0.9)
    assert m["error_mm"] <= m["largest_error_mm"] and held["verdict"] == "cannot tell"  # roll and pitch: not trained
    # so the next step is to train over them, and the command it names keeps the options the statement rests on
    assert held["next_step"].startswith("Measure training poses that move the inputs named under")
    assert f"`gecgen accuracy NEW_CALIB.json {volume} NEW_DATA.csv --noise-mm 0.04 --repeatability-mm 0.05 --share " \
           f"0.9 --tolerance-mm 0.5`" in held["next_step"]
    with pytest.raises(ModelError, match="not the data the calibration was fitted to"):
        accuracy(cal.calibration_, load_volume(volume, pps), val, to_world(cal.calibration_.frames, val), None, None,
                 0.0, 0.5, 0.95, 500, np.random.default_rng(0))
