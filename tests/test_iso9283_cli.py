"""`gecgen iso9283`: the pose test planned as joint commands, and its characteristics from the measured
cycles (gecgen/cli/iso9283.py), against the standard's formulas computed here with numpy."""
from __future__ import annotations


from dataclasses import replace

import numpy as np
from conftest import run_json

from gecgen.model import load_robot
from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import write_measurements
from gecgen.simulate import Design, load_truth, simulate




def test_a_planned_test_measured_gives_the_standards_figures(tmp_path):
    robot = load_robot("robots/puma560.yaml")
    plan = run_json("iso9283", "robots/puma560.yaml", "-o", tmp_path / "plan.csv", "--tool-rpy", "180,0,0",
                "--cycles", 6)
    assert plan["rows"] == 30 and plan["side_mm"] > 100
    table = np.genfromtxt(tmp_path / "plan.csv", delimiter=",", names=True)
    q = np.column_stack([table[f"q{j}"] for j in range(1, 7)])
    assert table["point"][:5].tolist() == [1, 5, 4, 3, 2]
    # the robot as built: repeatability 50 um per coordinate and a 0.3 mm offset of its base along x
    truth = load_truth({"noise": {"repeatability": 5e-5, "tracker": 0.0},
                        "constant": {"values": {"0.ex": 3e-4}}}, robot)
    data = simulate(robot, truth, Design(q, np.zeros(len(q)), np.zeros(3), ("t1",), np.array(["iso"] * len(q))),
                    np.random.default_rng(0))
    write_measurements(tmp_path / "run.csv", robot, data)
    out = run_json("iso9283", "robots/puma560.yaml", "--plan", tmp_path / "plan.csv", "--measured", tmp_path / "run.csv")
    commanded = target_positions(robot, q)[:, 0]
    for p in range(1, 6):
        rows = table["point"] == p
        xyz = data.xyz[rows]
        bary = xyz.mean(axis=0)
        l = np.linalg.norm(xyz - bary, axis=1)
        got = out["points"]["t1"][f"P{p}"]
        assert got["n"] == 6
        assert abs(got["AP_p"] - 1e3 * np.linalg.norm(bary - commanded[rows][0])) < 1e-9
        assert abs(got["AP_x"] - 1e3 * (bary[0] - commanded[rows][0][0])) < 1e-9
        assert abs(got["RP_l"] - 1e3 * (l.mean() + 3 * l.std(ddof=1))) < 1e-9
        assert 0.2 < got["AP_x"] < 0.4  # the base offset, within the noise of 6 cycles
    assert out["worst"]["AP_p"] == max(v["AP_p"] for v in out["points"]["t1"].values())
    # distance P2 to P4, cycle by cycle (the plan's cycle column pairs them)
    d = np.linalg.norm(data.xyz[table["point"] == 2] - data.xyz[table["point"] == 4], axis=1)
    d_c = np.linalg.norm(commanded[table["point"] == 2][0] - commanded[table["point"] == 4][0])
    got = out["distance"]["t1"]
    assert got["n"] == 6 and abs(got["AD_p"] - 1e3 * (d.mean() - d_c)) < 1e-9
    assert abs(got["RD_p"] - 3e3 * d.std(ddof=1)) < 1e-9
    # the same test on the robot without its base offset (as compensation would leave it): scored
    # against the same commanded poses, its accuracy is the noise's alone
    fixed = load_truth({"noise": {"repeatability": 5e-5, "tracker": 0.0}}, robot)
    after = simulate(robot, fixed, Design(q, np.zeros(len(q)), np.zeros(3), ("t1",), np.array(["iso"] * len(q))),
                     np.random.default_rng(1))
    write_measurements(tmp_path / "after.csv", robot, after)
    both = run_json("iso9283", "robots/puma560.yaml", "--plan", tmp_path / "plan.csv", "--measured", tmp_path / "run.csv",
                "--after", tmp_path / "after.csv")
    assert both["worst"] == out["worst"] and both["after"]["worst"]["AP_p"] < 0.15 < out["worst"]["AP_p"]
    # a tolerance between the compensated run's farthest cycle and the run as commanded: it meets it
    reach = max(v["AP_p"] + v["RP_l"] for v in both["after"]["points"]["t1"].values())
    tolerance = (reach + out["worst"]["AP_p"]) / 2
    assert reach < tolerance < out["worst"]["AP_p"]
    reported = run_json("iso9283", "robots/puma560.yaml", "--plan", tmp_path / "plan.csv", "--measured",
                    tmp_path / "run.csv", "--after", tmp_path / "after.csv", "--report", tmp_path / "report",
                    "--tolerance-mm", tolerance)
    text = (tmp_path / "report" / "report.md").read_text()
    assert reported["assessment"]["verdict"] == "meets" and "**Verdict: meets.**" in text
    assert "**Next step:** " in text and text.index("## Verdict and next step") < text.index("## Summary")
    assert "After compensation" in text and f"{out['worst']['AP_p']:.3g}" in text and "P2-P4" in text
    assert (tmp_path / "report" / "report.html").stat().st_size > 0 and reported["report"].endswith("report.md")


def test_a_run_or_plan_that_is_not_the_test_is_refused(tmp_path, capsys):
    """Too few cycles, P1 alone, a run with q1 0.2 rad off the plan's (another plan), and plan cells
    that are no integer or no point of the test: one line each, never figures."""
    from gecgen.cli import main

    robot = load_robot("robots/puma560.yaml")
    run_json("iso9283", "robots/puma560.yaml", "-o", tmp_path / "plan.csv", "--tool-rpy", "180,0,0", "--cycles", 3)
    plan = (tmp_path / "plan.csv").read_text().splitlines()
    table = np.genfromtxt(tmp_path / "plan.csv", delimiter=",", names=True)
    q = np.column_stack([table[f"q{j}"] for j in range(1, 7)])
    truth = load_truth({"noise": {"repeatability": 5e-5, "tracker": 0.0}}, robot)

    def run(name, rows, offset=0.0):
        rows = np.flatnonzero(rows)  # the plan's rows measured: their pose ids are their row numbers
        design = Design(q[rows] + offset, np.zeros(len(rows)), np.zeros(3), ("t1",), np.array(["iso"] * len(rows)))
        data = simulate(robot, truth, design, np.random.default_rng(0))
        write_measurements(tmp_path / name, robot, replace(data, pose_ids=rows))
        return tmp_path / name

    def refused(plan_file, measured) -> str:
        capsys.readouterr()
        assert main(["iso9283", "robots/puma560.yaml", "--plan", str(plan_file), "--measured", str(measured)]) == 2
        lines = capsys.readouterr().err.splitlines()
        assert len(lines) == 1, lines
        return lines[0]

    everything = run("all.csv", np.ones(len(q), bool))
    assert "target t1 is measured at 10 of the plan's 15 rows (pose 10 is missing)" in \
        refused(tmp_path / "plan.csv", run("two.csv", table["cycle"] <= 2))
    assert "target t1 is measured at 3 of the plan's 15 rows (pose 1 is missing)" in \
        refused(tmp_path / "plan.csv", run("p1.csv", table["point"] == 1))
    assert "(0.2 apart, more than 0.05 rad or m): not a run of this plan" in \
        refused(tmp_path / "plan.csv", run("off.csv", np.ones(len(q), bool), np.array([0.2, 0, 0, 0, 0, 0])))
    for old, new, message in ((",1,5,", ",1,2.7,", "row 3, column 'point': not an integer point number"),
                              ("\n0,", "\n0.5,", "row 2, column 'pose': not an integer pose id"),
                              (",1,5,", ",1,9,", "row 3, column 'point': 9 is not a point of the test (1..5)")):
        (tmp_path / "bad.csv").write_text("\n".join(plan).replace(old, new, 1) + "\n")
        assert message in refused(tmp_path / "bad.csv", everything)


def test_a_simulated_run_of_the_plan_from_the_command_line(tmp_path):
    """The documented way to simulate an ISO 9283 run: the plan's joints through `simulate --commands`
    (pose ids the plan's) are scored as measured; the same plan compensated by a calibration of the
    truth and simulated again scores closer to the commanded poses."""
    robot_file = "robots/industrial6r.yaml"
    run_json("iso9283", robot_file, "-o", tmp_path / "plan.csv", "--tool-rpy", "180,0,0", "--cycles", 3)
    before = run_json("simulate", robot_file, "--commands", tmp_path / "plan.csv", "-o", tmp_path / "run.csv")
    plan = np.genfromtxt(tmp_path / "plan.csv", delimiter=",", names=True)
    run = np.genfromtxt(tmp_path / "run.csv", delimiter=",", names=True, dtype=None, encoding=None)
    assert before["design"] == "commands" and before["poses"] == len(plan)
    assert sorted(set(run["pose"].tolist())) == sorted(plan["pose"].astype(int).tolist())
    run_json("simulate", robot_file, "--poses", 150, "--seed", 3, "-o", tmp_path / "train.csv")
    run_json("identify", robot_file, tmp_path / "train.csv", "-o", tmp_path / "calib.json")
    run_json("compensate", tmp_path / "calib.json", tmp_path / "plan.csv", "-o", tmp_path / "compensated.csv")
    run_json("simulate", robot_file, "--commands", tmp_path / "compensated.csv", "-o", tmp_path / "after.csv",
             "--seed", 1)
    scored = run_json("iso9283", robot_file, "--plan", tmp_path / "plan.csv", "--measured", tmp_path / "run.csv",
                      "--after", tmp_path / "after.csv")
    assert scored["after"]["worst"]["AP_p"] < 0.5 * scored["worst"]["AP_p"]
