"""Compensation at singular postures, on the walk-through's UR10 (tests/data/ur10, identified from its
measured poses) and the coupled FANUC-like arm (robots/fanuc.yaml, identified from simulated data): a
stretched elbow, a shoulder singularity (the wrist over joint 1's axis) and the wrist at J5 = 0. There
the exact correction swings joints without bound (an elbow bent by 19 degrees for a 4 mm error, J4 and
J6 turned by +-145 degrees); compensate gives the least damped correction the model's error justifies
instead, with status 2 (singular) and the tool error left, never a worse tool than the command's. The
generated C, the Python and the CLI give every row the same status."""
import json
import shlex
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROBOTS, ROOT
from scipy.optimize import minimize_scalar

import gecgen
from gecgen.cli import main
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import tool_pose
from gecgen.model.validation import read_yaml
from gecgen.runtime.compiled import BOUNDED, OK, SINGULAR, STATUS_NAMES, compiler
from gecgen.simulate import load_truth, random_design, simulate

UR10 = ROOT / "tests" / "data" / "ur10"
#: regular postures (smallest singular value of the tool Jacobian 0.44 and 0.23) from which each
#: singularity is found by moving one joint: the elbow (joint 3), the shoulder (joint 2), the wrist (joint 5)
REGULAR = {"fanuc": [0.3, 0.2, 0.1, 0.4, 0.8, 0.2], "ur10": [0.3, -1.2, 1.2, -1.0, 0.8, 0.2]}
SINGULARITIES = {"elbow": 2, "shoulder": 1, "wrist": 4}


def sigma_min(robot, q) -> np.ndarray:
    """The smallest singular value (N,) of the nominal tool Jacobian (position in m and rotation in rad
    per joint unit, as compensate weighs them) at q (N, n), by central differences."""
    q = np.atleast_2d(q)
    h, n = 1e-6, q.shape[1]
    R0, cols = tool_pose(robot, q)[:, :3, :3], []
    for k in range(n):
        dq = np.zeros(n)
        dq[k] = h
        Tp, Tm = tool_pose(robot, q + dq), tool_pose(robot, q - dq)
        W = (Tp[:, :3, :3] - Tm[:, :3, :3]) @ R0.transpose(0, 2, 1) / (2 * h)
        cols.append(np.column_stack([(Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h), W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]]))
    return np.linalg.svd(np.stack(cols, axis=-1), compute_uv=False)[:, -1]


def singular_posture(robot, q, k) -> np.ndarray:
    """q with joint k moved to where the tool Jacobian is singular: the lowest smallest singular value
    on a grid over the joint's range (within +-3.1 rad), refined."""
    lo, hi = max(robot.joints[k].lower, -3.1), min(robot.joints[k].upper, 3.1)
    grid = np.repeat(np.array(q, float)[None], 801, axis=0)
    grid[:, k] = np.linspace(lo, hi, 801)
    i = int(np.argmin(sigma_min(robot, grid)))

    def at(x):
        moved = np.array(q, float)
        moved[k] = x
        return moved

    best = minimize_scalar(lambda x: sigma_min(robot, at(x))[0], method="bounded",
                           bounds=(grid[max(i - 1, 0), k], grid[min(i + 1, 800), k]), options={"xatol": 1e-10})
    return at(best.x)


def commands(robot, name) -> dict[str, np.ndarray]:
    """Per posture ("regular" and each singularity) five commands: the posture, and joint 1 and the
    last joint turned (which moves no singularity)."""
    out = {}
    for posture, k in [("regular", None), *SINGULARITIES.items()]:
        q = np.array(REGULAR[name], float) if k is None else singular_posture(robot, REGULAR[name], k)
        variants = np.repeat(q[None], 5, axis=0)
        variants[1:, 0] += [0.3, -0.3, 0.1, -0.1]
        variants[1:, -1] += [0.4, -0.4, -0.2, 0.2]
        out[posture] = variants
    return out


@pytest.fixture(scope="module")
def arms(tmp_path_factory):
    """name -> (calibrator, calibration JSON path, commands by posture)."""
    folder = tmp_path_factory.mktemp("arms")
    robot = UR10 / "ur10_probe.yaml"
    with open(folder / "log", "w") as log:  # the commands' summaries are not this test's
        sys.stdout, saved = log, sys.stdout
        try:
            assert main(["import", str(robot), str(UR10 / "calibration.csv"), "--mapping",
                         str(UR10 / "calibration.mapping.yaml"), "-o", str(folder / "poses.csv")]) == 0
            assert main(["identify", str(robot), str(folder / "poses.csv"), "-o", str(folder / "ur10.json")]) == 0
        finally:
            sys.stdout = saved
    ur10 = gecgen.load_calibration(folder / "ur10.json")
    fanuc_robot = load_robot(ROBOTS / "fanuc.yaml")
    truth = load_truth(read_yaml(ROBOTS / "fanuc.truth.yaml", "truth"), fanuc_robot)
    rng = np.random.default_rng(5)
    fanuc = gecgen.Calibrator(errors=load_error_model(None, fanuc_robot)).fit(
        fanuc_robot, simulate(fanuc_robot, truth, random_design(fanuc_robot, 150, rng), rng))
    fanuc.save(folder / "fanuc.json")
    return {"ur10": (ur10, folder / "ur10.json", commands(ur10.robot_, "ur10")),
            "fanuc": (fanuc, folder / "fanuc.json", commands(fanuc_robot, "fanuc"))}


@pytest.mark.parametrize("name", ["ur10", "fanuc"])
def test_the_postures_are_what_they_are_called(arms, name):
    cal, _, by_posture = arms[name]
    assert sigma_min(cal.robot_, by_posture["regular"]).min() > 0.1
    for posture in SINGULARITIES:
        assert sigma_min(cal.robot_, by_posture[posture]).max() < 1e-6, posture
    assert np.abs(by_posture["wrist"][:, 4]).max() < 1e-9  # J5 = 0


@pytest.mark.filterwarnings("ignore:extrapolation")
@pytest.mark.parametrize("name", ["ur10", "fanuc"])
@pytest.mark.parametrize("posture", ["elbow", "shoulder", "wrist"])
def test_a_singular_posture_gets_a_small_damped_correction_and_says_so(arms, name, posture):
    cal, _, by_posture = arms[name]
    q_cmd = by_posture[posture]
    done = cal.compensate(q_cmd)
    before = cal.compensate(q_cmd, max_iter=0).residual  # no step: the model's tool error at the command
    assert set(done.status.tolist()) == {SINGULAR}, done.status
    # no swing: each joint moves by at most 3 rad per m (1 rad of the tool as 1 m) of the tool error at
    # the command (measured: 0.6 to 1.8; at most 0.077 rad on the UR10, 0.003 rad on the FANUC). The exact
    # corrections, which an earlier gecgen gave with status 0, moved joints by up to 0.36 (elbow), 0.52
    # (shoulder) and 1.64 rad (wrist) on the UR10, 0.18, 0.41 and 0.43 rad on the FANUC
    gain = np.abs(done.q - q_cmd).max(axis=1) / before
    assert gain.max() < 3, gain
    assert np.all(done.residual < before), (done.residual, before)  # never a worse tool
    assert done.failed == list(range(len(q_cmd)))


@pytest.mark.filterwarnings("ignore:extrapolation")
@pytest.mark.parametrize("name", ["ur10", "fanuc"])
def test_a_regular_posture_is_corrected_exactly(arms, name):
    cal, _, by_posture = arms[name]
    done = cal.compensate(by_posture["regular"])
    assert set(done.status.tolist()) == {OK} and done.residual.max() < 1e-11 and not done.failed


@pytest.mark.filterwarnings("ignore:extrapolation")
def test_a_bound_holds_every_joint_and_is_reported(arms):
    cal, _, by_posture = arms["fanuc"]
    q_cmd = np.vstack([by_posture["regular"], by_posture["wrist"]])
    free = cal.compensate(q_cmd)
    bound = 0.5 * np.abs(free.q - q_cmd).max(axis=0)  # half of each joint's largest correction
    done = cal.compensate(q_cmd, bound=bound)
    assert np.all(np.abs(done.q - q_cmd) <= bound + 1e-15)
    reached = np.any(np.abs(done.q - q_cmd) >= bound * (1 - 1e-12), axis=1)
    assert reached.any() and np.all(done.status[reached] == BOUNDED), done.status
    held = cal.compensate(q_cmd, bound={"J1": 0.0})  # a joint bound to 0 is not corrected
    assert np.array_equal(held.q[:, 0], q_cmd[:, 0])
    with pytest.raises(gecgen.ModelError, match="bound: J2 has a negative or NaN bound"):
        cal.compensate(q_cmd, bound=[0.1, -1, 0.1, 0.1, 0.1, 0.1])


def _rows(path) -> tuple[list[str], list[list[str]]]:
    header, *rows = [line.split(",") for line in path.read_text().splitlines()]
    return header, rows


@pytest.mark.filterwarnings("ignore:extrapolation")
@pytest.mark.parametrize("name", ["ur10", "fanuc"])
def test_the_cli_writes_every_row_with_its_status_and_says_which_failed(arms, name, tmp_path):
    cal, path, by_posture = arms[name]
    q_cmd = np.vstack(list(by_posture.values()))  # regular rows first, then the singular ones
    (tmp_path / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6,label\n" + "".join(
        ",".join(repr(float(v)) for v in q) + f",{k}\n" for k, q in enumerate(q_cmd)))
    run = subprocess.run([sys.executable, "-m", "gecgen.cli", "compensate", path, tmp_path / "cmd.csv", "-o",
                          tmp_path / "out.csv", "--json"], capture_output=True, text=True)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 1 and len(lines) == 1 and "cmd.csv: row 7: near a singular posture" in lines[0], lines
    assert "15 of 20 rows not placed (15 singular" in lines[0]
    summary = json.loads(run.stdout)
    assert summary["status_counts"] == {"ok": 5, "singular": 15} and summary["failed_rows"] == list(range(7, 22))
    header, rows = _rows(tmp_path / "out.csv")
    assert header == ["q1", "q2", "q3", "q4", "q5", "q6", "label", "status", "residual_mm"]
    assert [r[6] for r in rows] == [str(k) for k in range(len(q_cmd))]  # every row, in order, its columns kept
    done = cal.compensate(q_cmd)
    assert [int(r[7]) for r in rows] == done.status.tolist()
    np.testing.assert_array_equal(np.array([r[:6] for r in rows], float), done.q)
    np.testing.assert_allclose([float(r[8]) for r in rows], 1e3 * done.residual, rtol=1e-12)
    # a bound: every row still written, the bounded ones say so
    bounded = subprocess.run([sys.executable, "-m", "gecgen.cli", "compensate", path, tmp_path / "cmd.csv", "-o",
                              tmp_path / "out.csv", "--bound", "0.001"], capture_output=True, text=True)
    _, rows = _rows(tmp_path / "out.csv")
    corrected = np.array([r[:6] for r in rows], float)
    assert bounded.returncode == 1 and len(rows) == len(q_cmd) and np.abs(corrected - q_cmd).max() <= 0.001 + 1e-15
    assert STATUS_NAMES[BOUNDED] in bounded.stderr and {int(r[7]) for r in rows} >= {BOUNDED}


DRIVER = r"""
#include <stdio.h>
#include "%(name)s_calibration.h"
static const double commands[][%(N)s_NQ] = { %(commands)s };
static const double bound[%(N)s_NQ] = { %(bound)s };
int main(void)
{
    const double w[6] = {0, 0, 0, 0, 0, 0};
    double q[%(N)s_NQ], residual;
    int i, k, pass;
    for (pass = 0; pass < 2; ++pass) /* free, then bounded */
        for (i = 0; i < (int)(sizeof commands / sizeof commands[0]); ++i) {
            const int status = %(name)s_compensate_bounded(commands[i], w, NULL, %(name)s_calibration, 50, 1e-11,
                                                           pass ? bound : NULL, q, &residual, NULL);
            printf("%%d %%.17g", status, residual);
            for (k = 0; k < %(N)s_NQ; ++k) printf(" %%.17g", q[k]);
            printf("\n");
        }
    return 0;
}
"""


@pytest.mark.skipif(compiler() is None, reason="needs a C compiler")
@pytest.mark.filterwarnings("ignore:extrapolation")
@pytest.mark.parametrize("name", ["ur10", "fanuc"])
def test_the_exported_c_and_the_python_agree_on_every_status(arms, name, tmp_path):
    cal, path, by_posture = arms[name]
    q_cmd = np.vstack(list(by_posture.values()))
    bound = np.full(6, 0.002)
    with open(tmp_path / "log", "w") as log:
        sys.stdout, saved = log, sys.stdout
        try:
            assert main(["export", str(path), "--c", str(tmp_path / "c"), "--json"]) == 0
        finally:
            sys.stdout = saved
    export = json.loads((tmp_path / "log").read_text())["c"]
    (tmp_path / "c" / "driver.c").write_text(DRIVER % {
        "name": name, "N": name.upper(), "bound": ", ".join(repr(float(v)) for v in bound),
        "commands": ", ".join("{" + ", ".join(repr(float(v)) for v in q) + "}" for q in q_cmd)})
    build = shlex.split(export["compile"])
    build[next(i for i, a in enumerate(build) if a.endswith("_example.c"))] = str(tmp_path / "c" / "driver.c")
    build[build.index("-o") + 1] = str(tmp_path / "c" / "driver")
    made = subprocess.run(build, capture_output=True, text=True)
    assert made.returncode == 0, made.stderr
    printed = np.array([line.split() for line in subprocess.run(
        [tmp_path / "c" / "driver"], capture_output=True, text=True, check=True).stdout.splitlines()], float)
    for rows, limit in ((printed[:len(q_cmd)], None), (printed[len(q_cmd):], bound)):
        done = cal.compensate(q_cmd, bound=limit)
        assert rows[:, 0].astype(int).tolist() == done.status.tolist()
        np.testing.assert_allclose(rows[:, 1], done.residual, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(rows[:, 2:], done.q, rtol=0, atol=1e-12)
    assert {int(s) for s in printed[:, 0]} >= {OK, SINGULAR, BOUNDED}
