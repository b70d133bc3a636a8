"""Unknown tool placement: targets the robot file leaves to the data, or places wrongly.

industrial6r with constant generalized errors, measured at a reflector 0.83 m from the flange
(a long tool nobody drew) from a tracker turned by 135 degrees and 3.8 m away; TIAGo's four
motion-capture markers (real data) with their placement left to estimate."""
import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import ROBOTS, random_q

from gecgen.cli import main
from gecgen.model import ModelError, load_robot
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import Measurements, read_measurements, write_measurements
from gecgen.fit.placement import estimate_placement
from scipy.spatial.transform import Rotation

ROBOT = ROBOTS / "industrial6r.yaml"
CONSTANT = ROBOTS / "constant.errors.yaml"
TOOL = (0.35, -0.42, 0.62)  # where the reflector really is, flange frame (m)
TIAGO = ROBOTS.parent / "tests" / "data" / "tiago-mocap" / "train_2021-11-30.csv"


def robot_file(folder: Path, source: Path, old: str, new: str, name: str) -> Path:
    """A copy of a robot file in `folder` with one line replaced (a URDF it names by absolute path)."""
    text = source.read_text()
    assert old in text
    text = re.sub(r"^urdf: (.*)$", lambda m: f"urdf: {source.parent / m.group(1)}", text.replace(old, new), flags=re.M)
    out = folder / f"{name}.yaml"
    out.write_text(text)
    return out


@pytest.fixture(scope="module")
def long_tool(tmp_path_factory):
    """Files: the truth robot (reflector where it is), the user's (reflector left to estimate) and
    60 poses measured from a far tracker frame."""
    d = tmp_path_factory.mktemp("placement")
    truth_robot = robot_file(d, ROBOT, "smr: [0.05, 0.0, 0.20]", f"smr: {list(TOOL)}", "placement_truth")
    user_robot = robot_file(d, ROBOT, "smr: [0.05, 0.0, 0.20]", "smr: estimate", "placement_estimate")
    robot = load_robot(truth_robot)
    rng = np.random.default_rng(3)
    q = random_q(robot, rng, 60)
    eps = np.random.default_rng(7).normal(0, 5e-4, robot.n_errors)
    xyz = target_positions(robot, q, eps)[:, 0] + rng.normal(0, 3e-5, (60, 3))
    tracker = Rotation.from_rotvec([0.4, -1.2, 2.0]).as_matrix(), np.array([3.0, -2.0, 1.0])
    pose = np.arange(60)
    data = Measurements(q, np.zeros((60, 6)), np.zeros((60, 0)), (), pose, pose, np.zeros(60, int),
                        xyz @ tracker[0].T + tracker[1], "sim")
    write_measurements(d / "data.csv", robot, data, wrench=False)
    return d, truth_robot, user_robot


def run(capsys, *args) -> dict:
    assert main([*map(str, args), "--json"]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


def test_a_target_left_to_estimate_is_placed_and_fits_as_if_known(long_tool, capsys):
    d, truth_robot, user_robot = long_tool
    known = run(capsys, "identify", truth_robot, d / "data.csv", "--errors", CONSTANT, "-o", d / "known.json")
    assert main(["identify", str(user_robot), str(d / "data.csv"), "--errors", str(CONSTANT), "-o",
                 str(d / "placed.json"), "--json"]) == 0
    out, err = capsys.readouterr()
    placed = json.loads(out)
    assert "targets placed from the data before the fit: smr estimated" in err
    # the placement is a starting point: frame 6's errors still move the point, so the fit is the
    # same as with the reflector's true position, and the estimate is near it
    assert placed["placement"]["moved_mm"] == {"smr": None}
    assert np.linalg.norm(np.subtract(placed["placement"]["targets_m"]["smr"], TOOL)) < 3e-3
    assert placed["train"]["rms_mm"] == pytest.approx(known["train"]["rms_mm"], rel=0.01)
    assert placed["train"]["rms_mm"] < 0.1
    # the calibration carries the placed target: evaluate on the same poses repeats the fit
    ev = run(capsys, "evaluate", d / "placed.json", d / "data.csv")
    assert ev["after"]["rms_mm"] == pytest.approx(placed["train"]["rms_mm"], rel=1e-6)


def test_a_placement_the_data_cannot_give_is_refused(long_tool):
    """Poses that only turn the tool about the first joint's axis cannot say where on the tool
    the point is: its component along that axis trades against the tracker frame."""
    d, truth_robot, user_robot = long_tool
    robot = load_robot(user_robot)
    data = read_measurements(d / "data.csv", robot)
    q = data.q.copy()
    q[:, 1:] = q[0, 1:]
    with pytest.raises(ModelError, match="turn the tool about fewer than two independent axes"):
        estimate_placement(robot, dataclasses.replace(data, q=q))


def test_too_few_poses_place_nothing(long_tool, capsys):
    """Two poses give 6 coordinates for the tracker frame's 6 unknowns and the target's 3: the
    placement is refused (it once returned a target 5e20 m away and a fit that claimed success)."""
    d, truth_robot, user_robot = long_tool
    robot = load_robot(user_robot)
    data = read_measurements(d / "data.csv", robot).subset(np.arange(2))
    with pytest.raises(ModelError, match="does not place target"):
        estimate_placement(robot, data)
    # the robot file's target stands when the data cannot place it; identify then says the data is too little
    write_measurements(d / "two.csv", robot, data, wrench=False)
    assert main(["identify", str(truth_robot), str(d / "two.csv"), "--errors", str(CONSTANT), "-o", str(d / "two.json")]) == 2
    err = capsys.readouterr().err
    assert "measure more poses" in err and "placed" not in err


def test_nothing_compiles_before_the_targets_are_placed(long_tool, capsys):
    d, truth_robot, user_robot = long_tool
    assert main(["redundancy", str(user_robot), "--errors", str(CONSTANT), "--json"]) == 2
    err = capsys.readouterr().err
    assert "'smr' is left to estimate" in err and len(err.strip().splitlines()) == 1
    # with data, the targets are placed first
    assert run(capsys, "redundancy", user_robot, d / "data.csv", "--errors", CONSTANT)["n_identifiable"] == 27


def test_tiago_markers_placed_from_the_data_and_a_misplaced_one_corrected(tmp_path, capsys):
    """Four markers left to estimate land within a millimetre of the starting values the robot file
    ships (found once by a multi-start search on the same file); a marker written 50 mm off in the
    robot file is moved back before the fit, which then matches the shipped file's."""
    shipped = ROBOTS / "tiago.yaml"
    robot = load_robot(shipped)
    estimate = robot_file(tmp_path, shipped, "  m1: [0.0022, 0.0687, 0.1311]", "  m1: estimate", "tiago_estimate")
    off = robot_file(tmp_path, shipped, "  m3: [-0.0016, -0.0586, 0.2370]", "  m3: [-0.0016, -0.0586, 0.2870]",
                     "tiago_off")
    data = tmp_path / "tiago.csv"
    run(capsys, "import", shipped, TIAGO, "--mapping", ROBOTS / "tiago.import.yaml", "-o", data)
    placement = estimate_placement(load_robot(estimate), read_measurements(data, robot))
    for name in robot.targets:
        assert np.linalg.norm(np.subtract(placement.targets[name], robot.targets[name])) < 1e-3, name
    fits = {}
    for label, path in (("shipped", shipped), ("off", off)):
        fits[label] = run(capsys, "identify", path, data, "--errors", CONSTANT, "-o", tmp_path / f"{label}.json")
    moved = fits["off"]["placement"]["moved_mm"]
    assert moved["m3"] == pytest.approx(50, abs=2) and max(v for k, v in moved.items() if k != "m3") < 1
    assert fits["off"]["train"]["rms_mm"] == pytest.approx(fits["shipped"]["train"]["rms_mm"], rel=0.01)
    assert fits["shipped"]["placement"] is None  # the shipped targets stand


def test_large_data_is_placed_from_rows_spread_through_every_stationing():
    """The placement only starts the fit: beyond PLACEMENT_ROWS rows it reads an even spread of
    them, each stationing and target keeping its share and at least MIN_STATION_ROWS (all of fewer),
    so that a small station still gets its frame and a rarely measured target its place; only the
    chosen rows of the chosen poses are kept; smaller data is used whole."""
    from gecgen.fit.placement import MIN_STATION_ROWS, PLACEMENT_ROWS, spread_sample

    n = 3 * PLACEMENT_ROWS // 2
    station = np.r_[np.zeros(n - 600, int), np.ones(600, int)]
    pose = np.arange(n)
    target = np.zeros(n, int)
    target[5:5 + 300 * 7:7] = 1  # a second target on 300 rows of station 0
    data = Measurements(np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((n, 0)), (), pose, pose, target,
                        np.zeros((n, 3)), "big", station=station)
    sample = spread_sample(data)
    assert PLACEMENT_ROWS - 1 <= len(sample.xyz) <= PLACEMENT_ROWS + 2 * MIN_STATION_ROWS
    assert np.sum(sample.station == 1) == MIN_STATION_ROWS
    assert np.sum(sample.target == 1) == 300
    kept = sample.pose_ids[sample.pose]
    assert kept[0] == 0 and kept[-1] == n - 1  # spread to both ends of the file
    assert np.diff(kept[(sample.station == 0) & (sample.target == 0)]).max() <= 3  # 2 of 3, a target-1 row between
    # three targets a pose: the rows chosen, not every row of their poses
    three = Measurements(np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((n, 0)), (), pose, np.repeat(pose, 3)[:n],
                         np.tile([0, 1, 2], n)[:n], np.zeros((n, 3)), "big")
    assert len(spread_sample(three).xyz) <= PLACEMENT_ROWS + 3
    small = dataclasses.replace(data, station=None).subset(np.arange(100))
    assert spread_sample(small) is small



def test_glitches_do_not_move_the_placement(long_tool):
    """Five points moved by 2-5 cm (a reflector in the wrong nest) barely move the placed target
    (0.28 mm against 3.6 mm for least squares, measured), under every loss as scipy's
    least_squares places it from the same start."""
    from scipy.optimize import least_squares

    from gecgen.fit import placement, robust
    from gecgen.fit.registration import rotation_matrix

    d, truth_robot, user_robot = long_tool
    robot = load_robot(user_robot)
    data = read_measurements(d / "data.csv", robot)
    xyz = data.xyz.copy()
    xyz[[3, 17, 29, 41, 55]] += np.random.default_rng(5).uniform(2e-2, 5e-2, (5, 3))
    glitched = dataclasses.replace(data, xyz=xyz)
    clean = np.array(estimate_placement(robot, data).targets["smr"])
    moved = {loss: np.linalg.norm(estimate_placement(robot, glitched, loss).targets["smr"] - clean)
             for loss in ("cauchy", "huber", "l2")}
    assert moved["cauchy"] < 0.1 * moved["l2"] and moved["huber"] < 0.5 * moved["l2"]
    # the refinement itself against scipy's, on a rigid frame fitted to the glitched points
    p = data.xyz
    y = p @ rotation_matrix([0.02, -0.05, 0.03]).T + [0.01, 0.02, -0.03] + xyz - data.xyz
    y += np.random.default_rng(6).normal(0, 1e-3, y.shape)

    def residual(x):
        return p @ rotation_matrix(x[:3]).T + x[3:] - y

    def jacobian(x, h=1e-7):
        return np.stack([(residual(x + h * e) - residual(x)).ravel() / h for e in np.eye(6)], 1)

    x0 = np.zeros(6)
    c = max(robust.scale(np.linalg.norm(residual(x0), axis=1)), robust.SCALE_FLOOR_M)
    for loss, kind in (("cauchy", "cauchy"), ("huber", "huber"), ("l2", "linear")):
        ours, _ = placement._robust_refine(residual, jacobian, x0, loss)
        theirs = least_squares(lambda x: residual(x).ravel(), x0, loss=kind, f_scale=c, xtol=1e-14, ftol=1e-14).x
        assert np.abs(ours - theirs).max() < 1e-7, loss
