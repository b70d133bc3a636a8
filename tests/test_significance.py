"""Significance: backward elimination on the fitted covariance equals refitting without each
dropped coefficient (plain least squares, checked by brute force), and a calibration carries only
what the data determine."""
import json

import numpy as np
import pytest

from gecgen.model import ModelError
from gecgen.fit import significance


def brute_force(A, b):
    """Backward elimination by refitting least squares without each dropped column."""
    active, dropped = list(range(A.shape[1])), {}
    while active:
        x, *_ = np.linalg.lstsq(A[:, active], b, rcond=None)
        s2 = np.sum((b - A[:, active] @ x) ** 2) / (len(b) - len(active))
        t = np.abs(x) / np.sqrt(s2 * np.diag(np.linalg.inv(A[:, active].T @ A[:, active])))
        j = int(np.argmin(t))
        if t[j] >= significance.T_MIN:
            break
        dropped[active.pop(j)] = float(t[j])
    return dropped


@pytest.mark.parametrize("seed", range(4))
def test_elimination_on_the_covariance_is_refitting_without_the_dropped(seed):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(60, 8))
    A[:, 5] = A[:, 4] + 0.1 * rng.normal(size=60)  # two correlated columns: one survives for both
    truth = np.array([1.0, 0.0, 0.5, 0.0, 0.3, 0.3, 0.0, 2.0])
    b = A @ truth + 0.3 * rng.normal(size=60)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    sigma = np.sqrt(np.sum((b - A @ x) ** 2) / (60 - 8))
    cov = sigma ** 2 * np.linalg.inv(A.T @ A)
    got = significance.backward_elimination(x, cov, sigma, 60 - 8)
    want = brute_force(A, b)
    assert list(got) == list(want)
    assert np.allclose(list(got.values()), list(want.values()), rtol=1e-9)
    assert got  # the zeros of the truth are found insignificant


def test_the_verdict_names_what_is_held_and_counts_per_frame():
    names = ["0.ex:1", "0.ey:1", "1.ez:1", "1.ez:q1"]
    c = np.array([1e-3, 1e-6, 2e-3, 5e-7])
    std = np.array([1e-5, 1e-5, 1e-5, 1e-5])
    verdict, hold = significance.judge(names, c, std, [0, 1, 2, 3], np.diag(std ** 2), 1e-5, 100.0)
    assert sorted(hold) == [1, 3] and "held at zero" in hold[1]
    assert [h["param"] for h in verdict["held"]] == ["1.ez:q1", "0.ey:1"]  # least significant first
    assert verdict["n_determined"] == 2
    assert verdict["frames"] == {"0": {"determined": 1, "held": 1}, "1": {"determined": 1, "held": 1}}


def test_the_held_out_interval_resamples_poses_and_covers_the_rms():
    """By pose: four rows of one pose count as one draw, so the interval of 5 poses with 4 rows each
    is that of the 5 poses' own RMS, and it brackets the RMS; one pose repeated gives no spread."""
    rng = np.random.default_rng(1)
    per_pose = rng.uniform(0.5, 3.0, 5) * 1e-3
    errors, pose = np.repeat(per_pose, 4), np.repeat(np.arange(5), 4)
    lo, hi = significance.rms_interval(errors, pose)
    assert lo < np.sqrt(np.mean(errors ** 2)) < hi
    assert (lo, hi) == significance.rms_interval(per_pose, np.arange(5))  # rows of a pose do not add draws
    assert significance.rms_interval(np.full(4, 2e-3), np.zeros(4, int)) == pytest.approx((2e-3, 2e-3))


def test_the_residual_is_judged_against_the_stated_noise():
    """`overall` against scipy's chi-square law, and through identify on industrial6r (noise 3e-5 m
    repeatability and tracker: 0.042 mm per coordinate): with only geometric errors, constant errors
    leave that noise and no more; with its truth's elastic and other effects, the default model
    leaves more, reported with a warning."""
    import warnings

    from scipy import stats

    from gecgen.api import Calibrator
    from gecgen.model import load_robot
    from gecgen.model.validation import read_yaml
    from gecgen.simulate import load_truth, random_design, simulate

    o = significance.overall(2e-5, 300, 1.5e-5)
    assert o["p_value"] == pytest.approx(stats.chi2.sf(300 * (2 / 1.5) ** 2, 300), rel=1e-9)
    assert o["beyond_noise"] and o["unexplained_mm"] == pytest.approx(1e3 * np.sqrt(2e-5 ** 2 - 1.5e-5 ** 2))
    robot = load_robot("robots/industrial6r.yaml")
    spec = read_yaml("robots/industrial6r.truth.yaml", "truth")
    noise_mm = 1e3 * np.hypot(spec["noise"]["repeatability"], spec["noise"]["tracker"])
    design = random_design(robot, 120, np.random.default_rng(3))
    geometric = simulate(robot, load_truth({**spec, "sources": []}, robot), design, np.random.default_rng(4))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fair = Calibrator("robots/constant.errors.yaml", noise_mm=noise_mm).fit(robot, geometric)
    fair = fair.report_["significance"]["overall"]
    assert not fair["beyond_noise"] and 0.8 < fair["ratio"] < 1.2
    full = simulate(robot, load_truth(spec, robot), design, np.random.default_rng(4))
    with pytest.warns(UserWarning, match="the model misses about"):
        low = Calibrator(noise_mm=noise_mm).fit(robot, full).report_["significance"]["overall"]
    assert low["beyond_noise"] and low["unexplained_mm"] > 0.1
    with pytest.raises(ModelError, match="noise_mm"):
        Calibrator(noise_mm=-1)


def test_the_refit_begins_from_the_fits_own_analysis_and_finds_the_same():
    """The refit without the insignificant coefficients starts from the first fit's data analysis
    (Fit.analysis) rather than computing it again: the same coefficients to the last bit as a refit
    from scratch; an analysis at another rank tolerance, or of other data, is not taken."""
    import warnings

    from gecgen.model import load_robot
    from gecgen.symbolic.terms import load_error_model
    from gecgen.runtime.compiled import CompiledModel
    from gecgen.fit.identify import identify
    from gecgen.model.validation import read_yaml
    from gecgen.simulate import load_truth, random_design, simulate

    robot = load_robot("robots/industrial6r.yaml")
    truth = load_truth(read_yaml("robots/industrial6r.truth.yaml", "truth"), robot)
    data = simulate(robot, truth, random_design(robot, 60, np.random.default_rng(5)), np.random.default_rng(6))
    cm = CompiledModel(robot, load_error_model("robots/industrial6r.errors.yaml", robot))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = identify(cm, data)
        _, hold = significance.judge(cm.model.coefficient_names(robot), fit.c, fit.std, fit.redundancy.kept,
                                     fit.cov, fit.sigma_m, fit.measured_dof)
        assert hold  # the case the reuse is for
        again = identify(cm, data, hold=hold, analysis=fit.analysis)
        fresh = identify(cm, data, hold=hold)
    assert np.array_equal(again.c, fresh.c) and np.array_equal(again.std, fresh.std, equal_nan=True)
    assert again.redundancy == fresh.redundancy
    assert again.analysis is fit.analysis and fresh.analysis is not fit.analysis  # taken, not recomputed
    a = fit.analysis
    assert a.serves(cm, a.y, a.rank_tol) and not a.serves(cm, a.y, 1e-3) and not a.serves(cm, a.y[:-1], a.rank_tol)
    other = CompiledModel(robot, load_error_model("robots/constant.errors.yaml", robot))
    assert not a.serves(other, a.y, a.rank_tol)  # another model's analysis of the same data


def test_a_variance_that_is_not_positive_determines_nothing():
    """A singular or numerically broken covariance (a negative or NaN variance) never stops the gate:
    those coefficients are dropped first, the others judged as before."""
    x = np.array([1.0, 1e-3, 5.0])
    cov = np.diag([0.01, -1e-6, 0.01])
    assert list(significance.backward_elimination(x, cov, 1.0, 10.0)) == [1]
    cov[1, 1] = np.nan
    assert list(significance.backward_elimination(x, cov, 1.0, 10.0)) == [1]


def test_a_barely_moving_joint_leaves_no_coefficient_the_data_do_not_determine(tmp_path):
    """Joint 4 barely moves (1 mrad) and the default model has terms in it: its covariance from the
    squared normal equations lost every digit (condition 1e9) and stopped the gate silently; from R
    every kept coefficient is determined (|value| / std >= 2)."""
    from conftest import ROBOTS, run_json

    run_json("simulate", ROBOTS / "industrial6r.yaml", "--design", "barely-moving", "--joint", "4", "--poses", "120",
             "--seed", "1", "-o", tmp_path / "train.csv")
    fit = run_json("identify", ROBOTS / "industrial6r.yaml", tmp_path / "train.csv", "-o", tmp_path / "cal.json")
    calib = json.loads((tmp_path / "cal.json").read_text())
    kept = [c for c in calib["coefficients"] if c["identified"]]
    assert fit["significance"]["n_determined"] == len(kept) < fit["n_identifiable"]
    assert all(abs(c["value"]) >= 2 * c["std"] for c in kept), [c for c in kept if abs(c["value"]) < 2 * c["std"]]
