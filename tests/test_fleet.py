"""`gecgen fleet`: many robots calibrated as tasks on a local Dask cluster (gecgen/cli/fleet.py)."""
from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from gecgen.cli import main
from gecgen.cli.fleet import calibrate_fleet, read_manifest
from gecgen.model.validation import ModelError



@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """A robot that calibrates and one whose data is missing, through a local cluster of two workers;
    and the first robot calibrated alone, as `gecgen calibrate` would."""
    root = tmp_path_factory.mktemp("fleet")
    work = root / "a" / "b"
    work.mkdir(parents=True)
    assert main(["simulate", "robots/puma560.yaml", "--poses", "30", "--seed", "1", "-o", str(work / "one.csv")]) == 0
    (work / "m.csv").write_text("name,robot,train,holdout,models\n"
                                f"one,{_root()}/robots/puma560.yaml,one.csv,0.2,geometric\n"
                                f"gone,{_root()}/robots/puma560.yaml,missing.csv,,\n")
    results = calibrate_fleet(work / "m.csv", root / "out", workers=2)
    alone = root / "alone"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["calibrate", f"{_root()}/robots/puma560.yaml", str(work / "one.csv"), "--holdout", "0.2",
                     "--models", "geometric", "-o", str(alone), "--json"]) == 0
    return root, results, alone


def _root():
    from pathlib import Path
    return Path(__file__).resolve().parents[1]


def test_each_robot_is_reported_and_a_failure_stops_none(fleet):
    root, results, _ = fleet
    assert [(r["name"], r["status"]) for r in results] == [("one", "ok"), ("gone", "failed")]
    assert "missing.csv" in results[1]["reason"] and "no such measurement file" in results[1]["reason"]
    assert {c["model"] for c in results[0]["result"]["candidates"]} == {"geometric"}  # the manifest's models
    table = (root / "out" / "fleet.csv").read_text().splitlines()
    assert table[0] == "name,status,model,train_rms_mm,val_rms_mm,seconds,reason" and len(table) == 3
    assert json.loads((root / "out" / "fleet.json").read_text())[1]["status"] == "failed"
    assert (root / "out" / "one" / "report.html").is_file()


def test_a_robot_in_the_fleet_is_as_calibrated_alone(fleet):
    root, _, alone = fleet
    a = json.loads((root / "out" / "one" / "calibration.json").read_text())
    b = json.loads((alone / "calibration.json").read_text())
    assert [c["value"] for c in a["coefficients"]] == [c["value"] for c in b["coefficients"]]
    assert a["train"] == b["train"]
    assert np.array_equal(a["covariance"], b["covariance"])


@pytest.mark.parametrize("text, message", [
    ("name,robot\nx,r.yaml\n", "row 1: missing column 'train'"),
    ("name,robot,train,colour\nx,r.yaml,t.csv,red\n", "row 1: unknown column 'colour'"),
    ("name,robot,train\nx,r.yaml,t.csv\nx,r.yaml,u.csv\n", "row 3: name x is also row 2's"),
    ("name,robot,train\n../up,r.yaml,t.csv\n", "row 2, column 'name': '../up' is no folder name"),
    ("name,robot,train,val,holdout\nx,r.yaml,t.csv,v.csv,0.2\n", "row 2: val and holdout both given"),
])
def test_bad_manifests_are_refused(tmp_path, text, message):
    (tmp_path / "m.csv").write_text(text)
    with pytest.raises(ModelError) as exc:
        read_manifest(tmp_path / "m.csv")
    assert message in str(exc.value)


@pytest.mark.parametrize("name", ["fleet.json", "FLEET.CSV", "fleet.incomplete"])
def test_a_robot_named_as_a_fleet_file_is_refused_before_any_work(tmp_path, name):
    (tmp_path / "m.csv").write_text(f"name,robot,train\n{name},r.yaml,t.csv\n")
    with pytest.raises(ModelError) as exc:
        read_manifest(tmp_path / "m.csv")
    assert f"row 2, column 'name': {name} is a file the fleet writes" in str(exc.value)


@pytest.mark.parametrize("workers", [0, -1, 1.5, True])
def test_a_local_cluster_of_no_workers_is_refused_naming_the_keyword(tmp_path, workers):
    (tmp_path / "m.csv").write_text("name,robot,train\nx,r.yaml,t.csv\n")
    with pytest.raises(ModelError, match=r"^workers=.*\(the workers keyword; --workers on the command line\)"):
        calibrate_fleet(tmp_path / "m.csv", tmp_path / "out", workers=workers)
    assert not (tmp_path / "out").exists()


def test_a_fleet_with_a_failed_robot_exits_1_naming_it_and_says_nothing_of_dask(tmp_path):
    """Run as a user runs it (its own process, so that what Dask's processes print is seen too),
    with the dashboard's usual port taken."""
    import socket
    import subprocess
    import sys

    (tmp_path / "m.csv").write_text(f"name,robot,train\ngone,{_root()}/robots/puma560.yaml,missing.csv\n")
    with socket.socket() as taken:
        taken.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            taken.bind(("", 8787))
            taken.listen()
        except OSError:  # taken already, by something else
            pass
        run = subprocess.run([sys.executable, "-m", "gecgen.cli", "fleet", str(tmp_path / "m.csv"), "-o",
                              str(tmp_path / "out"), "--workers", "1", "--json"], capture_output=True, text=True)
    assert run.returncode == 1
    assert run.stderr.splitlines() == [
        f"gecgen fleet: gone: {tmp_path}/missing.csv: no such measurement file",
        "gecgen fleet: 1 of 1 robots failed: gone"]
    assert json.loads(run.stdout)["failed"] == 1
    assert (tmp_path / "out" / "fleet.csv").is_file() and not (tmp_path / "out" / "fleet.incomplete").exists()
