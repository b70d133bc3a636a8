"""A tracker that moves: the robot's errors stay, the measurement frame changes.

industrial6r with constant generalized errors and 30 um tracker noise. Training: 60 poses, the
second half measured from a tracker moved by 20 degrees and 1.5 m (a `station` column says
which). Day 2: 40 new poses measured from yet another stationing (35 degrees and 1.7 m from the world)."""
import json

import numpy as np
import pytest
from conftest import ROBOTS, random_q

from gecgen.cli import main
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import Measurements, read_measurements, write_measurements
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import identify, position_errors

ROBOT = ROBOTS / "industrial6r.yaml"
CONSTANT = ROBOTS / "constant.errors.yaml"
NOISE = 3e-5


def rotation(axis: int, deg: float) -> np.ndarray:
    a = np.radians(deg)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i] = R[j, j] = np.cos(a)
    R[i, j], R[j, i] = -np.sin(a), np.sin(a)
    return R


#: the tracker moved by 20 degrees (mostly about the vertical) and 1.5 m
MOVED = (rotation(2, 20) @ rotation(0, 3), np.array([1.2, -0.9, 0.0]))
DAY2 = (rotation(2, -35) @ rotation(1, 2), np.array([-0.8, 1.5, 0.2]))


def measure(robot, truth, n, seed, frames=(None,), stations=None) -> Measurements:
    """n poses of the truth chain, in len(frames) equal parts of consecutive poses, part k measured
    by a tracker at frames[k] = (R, t) (None: the world frame); `stations` labels the parts."""
    rng = np.random.default_rng(seed)
    q = random_q(robot, rng, n)
    pose, target = np.arange(n), np.zeros(n, int)
    xyz = target_positions(robot, q, truth)[:, 0] + rng.normal(0, NOISE, (n, 3))
    part = pose * len(frames) // n
    for k, frame in enumerate(frames):
        if frame is not None:
            xyz[part == k] = xyz[part == k] @ frame[0].T + frame[1]
    return Measurements(q, np.zeros((n, 6)), np.zeros((n, 0)), (), pose, pose, target, xyz, "sim",
                        station=None if stations is None else np.asarray(stations)[part])


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    robot = load_robot(ROBOT)
    truth = np.random.default_rng(7).normal(0, 5e-4, robot.n_errors)
    d = tmp_path_factory.mktemp("station")
    files = {"one": measure(robot, truth, 60, 1),
             "two": measure(robot, truth, 60, 1, [None, MOVED], stations=[0, 1]),
             "val": measure(robot, truth, 40, 2),
             "day2": measure(robot, truth, 40, 2, [DAY2]),  # no station column: station 0
             "day2_station5": measure(robot, truth, 40, 2, [DAY2], stations=[5])}
    for name, data in files.items():
        write_measurements(d / f"{name}.csv", robot, data, wrench=False)
    return robot, truth, d, files


def run(capsys, *args) -> dict:
    assert main([*map(str, args), "--json"]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def calibrations(setup):
    """The one-station and two-station calibrations, and what identify said of the latter."""
    robot, truth, d, files = setup
    for name in ("one", "two"):
        assert main(["identify", str(ROBOT), str(d / f"{name}.csv"), "--errors", str(CONSTANT),
                     "-o", str(d / f"{name}.json"), "--json"]) == 0
    return d / "one.json", d / "two.json"


def test_two_stations_recover_the_one_station_accuracy(setup, calibrations, capsys):
    robot, truth, d, files = setup
    one, two = (run(capsys, "evaluate", c, d / "val.csv")["after"]["rms_mm"] for c in calibrations)
    print(f"validation RMS: one station {one:.4f} mm, two stations {two:.4f} mm")
    assert abs(two - one) <= 0.05 * one and one < 0.1
    stored = json.loads(calibrations[1].read_text())
    assert set(stored["registrations"]) == {"0", "1"} and stored["registration"] == stored["registrations"]["0"]
    moved = stored["registrations"]["1"]
    assert moved["applied"] and abs(moved["angle_deg"] - 20.2) < 0.1 and abs(moved["distance_mm"] - 1500) < 1
    # the same points without the column: one frame cannot hold both halves
    cm = CompiledModel(robot, load_error_model(CONSTANT, robot))
    data = files["two"]
    merged = Measurements(data.q, data.w, data.aux, (), data.pose_ids, data.pose, data.target, data.xyz, "sim")
    with pytest.warns(UserWarning):
        fit = identify(cm, merged)
    val = files["val"]
    e = position_errors(cm, val, fit.to_world(val), fit.c)
    print(f"without the station column: {1e3 * np.sqrt(np.mean(e ** 2)):.1f} mm")
    assert 1e3 * np.sqrt(np.mean(e ** 2)) > 10 * one


def test_evaluate_register_fits_a_new_stationing(setup, calibrations, capsys):
    robot, truth, d, files = setup
    calib = calibrations[0]
    same = run(capsys, "evaluate", calib, d / "val.csv")
    assert same["registered"] is False and same["before_registration"] == "the calibration's"
    moved = run(capsys, "evaluate", calib, d / "day2.csv", "--register")
    stale = run(capsys, "evaluate", calib, d / "day2.csv")  # the calibration's frame: the old stationing
    refitted = run(capsys, "evaluate", calib, d / "val.csv", "--register")
    assert main(["evaluate", str(calib), str(d / "day2.csv"), "--register"]) == 0
    assert "tracker_frame: re-fitted on DATA" in capsys.readouterr().out
    print(f"day 2: same frame {same['after']['rms_mm']:.4f} mm, --register {moved['after']['rms_mm']:.4f} mm "
          f"(on the same-frame file {refitted['after']['rms_mm']:.4f} mm), without {stale['after']['rms_mm']:.1f} mm")
    # the frame fitted on the data also takes up what the calibration left of frame 0's errors, so
    # it may do better than the calibration's frame, never worse
    assert moved["after"]["rms_mm"] <= 1.05 * same["after"]["rms_mm"]
    # the day-2 file is the same-frame file moved rigidly: the fitted frame makes them the same
    assert abs(moved["after"]["rms_mm"] - refitted["after"]["rms_mm"]) <= 1e-6 * refitted["after"]["rms_mm"]
    assert moved["registered"] is True and moved["before_registration"].startswith("the nominal model's")
    assert moved["before"]["rms_mm"] > 10 * moved["after"]["rms_mm"]
    frame = moved["registration"]
    assert set(moved["registrations"]) == {"0"} and frame == moved["registrations"]["0"]
    assert abs(frame["angle_deg"] - 35.06) < 0.1 and abs(frame["distance_mm"] - 1711.7) < 5, frame
    assert stale["registered"] is False
    assert stale["after"]["rms_mm"] > 100 * same["after"]["rms_mm"]


def test_evaluate_register_auto_registers_only_a_moved_stationing(setup, calibrations, capsys):
    """`--register auto`, as identify's: day 2 (the tracker moved 35 degrees and 1.7 m) is scored in its
    fitted frame, as with --register; the same-frame file in the calibration's, as without."""
    robot, truth, d, files = setup
    calib = calibrations[0]
    moved = run(capsys, "evaluate", calib, d / "day2.csv", "--register", "auto")
    assert moved["registered"] is True
    assert moved["after"] == run(capsys, "evaluate", calib, d / "day2.csv", "--register")["after"]
    same = run(capsys, "evaluate", calib, d / "val.csv", "--register", "auto")
    assert same["registered"] is False and same["before_registration"] == "the calibration's"
    assert same["after"] == run(capsys, "evaluate", calib, d / "val.csv")["after"]


def test_a_glitch_does_not_tilt_the_new_frame(setup, calibrations, capsys):
    robot, truth, d, files = setup
    day2 = files["day2"]
    xyz = day2.xyz.copy()
    xyz[7, 0] += 0.05
    glitched = Measurements(day2.q, day2.w, day2.aux, (), day2.pose_ids, day2.pose, day2.target, xyz, "sim")
    write_measurements(d / "glitch.csv", robot, glitched, wrench=False)
    clean = run(capsys, "evaluate", calibrations[0], d / "day2.csv", "--register")["registration"]
    bad = run(capsys, "evaluate", calibrations[0], d / "glitch.csv", "--register")["registration"]
    tilt = np.abs(np.array(bad["rotation"]) - clean["rotation"]).max()
    shift = np.abs(np.array(bad["translation"]) - clean["translation"]).max()
    print(f"glitch of 50 mm: rotation moved {tilt:.2g}, translation {1e6 * shift:.2g} um")
    assert tilt < 1e-5 and shift < 1e-5  # least squares: 50 mm / 40 points = 1.25 mm


def test_an_unknown_station_needs_register(setup, calibrations, capsys):
    robot, truth, d, files = setup
    assert main(["evaluate", str(calibrations[1]), str(d / "day2_station5.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "station 5" in err[0] and "--register" in err[0], err
    # a station it knows uses its frame: the second half of the training file, on its own
    two = files["two"]
    write_measurements(d / "half.csv", robot, two.subset(np.arange(30, 60)), wrench=False)
    assert run(capsys, "evaluate", calibrations[1], d / "half.csv")["after"]["rms_mm"] < 0.1
    # a calibration written before stations knows one: station 0, its `registration`
    old = json.loads(calibrations[1].read_text())
    del old["registrations"]
    (d / "old.json").write_text(json.dumps(old))
    assert main(["evaluate", str(d / "old.json"), str(d / "half.csv")]) == 2
    assert "station 1 has no known tracker frame" in capsys.readouterr().err
    old_run, new_run = (run(capsys, "evaluate", c, d / "val.csv") for c in (d / "old.json", calibrations[1]))
    assert old_run.pop("error_model") == f"{d / 'old.json'}: error_model"  # each names its own file
    new_run.pop("error_model")
    assert old_run == new_run


def test_the_station_column_is_an_integer_id_not_a_signal(setup):
    robot, truth, d, files = setup
    data = read_measurements(d / "two.csv", robot)
    assert data.aux_names == () and sorted(set(data.station.tolist())) == [0, 1]
    lines = (d / "two.csv").read_text().splitlines()
    column = lines[0].split(",").index("station")
    fields = lines[3].split(",")
    fields[column] = "1.5"
    lines[3] = ",".join(fields)
    (d / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelError) as err:
        read_measurements(d / "bad.csv", robot)
    assert "row 4, column 'station'" in str(err.value) and "integer" in str(err.value) and "\n" not in str(err.value)


def test_diagnose_scores_the_validation_file_in_its_own_frame(setup, calibrations, capsys):
    robot, truth, d, files = setup
    args = ["diagnose", ROBOT, d / "one.csv", "--errors", CONSTANT, "--val", d / "day2.csv", "--max-rounds", "1",
            "-o", d / "diag.errors.yaml"]
    registered = run(capsys, *args, "--register")
    stale = run(capsys, *args)
    evaluated = run(capsys, "evaluate", calibrations[0], d / "day2.csv", "--register")["after"]["rms_mm"]
    print(f"diagnose val RMS: --register {registered['after']['val_rms_mm']:.4f} mm, "
          f"without {stale['after']['val_rms_mm']:.1f} mm; evaluate --register {evaluated:.4f} mm")
    assert registered["val_registered"] is True and stale["val_registered"] is False
    assert abs(registered["after"]["val_rms_mm"] - evaluated) <= 0.01 * evaluated
    assert stale["after"]["val_rms_mm"] > 100 * evaluated


def test_calibrate_scores_a_validation_file_from_another_stationing(setup, calibrations, capsys):
    """calibrate --register scores day 2 as evaluate --register does; without it the unknown
    frame is not guessed: the validation of the training frame is far off (100x)."""
    robot, truth, d, files = setup
    args = ["calibrate", ROBOT, d / "one.csv", "--errors", CONSTANT, "--models", "geometric", "--val", d / "day2.csv"]
    registered = run(capsys, *args, "-o", d / "cal_registered", "--register")
    stale = run(capsys, *args, "-o", d / "cal_stale")
    evaluated = run(capsys, "evaluate", d / "cal_registered" / "calibration.json", d / "day2.csv", "--register")
    assert registered["val_registered"] is True and stale["val_registered"] is False
    assert registered["val"] == evaluated["after"] and registered["val_before"] == evaluated["before"]
    assert stale["val"]["rms_mm"] > 100 * registered["val"]["rms_mm"]
    # the report scores the validation data as the JSON does, and a station the training lacks is no bar
    headline = (d / "cal_registered" / "report.md").read_text()
    assert f"{registered['val']['rms_mm']:.4f}" in headline, headline[:1500]
    other = run(capsys, *args[:-1], d / "day2_station5.csv", "-o", d / "cal_station5", "--register")
    assert other["val"] == registered["val"]
