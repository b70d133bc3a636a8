"""`gecgen iso9283`: the pose test planned as joint commands, and its characteristics from the measured
cycles (gecgen/cli/iso9283.py), against the standard's formulas computed here with numpy."""
from __future__ import annotations


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
    reported = run_json("iso9283", "robots/puma560.yaml", "--plan", tmp_path / "plan.csv", "--measured",
                    tmp_path / "run.csv", "--after", tmp_path / "after.csv", "--report", tmp_path / "report")
    text = (tmp_path / "report" / "report.md").read_text()
    assert "After compensation" in text and f"{out['worst']['AP_p']:.3g}" in text and "P2-P4" in text
    assert (tmp_path / "report" / "report.html").stat().st_size > 0 and reported["report"].endswith("report.md")
