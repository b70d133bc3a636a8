"""Designs for calibration without a tracker (gecgen/plan/fixture_design.py, `gecgen design
--fixtures`): which configurations to record in each socket and on each plane.

Checked against independent computation: the exchange's incremental gain against the log det of the
information recomputed from scratch; the candidates against the forward kinematics; and the point
of a design, on a simulated Panda, a held-out plane flatness closer to the noise floor than the same
number of touches chosen at random.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from conftest import run_json
import pytest
import yaml

from gecgen import api
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.fixture_file import Fixture
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import read_measurements
from gecgen.model.validation import ModelError, read_yaml
from gecgen.plan import fixture_design as FD
from gecgen.runtime.compiled import CompiledModel
from gecgen.plan.design import logdet
from gecgen.simulate import load_truth
from gecgen.simulate.fixtures import Fixtures, simulate_fixtures

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "robots" / "panda_ball.yaml"
CONSTANT = ROOT / "robots" / "constant.errors.yaml"
#: constant errors and a stiffness per joint that gravity loads, as tests/test_relative.py
ELASTIC = {"default": ["1"], "frames": {j: {"er": ["1", f"gravity_torque(q{j})"]} for j in range(2, 8)}}
#: two sockets of a plate 50 mm apart and a table, in the Panda's reach
FIXTURES = "name,x,y,z,nx,ny,nz\ns1,0.5,0.025,0.2,,,\ns2,0.5,-0.025,0.2,,,\ntable,0.45,0.25,0.05,0,0,2\n"


@pytest.fixture(scope="module")
def fixture_design(tmp_path_factory):
    robot = load_robot(ROBOT)
    cm = CompiledModel(robot, load_error_model(CONSTANT, robot))
    folder = tmp_path_factory.mktemp("fixtures")
    (folder / "fx.csv").write_text(FIXTURES)
    from gecgen.model.fixture_file import read_fixtures

    fixtures = read_fixtures(folder / "fx.csv")
    cands = FD.fixture_candidates(robot, fixtures, 0, 60, np.random.default_rng(0))
    return robot, cm, cands, FD.design_fixtures(cm, cands, 30, 0, seed=0), folder


def test_candidates_put_the_target_on_its_fixture(fixture_design):
    """Each socket's configurations put the ball at its centre, each plane's on the plane within its
    patch, all inside the joint limits by the margin."""
    robot, _, cands, _, _ = fixture_design
    lo, hi = (np.array(v) for v in robot.sampling_box())
    for f, q, goal in zip(cands.fixtures, cands.q, cands.goal):
        assert len(q) >= 30
        p = target_positions(robot, q)[:, 0]
        assert np.abs(p - goal).max() < 1e-9
        assert ((q >= lo + FD.LIMIT_MARGIN * (hi - lo)) & (q <= hi - FD.LIMIT_MARGIN * (hi - lo))).all()
        if f.is_plane:
            assert np.allclose(f.normal, [0, 0, 1]) and np.abs((p - f.point) @ f.normal).max() < 1e-9
            assert np.abs(p - f.point)[:, :2].max() <= FD.PATCH_M + 1e-9 and np.ptp(p[:, 0]) > FD.PATCH_M
        else:
            assert np.abs(p - f.point).max() < 1e-9


def test_the_exchange_gain_is_the_log_det_it_adds():
    """The recursive least-squares gain of adding a configuration to a fixture whose nuisance is
    fitted equals log det of the information recomputed from scratch with it, for a socket (3 rows,
    the mean eliminated) and a plane (1 row, offset and tilts eliminated)."""
    rng = np.random.default_rng(3)
    k = 6
    M0 = np.eye(k) * 0.5
    for r, nuisance in ((3, lambda n: np.tile(np.eye(3), (n, 1, 1))),
                        (1, lambda n: np.column_stack([np.ones(n), rng.normal(size=(n, 2))])[:, None, :])):
        a, b = rng.normal(size=(12, r, k)), nuisance(12)
        chosen = [0, 1, 2, 3, 4]
        G, P, C = FD._nuisance(a, b, chosen)
        M = M0 + C
        gains = FD._gains(a, b, G, P, np.linalg.inv(M))
        for i in range(5, 12):
            exact = logdet(M0 + FD._nuisance(a, b, chosen + [i])[2]) - logdet(M)
            assert gains[i] == pytest.approx(exact, rel=1e-9, abs=1e-12)


def test_a_design_beats_its_random_start(fixture_design):
    """More information (log det) and a smaller predicted residual than the seeded even random start
    it was exchanged from; every fixture keeps what makes it say anything; what no configuration sees
    (the rigid motions and the scale) is counted apart."""
    _, cm, cands, d, _ = fixture_design
    counts = [len(c) for c in d.chosen]
    assert sum(counts) == 30 and all(c >= FD.MINIMUM[f.is_plane] for c, f in zip(counts, cands.fixtures))
    assert all(len(set(c.tolist())) == len(c) for c in d.chosen)
    assert [len(c) for c in d.random] == [10, 10, 10]
    assert d.log_det["design"] > d.log_det["random"] + 3
    assert d.predicted_mm["design"] < d.predicted_mm["random"]
    assert d.unseen == 7 and d.swaps > 0


def test_design_through_the_command_line(fixture_design, tmp_path):
    """`gecgen design --fixtures` writes a measurement file's rows (x y z empty, point or plane named)
    that read back as the sockets and plane they name, and reports per fixture."""
    _, _, _, _, folder = fixture_design
    out = run_json("design", ROBOT, "--errors", CONSTANT, "--fixtures", folder / "fx.csv", "--poses", 24,
                   "--candidates", 40, "-o", tmp_path / "d.csv")
    assert out["n_poses"] == 24 and out["target"] == "ball" and out["unseen"] == 7
    assert [f["name"] for f in out["fixtures"]] == ["s1", "s2", "table"]
    assert out["log_det"] > out["random_log_det"]
    data = read_measurements(tmp_path / "d.csv", load_robot(ROBOT))
    rel = data.relative
    assert rel.names == ("s1", "s2", "table") and list(rel.is_plane()) == [False, False, True]
    assert np.bincount(rel.group).tolist() == [f["poses"] for f in out["fixtures"]]
    by = out["by_fixtures"]
    assert [b["fixtures"] for b in by][-1] == 3 and by[-1]["predicted_rms_mm"] == out["predicted"]["rms_mm"]
    assert by[-1]["log_det"] == pytest.approx(out["log_det"], rel=1e-12)


@pytest.mark.parametrize("text, options, message", [
    ("name,x,y,z\ns1,0.5,0,0.2\ns1,0.5,0.05,0.2\n", [], "row 3, column 'name': 's1' is already the name of row 2"),
    ("name,x,y,z,nx,ny,nz\np,0.5,0,0.2,0,0,0\n", [], "row 2, column 'nx': the normal (0, 0, 0) is not a nonzero"),
    ("name,x,y\ns1,0.5,0\n", [], "no column z"),
    ("name,x,y,z\ns1,0.5,0,0.2\n", ["--min-z", "0"], "--min-z does not apply to a design for --fixtures"),
    ("name,x,y,z\ns1,0.5,0,0.2\n", ["--tracker", "2,0,1", "--max-incidence-deg", "30"],
     "--tracker does not apply to a design for --fixtures"),
    ("name,x,y,z,nx,ny,nz\np,0.5,0,0.2,0,nan,1\n", [], "row 2, column 'ny': the normal (0, nan, 1) is not a"),
    ("name,x,y,z\ns1,0.5,0,0.2\ns2,5,0,0.2\n", [], "fixture s2: the ball reaches it in 0 of"),
    ("name,x,y,z\ns1,0.5,0,0.2\ns2,0.5,0,0.2\n", [], "fx.csv: rows 2 and 3: 's1' and 's2' are sockets 0 mm apart; "
                                                     "give each fixture its own position"),
    ("name,x,y,z,nx,ny,nz\np,0.5,0,0.2,0,0,1\nq,0.4,0.1,0.2,0,0,-2\n", [], "rows 2 and 3: 'p' and 'q' are the same plane"),
])
def test_bad_fixture_designs_are_refused(tmp_path, capsys, text, options, message):
    """One line naming the file, row and column or the option, and the fix; no output written."""
    from gecgen.cli import main

    (tmp_path / "fx.csv").write_text(text)
    args = ["design", ROBOT, "--errors", CONSTANT, "--fixtures", tmp_path / "fx.csv", "--poses", 10, "--candidates", 10,
            "-o", tmp_path / "d.csv", *options]
    assert main([str(a) for a in args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and not (tmp_path / "d.csv").exists(), err


def test_a_huge_normal_is_a_direction(tmp_path):
    """A normal of finite but huge components is a direction like any other (its norm overflows)."""
    from gecgen.model.fixture_file import read_fixtures

    (tmp_path / "fx.csv").write_text("name,x,y,z,nx,ny,nz\np,0.45,0.25,0.05,1e300,1e300,0\n")
    np.testing.assert_allclose(read_fixtures(tmp_path / "fx.csv")[0].normal, [0.5 ** 0.5, 0.5 ** 0.5, 0], atol=1e-15)


def test_designed_touches_flatten_held_out_planes(tmp_path):
    """Three planes, 30 touches each chosen by the design from 150 recorded per plane, against 30 each
    chosen at random from the same: the held-out planes' flatness comes closer to the noise floor, and
    within the acceptance's 1.3x of it."""
    robot = load_robot(ROBOT)
    truth = load_truth(read_yaml(ROOT / "robots" / "panda.truth.yaml", "truth"), robot)
    rng = np.random.default_rng(101)
    pool, _ = simulate_fixtures(robot, truth, Fixtures("ball", planes=3, touches=150), rng)
    val, floor = simulate_fixtures(robot, truth, Fixtures("ball", planes=3, touches=30), rng)
    errors = tmp_path / "elastic.errors.yaml"
    errors.write_text(yaml.safe_dump(ELASTIC))  # the truth's joints twist under gravity
    model = load_error_model(errors, robot)
    cands, poses = FD.recorded_candidates(robot, pool, 0)
    d = FD.design_fixtures(CompiledModel(robot, model), cands, 90, 0, seed=1)
    flatness = {}
    for name, chosen in (("design", d.chosen), ("random", d.random)):
        train = pool.subset(np.sort(np.concatenate([p[c] for p, c in zip(poses, chosen)])))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            cal = api.Calibrator(errors=errors).fit(ROBOT, train)
        flatness[name] = cal.score(val).after.flatness_mm / floor["flatness_mm"]
    assert flatness["design"] < flatness["random"] and flatness["design"] <= 1.3, flatness


def test_a_fixture_must_be_a_point_or_a_plane():
    assert not Fixture("s", np.zeros(3)).is_plane and Fixture("p", np.zeros(3), np.array([0, 0, 1.0])).is_plane
    with pytest.raises(ModelError, match="need at least"):
        robot = load_robot(ROBOT)
        cands = FD.FixtureCandidates((Fixture("s", np.zeros(3)),), (np.zeros((5, 7)),), (np.zeros((5, 3)),))
        FD.design_fixtures(CompiledModel(robot, load_error_model(CONSTANT, robot)), cands, 1, 0)


@pytest.mark.parametrize("option", [["--patch-mm", "50"], ["--target", "ball"]])
def test_fixture_options_without_fixtures_are_refused(tmp_path, capsys, option):
    from gecgen.cli import main

    assert main(["design", str(ROBOT), "--poses", "10", "-o", str(tmp_path / "d.csv"), *option]) == 2
    assert f"{option[0]} goes with --fixtures" in capsys.readouterr().err


def test_the_summary_of_a_fixture_design_says_what_each_figure_is(fixture_design, tmp_path, capsys):
    from gecgen.cli import main
    from gecgen.cli.human import scalar

    _, _, _, _, folder = fixture_design
    args = ["design", str(ROBOT), "--errors", str(CONSTANT), "--fixtures", str(folder / "fx.csv"), "--poses", "24",
            "--candidates", "40", "-o", str(tmp_path / "d.csv")]
    out = run_json(*args[:-1], tmp_path / "e.csv")
    assert main(args) == 0
    text = capsys.readouterr().out
    assert (f"log det of the information (D)        {scalar(out['log_det']):>10}{scalar(out['random_log_det']):>10}"
            f"  higher is better") in text
    assert f"{scalar(out['predicted']['rms_mm']):>10}{scalar(out['predicted']['random_rms_mm']):>10}  by the " in text
    assert "\nswaps:" not in text and "\nlog_det:" not in text
    assert f"then {out['swaps']} exchanges in {out['passes']} passes" in text
