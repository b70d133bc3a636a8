"""Real data end to end: import the TIAGo motion-capture files, register, identify, and match the
figures figaroh (an independent implementation) published for the same data and models."""
import json

import pytest
from conftest import ROBOTS, ROOT

from gecgen.cli import main

DATA = ROOT / "tests" / "data" / "tiago-mocap"


def run(capsys, *args) -> dict:
    assert main([*map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


LOADED = ",".join(f"arm_{k}_joint" for k in range(2, 8))


@pytest.fixture
def files(tmp_path, capsys) -> dict:
    """Marker 1 of both days and all four markers of the training day, with the arm joints' gravity torques."""
    out = {}
    for key, name, targets in (("train", "train_2021-11-30", ["--targets", "m1"]),
                               ("val", "validation_2021-11-26", ["--targets", "m1"]), ("train_all", "train_2021-11-30", [])):
        joints, out[key] = tmp_path / f"{key}.joints.csv", tmp_path / f"{key}.csv"
        imp = run(capsys, "import", ROBOTS / "tiago.yaml", DATA / f"{name}.csv", "--mapping",
                  ROBOTS / "tiago.import.yaml", *targets, "-o", joints)
        assert imp["poses"] == {"train": 37, "val": 62, "train_all": 37}[key]
        assert imp["rows"] == imp["poses"] * (4 if key == "train_all" else 1)
        assert [o["joint"] for o in imp["outside_limits"]] == ["torso_lift_joint"]  # reported, not clipped
        run(capsys, "gravity", ROBOTS / "tiago.yaml", joints, "--joints", LOADED, "-o", out[key])
    return out


@pytest.mark.parametrize("model, n, train_rms, val_rms", [
    ("tiago.base.errors.yaml", 9, 3.37, 4.87),      # figaroh: base registration only
    ("tiago.offsets.errors.yaml", 14, 2.88, 4.23),  # figaroh: joint offsets
])
def test_reduced_models_reproduce_figaroh(files, tmp_path, capsys, model, n, train_rms, val_rms):
    calib = tmp_path / "c.json"
    fit = run(capsys, "identify", ROBOTS / "tiago.yaml", files["train"], "--errors", ROBOTS / model, "-o", calib,
              "--keep-insignificant")  # figaroh fits every parameter
    assert fit["registration"]["applied"] and fit["n_identifiable"] == n
    assert abs(fit["train"]["rms_mm"] - train_rms) < 0.006
    ev = run(capsys, "evaluate", calib, files["val"])
    assert abs(ev["after"]["rms_mm"] - val_rms) < 0.006


def test_full_geometric_point_model_has_the_theoretical_count(files, tmp_path, capsys):
    """The full geometric model: every identifiable parameter carried, and by default (insignificant
    ones held at zero, the rest refitted) fewer carried and the other day predicted better (measured:
    4.172 -> 4.065 mm)."""
    val = {}
    for keep in (True, False):
        fit = run(capsys, "identify", ROBOTS / "tiago.yaml", files["train"], "--errors", ROBOTS / "tiago.errors.yaml",
                  "-o", tmp_path / "c.json", *["--keep-insignificant"] * keep)
        assert fit["n_identifiable"] == 4 * 7 + 2 * 1 + 3
        assert fit["train"]["rms_mm"] < 1.68 or not keep  # figaroh's 30-parameter model: 1.68 mm
        assert (fit["n_carried"] == fit["n_identifiable"]) == keep
        val[keep] = run(capsys, "evaluate", tmp_path / "c.json", files["val"])["after"]["rms_mm"]
    assert val[False] < val[True]


def test_rank_tolerance_chosen_on_training_data(files, tmp_path, capsys):
    """--rank-tol auto on the full model (marker 1): the weakest columns are the arm_5 frame's ep and
    the arm_6 frame's es (tiny shares, values that are mostly noise); 5-fold CV over the 37 training
    postures picks 0.1 and 22 parameters. Same-day CV does not carry over to the other day's postures:
    validation 4.90 mm, worse than the exact model's 4.17 and above figaroh's 3.22 (docs/real-data-tiago.md)."""
    calib = tmp_path / "c.json"
    fit = run(capsys, "identify", ROBOTS / "tiago.yaml", files["train"], "--errors", ROBOTS / "tiago.errors.yaml",
              "--rank-tol", "auto", "-o", calib, "--keep-insignificant")  # the rank tolerance alone
    weak = sorted((e for e in fit["eliminated"] if e["reason"] == "weak"), key=lambda e: e["share"])
    # the two weakest, whichever comes first: their shares are close enough for rounding to order them
    assert {e["param"] for e in weak[:2]} == {"6.ep:1", "7.es:1"} and weak[0]["share"] < 0.02
    assert fit["rank_tol"] == 0.1 and fit["n_identifiable"] == 33 - len(weak) == 22
    assert min(fit["cv"], key=lambda row: row["cv_rms_mm"])["rank_tol"] == 0.1
    ev = run(capsys, "evaluate", calib, files["val"])
    assert abs(ev["after"]["rms_mm"] - 4.90) < 0.006


def test_diagnose_adds_only_what_cross_validates(files, tmp_path, capsys):
    """diagnose on the real data, the arm joints' gravity torques offered: from the joint-offset model it
    adds the missing constant error first and the refit predicts the other day better; from the full
    model nothing survives the selection-aware cross-validation on 37 postures.

    Until candidates were ranked by significance (issue 11) the offsets run went on to add q1**2 on
    3.ez and then arm_6's angle under its gravity load (7.er). On these 37 postures the folds of the
    selection check do not agree on a winner (q1**2 in two, arm_6's load in two, a Fourier pair in
    one), so the choice does not generalise (3.276 mm against 3.195 mm) and is refused; the arm_6 trace
    it used to unmask does not follow. Ranking the folds' winners by raw drop instead would let a
    12-column link-bending group win there and predict far worse (held-out 3478 against 86 mm^2)."""
    for model, first in (("tiago.offsets.errors.yaml", "5.ex"), ("tiago.errors.yaml", None)):
        out = tmp_path / f"{model}.diagnosed.yaml"
        d = run(capsys, "diagnose", ROBOTS / "tiago.yaml", files["train"], "--val", files["val"], "--errors",
                ROBOTS / model, "-o", out)
        if first is None:
            assert d["effects"] == [] and d["after"] == d["before"]
        else:
            assert d["effects"][0]["error"] == first and d["effects"][0]["terms"] == ["1"]
            assert d["after"]["val_rms_mm"] < d["before"]["val_rms_mm"]


def test_gravity_compliance_model_beats_figaroh_on_the_other_day(files, tmp_path, capsys):
    """The model the training file chooses (docs/real-data-tiago.md): full geometric plus one compliance
    per loaded arm joint, fitted on all four markers. arm_6's compliance stands far above its
    uncertainty, and marker 1 of the validation day lands below figaroh's full geometric 3.22 mm."""
    calib = tmp_path / "c.json"
    fit = run(capsys, "identify", ROBOTS / "tiago.yaml", files["train_all"], "--errors",
              ROBOTS / "tiago.elastic.errors.yaml", "-o", calib, "--keep-insignificant")
    assert fit["n_identifiable"] == 4 * 7 + 2 * 1 + 6 + 6  # full pose: 36 geometric, and 6 compliances
    arm6 = next(c for c in json.loads(calib.read_text())["coefficients"] if c["name"] == "7.er:tau_arm_6_joint")
    assert arm6["value"] > 10 * arm6["std"] > 0
    ev = run(capsys, "evaluate", calib, files["val"])
    assert abs(ev["after"]["rms_mm"] - 3.20) < 0.006 and ev["after"]["rms_mm"] < 3.22
