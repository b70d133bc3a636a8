"""gecgen design: D- and I-optimal choice of the poses to measure (gecgen/plan/design.py)."""
import csv
import json
import warnings

import numpy as np
import pytest
from conftest import ROBOTS
from test_cli import gecgen

from gecgen.cli import main
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.measurements import read_measurements, write_measurements
from gecgen.plan import design as D
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import identify, position_errors, rows_H_and_residual
from gecgen.simulate import load_truth, random_design, simulate

CONTRACT_KEYS = {"n_poses", "criterion", "value", "random_value"}


def _model(name, errors="constant"):
    robot = load_robot(ROBOTS / f"{name}.yaml")
    return robot, CompiledModel(robot, load_error_model(ROBOTS / f"{errors}.errors.yaml", robot))


def _read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_cli_poses_within_limits_and_constraints(tmp_path):
    """The written poses are joints within the limits that satisfy the constraints, and the
    constraints really removed candidates (else this would test nothing)."""
    out = tmp_path / "poses.csv"
    tracker = (3.0, 0.0, 1.0)
    run = gecgen("design", ROBOTS / "industrial6r.yaml", "--errors", ROBOTS / "constant.errors.yaml", "--poses", 12,
                 "--candidates", 600, "--min-z", 0.5, "--tracker", ",".join(map(str, tracker)),
                 "--max-incidence-deg", 60, "-o", out, "--json")
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    assert CONTRACT_KEYS <= set(result) and result["criterion"] == "D" and result["n_poses"] == 12
    assert result["n_candidates"] < result["n_sampled"] == 600
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    rows = _read(out)
    assert list(rows[0]) == ["pose"] + [f"q{i + 1}" for i in range(6)] and len(rows) == 12
    q = np.array([[float(r[f"q{i + 1}"]) for i in range(6)] for r in rows])
    assert np.all(q >= [j.lower for j in robot.joints]) and np.all(q <= [j.upper for j in robot.joints])
    cands = D.Candidates(q, np.zeros((12, 6)), np.zeros((12, 0)))
    assert D.constraint_mask(robot, cands, np.array([0]), 0.5, tracker, 60).all()
    for prefix in ("", "random_"):
        assert {f"{prefix}O1", f"{prefix}O2", f"{prefix}O3"} <= set(result["observability"])
        assert result["predicted_std"][f"{prefix}rms_mm"] <= result["predicted_std"][f"{prefix}max_mm"]


def test_design_beats_random_and_exchange_never_lowers():
    robot, cm = _model("pps")
    cands = D.uniform_candidates(robot, 400, np.random.default_rng(3))
    d = D.design_poses(cm, cands, 10, np.array([0, 1, 2]), seed=3)
    assert d.value > d.random_value
    assert len(set(d.chosen.tolist())) == 10
    assert np.all(np.diff(d.history) >= 0) and d.history[-1] > d.history[0]
    # the design's own figures: better conditioned, smaller predicted uncertainty than random
    assert d.observability["design"]["O1"] > d.observability["random"]["O1"]
    assert d.predicted_std_mm["design"]["rms_mm"] < d.predicted_std_mm["random"]["rms_mm"]


def test_exchange_from_a_poor_start_only_raises_log_det():
    """From a random start the exchange must climb, one checked swap at a time."""
    rng = np.random.default_rng(0)
    H = rng.normal(size=(300, 3, 8)) * rng.uniform(0.1, 2.0, (300, 1, 1))
    search = D._Search(H, 1e-3 * np.eye(8), rng)
    search.start(range(6))
    start = D.logdet(search.M)
    swaps, passes, history = search.exchange()
    assert swaps > 0 and history[0] == pytest.approx(start)
    assert np.all(np.diff(history) >= 0) and history[-1] > start + 1.0
    Hc = H[search.chosen].astype(np.float32).astype(float)
    assert D.logdet(1e-3 * np.eye(8) + np.einsum("pik,pil->kl", Hc, Hc)) == pytest.approx(history[-1])


def test_i_exchange_from_a_poor_start_only_lowers_the_trace():
    """I criterion: from a random start every pass lowers tr(M^-1) (never raises it), the trace it
    ends with is that of the chosen poses' information computed afresh, and no single swap (all
    of them tried here) lowers it by more than a pass's tolerance."""
    rng = np.random.default_rng(0)
    # unequal columns: D's choice ignores their scale, I's does not
    H = rng.normal(size=(300, 3, 8)) * rng.uniform(0.1, 2.0, (300, 1, 1)) * np.logspace(-1, 1, 8)
    H = H.astype(np.float32).astype(float)
    search = D._Search(H, 1e-3 * np.eye(8), rng, D.I_OPTIMAL)
    search.start(range(6))
    swaps, passes, history = search.exchange()
    trace = np.exp(-np.array(history))  # the objective is -log tr(M^-1)
    assert swaps > 0 and np.all(np.diff(trace) <= 0) and trace[-1] < 0.5 * trace[0]
    info = np.einsum("pik,pjk->pij", H.transpose(0, 2, 1), H.transpose(0, 2, 1))  # H_p^T H_p
    M = 1e-3 * np.eye(8) + info[search.chosen].sum(axis=0)
    assert trace[-1] == pytest.approx(np.trace(np.linalg.inv(M)))
    best = min(np.trace(np.linalg.inv(M - info[j] + info[i])) for j in search.chosen
               for i in np.setdiff1d(np.arange(300), search.chosen))
    assert best > trace[-1] * np.exp(-D.PASS_TOL)


@pytest.mark.parametrize("criterion, value", [
    (D.D_OPTIMAL, D.logdet), (D.I_OPTIMAL, lambda M: -np.trace(np.linalg.inv(M)))])
def test_greedy_picks_the_largest_gain_first(criterion, value):
    """The first pick maximises log det M, or minimises tr(M^-1), checked by brute force."""
    rng = np.random.default_rng(1)
    H = rng.normal(size=(50, 3, 5))
    M0 = np.diag(rng.uniform(0.5, 2.0, 5))
    search = D._Search(H, M0, rng, criterion)
    search.greedy(1)
    brute = [value(M0 + h.astype(np.float32).astype(float).T @ h.astype(np.float32).astype(float)) for h in H]
    assert search.chosen == [int(np.argmax(brute))]


def test_i_design_value_is_the_mean_variance_and_below_d():
    """The I design's value is tr(M^-1 W) (W the candidates' mean information per pose), computed
    here from H_e without the search's whitening; it is below that of D's design (5.1 against 5.6
    here: not a tie, so the two criteria really choose differently), which in turn has the larger
    log det."""
    robot, cm = _model("industrial6r")
    cands = D.uniform_candidates(robot, 300, np.random.default_rng(2))
    i_design = D.design_poses(cm, cands, 10, np.array([0]), seed=2, criterion="I")
    d_design = D.design_poses(cm, cands, 10, np.array([0]), seed=2, criterion="D")
    assert i_design.criterion == "I" and i_design.to_dict()["criterion"] == "I"
    _, H = cm.model_targets(cands.q, None, None, np.zeros(cm.dims.nc), with_H=True)
    H = H[:, :3][:, :, i_design.columns]
    W = np.einsum("pik,pil->kl", H, H) / len(H)

    def mean_variance(idx):
        return np.trace(np.linalg.solve(np.einsum("pik,pil->kl", H[idx], H[idx]), W))

    assert i_design.value == pytest.approx(mean_variance(i_design.chosen), rel=1e-6)
    assert i_design.random_value == pytest.approx(mean_variance(i_design.random), rel=1e-6)
    assert i_design.value < 0.98 * mean_variance(d_design.chosen) < i_design.random_value
    assert d_design.value >= i_design.values["design"]["D"]


def test_given_information_is_the_start(tmp_path):
    """With data already measured the value is log det of (given + chosen) information, computed
    here independently from H_e and the reported column scaling; the given poses keep it above
    what the chosen poses alone have, and the design adds what they lack."""
    robot, cm = _model("industrial6r")
    truth = load_truth({"constant": {"translation_std": 5e-4}, "noise": {"tracker": 3e-5}}, robot)
    rng = np.random.default_rng(5)
    given = simulate(robot, truth, random_design(robot, 15, rng), rng)
    path = tmp_path / "given.csv"
    write_measurements(path, robot, given)
    given = read_measurements(path, robot)
    cands = D.uniform_candidates(robot, 300, rng)
    d = D.design_poses(cm, cands, 10, np.array([0]), given=given, seed=1)
    alone = D.design_poses(cm, cands, 10, np.array([0]), seed=1)

    def scaled(q):
        _, H = cm.model_targets(q, None, None, np.zeros(cm.dims.nc), with_H=True)
        return H[:, :, d.columns].reshape(-1, len(d.columns)) / d.scale

    A_given = np.vstack([H[:, d.columns] for H, _ in rows_H_and_residual(cm, given, given.xyz, np.zeros(cm.dims.nc))])
    A = np.vstack([A_given / d.scale, scaled(cands.q[d.chosen])])
    assert d.value == pytest.approx(D.logdet(A.T @ A), abs=1e-6)
    assert d.value > alone.value
    A_given_more = np.vstack([A_given / d.scale, scaled(cands.q[alone.chosen])])
    assert d.value >= D.logdet(A_given_more.T @ A_given_more) - 1e-6  # designed for the given data

    out = tmp_path / "more.csv"
    run = gecgen("design", ROBOTS / "industrial6r.yaml", "--errors", ROBOTS / "constant.errors.yaml", "--poses", 10,
                 "--candidates", 300, "--given", path, "--criterion", "I", "-o", out, "--json")
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    assert result["criterion"] == "I" and result["value"] == result["mean_variance"] < result["random_mean_variance"]
    ids = [int(r["pose"]) for r in _read(out)]
    assert ids == list(range(15, 25))  # appended after the given file's pose ids


def test_payload_wrench_columns(tmp_path, capsys):
    """Payloads put the sensor's reading of their weight into each pose (as gecgen simulate does)
    and into the written columns; wrench terms are informed only as far as the load varies."""
    errors = tmp_path / "load.errors.yaml"
    errors.write_text('default: ["1"]\nframes:\n  4: {er: ["1", "fy", "mx"]}\n')
    out = tmp_path / "poses.csv"
    code = main(["design", str(ROBOTS / "pps.yaml"), "--errors", str(errors), "--poses", "12", "--candidates", "200",
                 "--targets", "t1,t2,t3", "--payload-kg", "0,70", "--gravity", "0,-9.81,0", "-o", str(out), "--json"])
    result = json.loads(capsys.readouterr().out)
    assert code == 0
    rows = _read(out)
    assert {"fx", "fy", "fz", "mx", "my", "mz", "payload_kg"} <= set(rows[0])
    loaded = [r for r in rows if float(r["payload_kg"]) == 70.0]
    # world y is up; roll and pitch (+-3 deg) tilt the sensor a little
    assert loaded and all(abs(float(r["fy"]) + 70 * 9.81) < 70 * 9.81 * (1 - np.cos(np.radians(4.5))) for r in loaded)
    assert all(float(r["fy"]) == 0.0 for r in rows if float(r["payload_kg"]) == 0.0)
    # the payload sits at the sensor's origin: its moment is always zero, so mx cannot be told
    assert "4.er:fy" in result["identifiable"] and result["unexcitable"] == ["4.er:mx"]


@pytest.mark.parametrize("args, expect", [
    (["--poses", 0], "--poses 0: give at least 1 pose"),
    (["--poses", 50, "--candidates", 20], "--poses 50: only 20 candidates"),
    (["--poses", 5, "--min-z", 20], "no candidate pose passes the constraints (--min-z 20.0)"),
    (["--poses", 5, "--tracker", "1,2"], "--tracker and --max-incidence-deg go together"),
    (["--poses", 5, "--tracker", "1,2", "--max-incidence-deg", 30], "--tracker 1,2: expected 3"),
    (["--poses", 3], "--poses 3: 3 poses inform at most 9 of the 27"),
    (["--poses", 12, "--noise-mm", 0], "--noise-mm 0.0"),
])
def test_cli_bad_input_is_one_line(args, expect, tmp_path, capsys):
    """In process (the contract's own process test is in test_cli): exit 2, one line, no file."""
    more = [] if "--candidates" in args else ["--candidates", 200]
    code = main(["design", str(ROBOTS / "industrial6r.yaml"), "--errors", str(ROBOTS / "constant.errors.yaml"),
                 *map(str, args + more), "-o", str(tmp_path / "p.csv"), "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and expect in lines[0], err
    assert not (tmp_path / "p.csv").exists()


def test_from_csv_candidates_outside_limits_named(tmp_path, capsys):
    path = tmp_path / "allowed.csv"
    path.write_text("q1,q2,q3,q4,q5,q6\n0,-1,0,0,0,0\n0,-3,0,0,0,0\n")
    code = main(["design", str(ROBOTS / "industrial6r.yaml"), "--poses", "1", "--from", str(path),
                 "-o", str(tmp_path / "p.csv")])
    assert code == 2 and "row 3, column 'q2'" in capsys.readouterr().err


def test_designed_poses_calibrate_better_than_random():
    """The point of it: on the PPS with constant errors (a geometric truth, tracker noise), poses
    chosen from the same candidates give a lower validation error than random ones, same N."""
    robot, cm = _model("pps")
    truth = load_truth({"seed": 4, "constant": {"translation_std": 1e-3, "rotation_std": 1e-3},
                        "joint_offsets": {"std": 3e-4}, "noise": {"tracker": 5e-5}}, robot)
    targets = ("t1", "t2", "t3")
    better = 0
    for seed in range(3):
        rng = np.random.default_rng(seed)
        cands = D.uniform_candidates(robot, 500, rng)
        val = simulate(robot, truth, random_design(robot, 200, rng, targets=targets), rng)
        d = D.design_poses(cm, cands, 5, np.array([0, 1, 2]), seed=seed)
        rms = []
        for idx in (d.chosen, d.random):
            design = random_design(robot, 5, rng, targets=targets)
            data = simulate(robot, truth, type(design)(cands.q[idx], design.payload_kg, design.payload_at, targets,
                                                       design.group), rng)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fit = identify(cm, data)
            rms.append(np.sqrt(np.mean(position_errors(cm, val, val.xyz, fit.c) ** 2)))
        better += rms[0] < rms[1]
    assert better == 3


def test_the_i_gain_of_a_pose_that_spans_every_direction_is_finite():
    """A pose whose rows inform all 6 coefficients takes (in single precision) a hair over the
    whole of tr(M^-1) at the start: its gain must rank first, not be NaN (which argmax would pick
    blindly). 40 of 50 such random searches met it before the fix."""
    for seed in range(10):
        rng = np.random.default_rng(seed)
        H = rng.normal(size=(400, 12, 6)) * np.exp(rng.normal(size=(400, 1, 1)))
        H /= np.sqrt(np.einsum("pik,pil->kl", H, H).trace() / 400 / 6)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # log of a negative number warns
            search = D._Search(H, D.RIDGE * np.eye(6), rng, D.I_OPTIMAL)
            search.greedy(10)
            search.exchange()
        assert len(set(search.chosen)) == 10


def test_the_summary_says_what_each_figure_is_beside_the_random_poses(tmp_path, capsys):
    """Without --json: every figure of the comparison on a line of its own with its meaning (which
    way is better, its unit), the designed value beside the random one, the same numbers as --json."""
    from gecgen.cli.human import scalar

    args = ["design", str(ROBOTS / "puma560.yaml"), "--poses", "12", "--candidates", "300", "-o", str(tmp_path / "p.csv")]
    assert main(args + ["--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert main(args) == 0
    text = capsys.readouterr().out
    lines = text.splitlines()
    assert max(len(ln) for ln in lines if str(ROBOTS) not in ln and str(tmp_path) not in ln) <= 120, text
    figures = {**result, **result["observability"], **result["predicted_std"]}
    for key, label, means in [("log_det", "log det of the information (D)", "higher is better"),
                              ("mean_variance", "mean prediction variance (I)", "per unit noise variance; lower is better"),
                              ("rms_mm", "predicted position std, RMS (mm)", "at 0.05 mm noise per coordinate"),
                              ("O2", "O2: condition number", "lower is better")]:
        line = next(ln for ln in lines if ln.strip().startswith(label))
        assert f"{scalar(figures[key]):>10}{scalar(figures[f'random_{key}']):>10}  {means}" in line, line
    # the bare keys of the record are not what a person reads
    assert not any(ln.startswith(("value:", "log_det:", "observability:", "swaps:", "history:")) for ln in lines)
    assert f"then {result['swaps']} exchanges in {result['passes']} passes" in text
