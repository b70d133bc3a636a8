"""gecgen calibrate: the model chosen on the training data alone, then fitted, written and scored.

Simulated industrial6r (robots/industrial6r.truth.yaml: gravity bending, gear eccentricity,
compliance) with a payload measured by the wrench sensor: 0 or 150 kg on alternate poses."""
import json
import re
import shutil

import numpy as np
import pytest
from conftest import ROBOTS

from gecgen.cli import main
from gecgen.fit import calibration
from gecgen.model import load_robot
from gecgen.model.measurements import hold_out, read_measurements

ROBOT = ROBOTS / "industrial6r.yaml"


def run(capsys, *args) -> dict:
    assert main([*map(str, args), "--json"]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def payload_data(tmp_path_factory):
    d = tmp_path_factory.mktemp("calibrate")
    assert main(["simulate", str(ROBOT), "--poses", "60", "--seed", "2", "--payload-kg", "0,150",
                 "-o", str(d / "train.csv"), "--json"]) == 0
    assert main(["simulate", str(ROBOT), "--poses", "40", "--seed", "3", "--payload-kg", "0,150",
                 "-o", str(d / "val.csv"), "--json"]) == 0
    return d


def test_the_elastic_model_is_chosen_when_a_payload_bends_the_arm(payload_data, capsys):
    d = payload_data
    out = run(capsys, "calibrate", ROBOT, d / "train.csv", "--val", d / "val.csv", "--models", "geometric,elastic",
              "-o", d / "elastic")
    cv = {c["model"]: c["cv_rms_mm"] for c in out["candidates"]}
    assert set(cv) == {"geometric", "elastic"}
    # the wrench torque on each joint's own error is what the truth's compliance is made of
    assert out["model"] == "elastic" and cv["elastic"] < 0.7 * cv["geometric"]
    errors = (d / "elastic" / "errors.yaml").read_text()
    assert "wrench_torque(q2)" in errors and "wrench_torque(q3)" in errors
    # the validation figure is what evaluate says of the written calibration on the same file
    ev = run(capsys, "evaluate", d / "elastic" / "calibration.json", d / "val.csv")
    assert ev["after"]["rms_mm"] == pytest.approx(out["val"]["rms_mm"], rel=1e-9)
    assert out["val"]["rms_mm"] < 0.25 * out["val_before"]["rms_mm"]
    for f in ("calibration.json", "errors.yaml", "report.md", "report.html", "generated/industrial6r.c",
              "generated/industrial6r_calibration.h", "generated/industrial6r_example.c"):
        assert (d / "elastic" / f).is_file(), f
    assert "| elastic (chosen) |" in (d / "elastic" / "report.md").read_text()
    assert "elastic (chosen)" in (d / "elastic" / "report.html").read_text()
    assert _summary_row(d / "elastic" / "report.md", "calibrated") == _figures(out, ev)


def _summary_row(report, stage: str) -> list[str]:
    """The report's Summary row of a stage: training RMS and max, validation RMS and max (mm)."""
    row = next(line for line in report.read_text().splitlines() if line.startswith(f"| {stage} |"))
    return [c.strip() for c in row.strip("|").split("|")][1:5]


def _figures(out: dict, ev: dict) -> list[str]:
    """The same four figures as calibrate's JSON gives the training data and evaluate the validation data."""
    return [f"{out['train']['rms_mm']:.3g}", f"{out['train']['max_mm']:.3g}", f"{ev['after']['rms_mm']:.3g}",
            f"{ev['after']['max_mm']:.3g}"]


def test_the_report_gives_the_delivered_diagnosed_calibration_s_figures(payload_data, capsys):
    """Coefficients the data do not determine are held at zero after diagnose: the report's diagnosed row
    is that delivered fit, as the JSON and evaluate of the written calibration give it, not diagnose's own."""
    d = payload_data
    out = run(capsys, "calibrate", ROBOT, d / "train.csv", "--val", d / "val.csv", "--models", "diagnosed",
              "-o", d / "delivered")
    assert out["significance"]["held"]  # else the delivered fit would be diagnose's own
    ev = run(capsys, "evaluate", d / "delivered" / "calibration.json", d / "val.csv")
    assert _summary_row(d / "delivered" / "report.md", "diagnosed") == _figures(out, ev)
    assert ev["after"]["rms_mm"] == pytest.approx(out["val"]["rms_mm"], rel=1e-9)
    (row,) = out["candidates"]
    assert row["n_params_delivered"] == out["n_params"] > row["n_params"]


def test_a_tie_goes_to_the_smaller_model_as_delivered(payload_data, monkeypatch):
    """Elastic and diagnosed tie within 1 %; diagnose starts smaller than elastic but delivers a larger
    model: the elastic one is chosen (counting diagnose's start size would choose it instead)."""
    from types import SimpleNamespace

    import gecgen.loop.calibrate as loop
    from gecgen.symbolic.terms import error_model_from_dict

    monkeypatch.setenv("GECGEN_WORKERS", "1")
    robot = load_robot(ROBOT)
    data = read_measurements(payload_data / "train.csv", robot)
    cv_mm = {"geometric": 1.0, "elastic": 0.500, "diagnosed": 0.498}
    big = error_model_from_dict({"default": ["1", "q1", "q2"]}, robot, "<big>")
    monkeypatch.setattr(loop, "_scored", lambda robot, p, *_: ((cv_mm[p.name] / 1e3) ** 2, 1.0))
    monkeypatch.setattr(loop, "run_pipeline", lambda robot, p, *_: (big if p.diagnose else p.model, None,
                                                                     SimpleNamespace(failures=[]), None))
    choice = loop.choose(robot, data, None, names=("geometric", "elastic", "diagnosed"))
    sizes = {row["model"]: row for row in choice.table}
    assert sizes["diagnosed"]["n_params"] < sizes["elastic"]["n_params"] < sizes["diagnosed"]["n_params_delivered"]
    assert choice.chosen.name == "elastic"
    cv_mm["elastic"] = 0.504  # no longer within 1 %: the lowest wins
    assert loop.choose(robot, data, None, names=("geometric", "elastic", "diagnosed")).chosen.name == "diagnosed"


def test_every_candidate_scored_and_the_rule_followed(payload_data, capsys):
    """All four candidates on 30 poses, validation by --holdout: the chosen one has the lowest
    cross-validated RMS (or ties it within 1% with fewer coefficients)."""
    d = payload_data
    out = run(capsys, "calibrate", ROBOT, d / "val.csv", "--holdout", "0.25", "--seed", "1", "-o", d / "all")
    cv = {c["model"]: c["cv_rms_mm"] for c in out["candidates"]}
    assert set(cv) == {"geometric", "default", "elastic", "diagnosed"}
    best = min(v for v in cv.values() if v is not None)
    assert cv[out["model"]] <= 1.01 * best
    assert out["validation"] == f"--holdout 0.25 of {d / 'val.csv'} (seed 1)"
    assert {"rms_mm", "max_mm"} <= set(out["train"]) and {"rms_mm", "max_mm"} <= set(out["val"])


def test_the_same_choice_and_report_in_one_process_or_two(payload_data, capsys, monkeypatch):
    """The folds and the report's figures run side by side (`runtime.processes`); one process gives
    the same candidates' scores, the same choice, the same warnings and the same report, byte for byte."""
    d = payload_data
    outs = {}
    for n in ("1", "2"):
        monkeypatch.setenv("GECGEN_WORKERS", n)
        capsys.readouterr()
        assert main(["calibrate", str(ROBOT), str(d / "val.csv"), "--models", "geometric,diagnosed", "--holdout",
                     "0.25", "-o", str(d / f"workers{n}"), "--json"]) == 0
        printed = capsys.readouterr()
        out = json.loads(printed.out)
        outs[n] = (out["candidates"], out["model"], printed.err, (d / f"workers{n}" / "report.md").read_text(),
                   sorted((f.name, f.read_bytes()) for f in (d / f"workers{n}").glob("*.png")))
    assert outs["1"] == outs["2"] and len(outs["1"][4]) >= 6


def test_mapped_keeps_the_order_and_refuses_a_bad_worker_count(monkeypatch):
    from gecgen.model.validation import ModelError
    from gecgen.runtime.processes import mapped

    calls = [(divmod, (k * 7, 3)) for k in range(9)]
    for n in ("1", "3"):
        monkeypatch.setenv("GECGEN_WORKERS", n)
        with mapped(calls) as results:
            assert list(results) == [divmod(k * 7, 3) for k in range(9)]
    monkeypatch.setenv("GECGEN_WORKERS", "two")
    with pytest.raises(ModelError, match="GECGEN_WORKERS='two': give a whole number of processes"):
        with mapped(calls) as results:
            list(results)


@pytest.mark.parametrize("n", ["1", "2"])
def test_a_worker_s_warnings_and_errors_reach_the_caller(monkeypatch, n):
    """What a task says (a warning) and how it fails (an exception) are the same in one process or two."""
    import warnings

    from gecgen.runtime.processes import mapped

    monkeypatch.setenv("GECGEN_WORKERS", n)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with mapped([(warnings.warn, (f"task {k}",)) for k in range(3)]) as results:
            assert list(results) == [None] * 3
    assert [str(w.message) for w in caught] == ["task 0", "task 1", "task 2"]
    with pytest.raises(ZeroDivisionError):
        with mapped([(divmod, (1, 1)), (divmod, (1, 0)), (divmod, (2, 1))]) as results:
            list(results)


def test_hold_out_splits_by_pose_and_is_seeded(payload_data):
    data = read_measurements(payload_data / "train.csv", load_robot(ROBOT))
    train, val = hold_out(data, 0.25, seed=5)
    assert (train.n_poses, val.n_poses) == (45, 15)
    assert not set(train.pose_ids) & set(val.pose_ids)
    again = hold_out(data, 0.25, seed=5)[1]
    np.testing.assert_array_equal(again.pose_ids, val.pose_ids)
    assert not np.array_equal(hold_out(data, 0.25, seed=6)[1].pose_ids, val.pose_ids)


@pytest.mark.parametrize("args, message", [
    (["--models", "geometric,bogus"], "--models: 'bogus' is not a candidate"),
    (["--holdout", "1.5"], "--holdout 1.5: give the share of poses to hold out"),
])
def test_bad_options_are_refused_in_one_line(payload_data, capsys, args, message):
    d = payload_data
    assert main(["calibrate", str(ROBOT), str(d / "train.csv"), *args, "-o", str(d / "bad"), "--json"]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def _same_numbers(a, b, path="result"):
    """a and b alike: the same keys, lists and text, numbers equal to 1e-9 (mm in the figures)."""
    assert type(a) is type(b) or {type(a), type(b)} <= {int, float}, path
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _same_numbers(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for k, (x, y) in enumerate(zip(a, b)):
            _same_numbers(x, y, f"{path}[{k}]")
    elif isinstance(a, float):
        assert b == pytest.approx(a, rel=1e-9, abs=1e-9), path
    else:
        assert a == b, path


def test_a_robot_never_compiled_is_calibrated_without_the_compiler_and_as_with_it(payload_data, capsys,
                                                                                   monkeypatch, tmp_path):
    """An empty code cache: calibrate fits, scores and compensates (the example program's command) in
    numpy, never waiting for the C compiler, asks for the delivered model's C for the next run, and
    writes what the compiled path writes: its generated code byte for byte, its numbers to 1e-9 mm."""
    from gecgen.runtime import compiled

    from gecgen.model.files import cache_dir

    d = payload_data
    args = ["calibrate", ROBOT, d / "val.csv", "--holdout", "0.25", "--models", "geometric"]
    monkeypatch.setenv("GECGEN_BACKEND", "c")
    with_c = run(capsys, *args, "-o", tmp_path / "c")
    monkeypatch.delenv("GECGEN_BACKEND")
    # a cache with the robot's printed code (its symbolic build is not what is tested) and no library
    cold = tmp_path / "cache"
    cold.mkdir()
    for f in cache_dir().glob(f"{ROBOT.stem}-*.json*"):
        shutil.copy(f, cold)
    monkeypatch.setenv("GECGEN_CACHE", str(cold))

    def compiler(*args):
        raise AssertionError("calibrate waited for the C compiler")

    asked = []
    monkeypatch.setattr(compiled, "shared_library", compiler)
    monkeypatch.setattr(compiled, "build_in_background", lambda robot, model, key, alongside=False: asked.append((key, alongside)))
    without = run(capsys, *args, "-o", tmp_path / "numpy")
    calib = calibration.load(tmp_path / "numpy" / "calibration.json")
    assert (compiled.model_key(calib.robot, calib.model), True) in asked  # the delivered model's, beside the others
    text = json.dumps(without).replace(str(tmp_path / "numpy"), str(tmp_path / "c"))
    _same_numbers(with_c, json.loads(text))
    header = "industrial6r_calibration.h"
    files = {f.name for f in (tmp_path / "c" / "generated").iterdir()}
    assert files == {f.name for f in (tmp_path / "numpy" / "generated").iterdir()} and header in files
    for name in files - {header}:  # the C, its header, the CasADi form, the example program: byte for byte
        assert (tmp_path / "c" / "generated" / name).read_bytes() == (tmp_path / "numpy" / "generated" / name).read_bytes()
    # the coefficients, printed to 17 digits, differ by rounding only: 1e-12 m (1e-9 mm) or 1e-12 rad
    lines = [re.findall(r"^    (-?[\d.e-]+), /\* \d+ ", (tmp_path / k / "generated" / header).read_text(), re.M)
             for k in ("c", "numpy")]
    assert len(lines[0]) == len(lines[1]) == with_c["n_params"]
    np.testing.assert_allclose(np.array(lines[1], float), np.array(lines[0], float), rtol=0, atol=1e-12)
