"""The Python API (gecgen/api.py): docs/python-api.md runs as written, the API and the command line
give the same numbers, and bad input at its boundary is refused in one line that names the fix."""
import json
import re

import numpy as np
import pandas as pd
import pytest

import gecgen
from gecgen.cli import main
from conftest import ROBOTS, ROOT

ROBOT = ROBOTS / "industrial6r.yaml"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The data files docs/python-api.md names, made by `gecgen simulate` as the page says, in a
    folder where robots/ is the repository's."""
    d = tmp_path_factory.mktemp("api")
    (d / "robots").symlink_to(ROBOTS)
    for poses, seed, name in ((150, 1, "train.csv"), (40, 2, "val.csv")):
        assert main(["simulate", str(ROBOT), "--poses", str(poses), "--seed", str(seed), "-o", str(d / name),
                     "--json"]) == 0
    return d


@pytest.fixture(scope="module")
def fitted(files):
    # what it holds at zero is said with the keyword that carries it, not only the command's option
    with pytest.warns(UserWarning, match=r"keep_insignificant=True, or --keep-insignificant, carries them"):
        return gecgen.Calibrator().fit(ROBOT, files / "train.csv")


def test_the_python_api_page_runs(files, monkeypatch, capsys):
    """Every ```python block of docs/python-api.md, in order, in one namespace."""
    monkeypatch.chdir(files)
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "python-api.md").read_text(), re.S)
    assert len(blocks) >= 2
    namespace = {}
    for block in blocks:
        exec(compile(block, "docs/python-api.md", "exec"), namespace)
    out = capsys.readouterr().out
    before, after = map(float, re.search(r"validation: ([\d.]+) mm before, ([\d.]+) mm after", out).groups())
    assert after < 0.2 * before  # the calibration removes most of the simulated error
    assert (files / "industrial6r.calib.json").is_file()
    diag, chosen = namespace["diag"], namespace["chosen"]
    assert diag.effects_ and len(diag.error_model_.coefficients) > 42  # terms added to the constant errors
    assert diag.diagnosis_.after["val_rms_mm"] < 0.5 * namespace["score"].after.rms_mm
    assert chosen.model in ("geometric", "default") and chosen.val.rms_mm > 0 and len(chosen.table) == 2


def test_the_readme_python_snippet_runs(files, monkeypatch, capsys):
    """The README's ```python block as written, in a folder with the files its comment makes."""
    monkeypatch.chdir(files)
    [block] = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    namespace = {}
    exec(compile(block, "README.md", "exec"), namespace)
    assert 0 < float(capsys.readouterr().out) < 1.0  # mm after calibration (3 mm before)
    assert namespace["fixed"].status.tolist() == [0] and (files / "robot.calib.json").is_file()


def test_api_and_cli_give_the_same_numbers(files, fitted, tmp_path, capsys):
    calib = tmp_path / "cli.calib.json"
    assert main(["identify", str(ROBOT), str(files / "train.csv"), "-o", str(calib), "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    assert cli["train"] == fitted.report_["train"] and cli["before"] == fitted.report_["before"]
    coefficients = [c["value"] for c in json.loads(calib.read_text())["coefficients"]]
    assert np.array_equal(coefficients, fitted.calibration_.c)

    assert main(["evaluate", str(calib), str(files / "val.csv"), "--json"]) == 0
    evaluated = json.loads(capsys.readouterr().out)
    score = fitted.score(files / "val.csv")
    assert evaluated["after"] == score.after.to_dict() and evaluated["before"] == score.before.to_dict()
    assert evaluated["n_points"] == score.n_points == 40

    q = gecgen.read_measurements(files / "val.csv", ROBOT).q[:7]
    pd.DataFrame(q, columns=[f"q{j + 1}" for j in range(6)]).to_csv(tmp_path / "cmd.csv", index=False)
    code = main(["compensate", str(calib), str(tmp_path / "cmd.csv"), "-o", str(tmp_path / "out.csv"), "--json"])
    assert json.loads(capsys.readouterr().out)["failed_rows"] == [k + 2 for k in fitted.compensate(q).failed]
    done = fitted.compensate(q)
    assert code == (1 if done.failed else 0)  # a row near a singular posture is written, and said
    out = pd.read_csv(tmp_path / "out.csv")
    assert np.array_equal(out[[f"q{j + 1}" for j in range(6)]].to_numpy(), done.q)
    assert out["status"].tolist() == done.status.tolist() and np.allclose(out["residual_mm"], 1e3 * done.residual)
    frame = pd.read_csv(tmp_path / "cmd.csv")  # commands as a DataFrame or a path: the same numbers
    for commands in (frame, tmp_path / "cmd.csv"):
        assert np.array_equal(fitted.compensate(commands).q, done.q)


def test_predict_and_compensate_agree_with_the_calibrated_model(fitted, files):
    """The compensated command, through the calibrated model, lands where the nominal model puts the
    nominal command: predict (calibrated) at q_fixed equals the nominal forward kinematics at q."""
    from gecgen.runtime.compiled import CompiledModel

    q = gecgen.read_measurements(files / "train.csv", ROBOT).q[:5]
    done = fitted.compensate(q)
    nominal = CompiledModel(fitted.robot_, fitted.calibration_.model).nominal_targets(q)
    ok = done.status == 0  # random poses: one is near J5 = 0 (smallest singular value 0.001), damped there
    assert ok.sum() >= 4 and set(done.status[~ok]) <= {2}, done.status
    assert np.abs(fitted.predict(done.q[ok]) - nominal[ok]).max() < 1e-9
    assert np.abs(fitted.predict(q) - nominal).max() > 1e-4  # the calibration moves the tool


def test_a_dataframe_reads_as_its_csv(files):
    robot = gecgen.load_robot(ROBOT)
    frame = pd.read_csv(files / "train.csv")
    a, b = gecgen.read_measurements(frame, robot), gecgen.read_measurements(files / "train.csv", robot)
    for name in ("q", "w", "xyz", "pose", "target", "pose_ids"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.source == "DataFrame"
    bad = frame.copy()
    bad.loc[3, "x"] = np.nan
    with pytest.raises(gecgen.ModelError, match=r"^DataFrame: row 5, column 'x': '' is not a number"):
        gecgen.read_measurements(bad, robot)
    with pytest.raises(gecgen.ModelError, match=r"missing column 'q6'"):
        gecgen.read_measurements(frame.drop(columns="q6"), robot)


def one_line(exc_info) -> str:
    message = str(exc_info.value)
    assert "\n" not in message
    return message


def test_boundary_checks_name_the_fix(fitted, files):
    fresh = gecgen.Calibrator()
    for call in (lambda: fresh.predict(np.zeros(6)), lambda: fresh.score(files / "val.csv"),
                 lambda: fresh.compensate(np.zeros((1, 6))), lambda: fresh.save(files / "x.json")):
        with pytest.raises(gecgen.ModelError) as exc:
            call()
        assert "not fitted yet" in one_line(exc) and "fit(robot, data)" in str(exc.value)
    with pytest.raises(gecgen.ModelError) as exc:
        fitted.predict(np.zeros((3, 5)))
    assert "shape (3, 5)" in one_line(exc) and "(N, 6)" in str(exc.value)
    with pytest.raises(gecgen.ModelError) as exc:
        fitted.compensate([[0.0, 0.0, np.nan, 0.0, 0.0, 0.0]])
    assert "not finite" in one_line(exc)
    with pytest.raises(gecgen.ModelError) as exc:
        fitted.predict(np.zeros(6), w=np.zeros(5))
    assert "w: shape (1, 5)" in one_line(exc)
    with pytest.raises(gecgen.ModelError) as exc:  # measurements of another robot
        gecgen.Calibrator().fit(ROBOTS / "pps.yaml", files / "train.csv")
    assert "train.csv" in one_line(exc)
    with pytest.raises(gecgen.ModelError) as exc:
        gecgen.Calibrator().fit(ROBOTS / "panda.yaml", gecgen.read_measurements(files / "train.csv", ROBOT))
    assert "robot panda has 7 joints" in one_line(exc)
    for options, text in (({"loss": "L2"}, "loss='L2': did you mean 'l2'? the choices: cauchy, huber, l2"),
                          ({"ridge": -1}, "ridge -1: give a non-negative number, or auto"),
                          ({"rank_tol": 2}, "rank_tol 2: give a number from 0 to below 1, or auto"),
                          ({"orientation_length": 0}, "orientation_length=0: give a positive length")):
        with pytest.raises(gecgen.ModelError) as exc:  # at construction: the line that made the mistake
            gecgen.Calibrator(**options)
        assert text in one_line(exc)
    with pytest.raises(gecgen.ModelError) as exc:
        gecgen.calibrate(ROBOT, files / "train.csv", models=("geometric", "bogus"))
    assert "models: 'bogus' is not a candidate" in one_line(exc)
    with pytest.raises(gecgen.ModelError) as exc:
        gecgen.Diagnoser().save(files / "x.errors.yaml")
    assert "not fitted yet" in one_line(exc)
    with pytest.raises(gecgen.ModelError) as exc:
        gecgen.Diagnoser(register_val=True).fit(ROBOT, files / "train.csv")
    assert "pass val" in one_line(exc)
