"""ISO 9283 (gecgen/plan/iso9283.py, gecgen/verify/iso9283.py): the standard's formulas against hand
computations on small tables, the test cube of the PUMA 560, and a simulated perfect robot."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gecgen.model import load_robot
from gecgen.model.kinematics import tool_poses
from gecgen.model.validation import ModelError
from gecgen.plan.iso9283 import CYCLES, PLANES, command_table, cube_corners, plan_cube, plane_points
from gecgen.verify.iso9283 import distance_characteristics, pose_characteristics

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
#: the tool pointing down (its z along the world's -z), x along the world's x
TOOL_DOWN = np.diag([1.0, -1.0, -1.0])


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def ry(b):
    c, s = np.cos(b), np.sin(b)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rz(c_):
    c, s = np.cos(c_), np.sin(c_)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_pose_characteristics_by_hand():
    # one point, 4 cycles, mm
    commanded = np.array([500, -200, 300])
    attained = np.array([[505, -193, 306],
                         [499, -201, 306],
                         [502, -197, 318],
                         [502, -197, 294]])
    # barycentre: x (505 + 499 + 502 + 502) / 4 = 2008 / 4 = 502, y (-193 - 201 - 197 - 197) / 4 = -788 / 4 = -197,
    # z (306 + 306 + 318 + 294) / 4 = 1224 / 4 = 306
    # AP_x = 502 - 500 = 2, AP_y = -197 + 200 = 3, AP_z = 306 - 300 = 6, AP_p = sqrt(4 + 9 + 36) = 7
    # from the barycentre: (3, 4, 0), (-3, -4, 0), (0, 0, 12), (0, 0, -12): l = 5, 5, 12, 12
    # lbar = (5 + 5 + 12 + 12) / 4 = 8.5; S_l = sqrt((3.5^2 + 3.5^2 + 3.5^2 + 3.5^2) / 3) = sqrt(49 / 3)
    # RP_l = 8.5 + 3 sqrt(49 / 3) = 8.5 + 7 sqrt(3)
    R_c = rz(0.3) @ ry(-0.2) @ rx(1.0)
    # attained orientations: Rz(c_j) Ry(b_j) Rx(a_j) R_c, angles in mrad
    a = [1, 3, -1, 1]  # abar = 4 / 4 = 1; a - abar = 0, 2, -2, 0: S_a = sqrt(8 / 3), RP_a = 3 sqrt(8 / 3) = sqrt(24)
    b = [-1, 0, 1, 4]  # bbar = 4 / 4 = 1; b - bbar = -2, -1, 0, 3: S_b = sqrt(14 / 3), RP_b = sqrt(42)
    c = [0, 0, 0, -4]  # cbar = -4 / 4 = -1; c - cbar = 1, 1, 1, -3: S_c = sqrt(12 / 3) = 2, RP_c = 6
    R = np.stack([rz(cj / 1e3) @ ry(bj / 1e3) @ rx(aj / 1e3) @ R_c for aj, bj, cj in zip(a, b, c)])
    got = pose_characteristics((commanded / 1e3, R_c), (attained / 1e3, R))
    want = dict(AP_p=7, AP_x=2, AP_y=3, AP_z=6, AP_a=1, AP_b=1, AP_c=-1, RP_l=8.5 + 7 * np.sqrt(3),
                RP_a=np.sqrt(24), RP_b=np.sqrt(42), RP_c=6)
    for name, value in want.items():
        assert getattr(got, name) == pytest.approx(value, abs=1e-12), name
    assert got.n == 4


def test_pose_characteristics_positions_only():
    got = pose_characteristics((np.zeros(3), None), (np.array([[0.001, 0, 0], [-0.001, 0, 0]]), None))
    # barycentre at the commanded position; l = 1, 1 mm: lbar = 1, S_l = 0
    assert (got.AP_p, got.RP_l) == pytest.approx((0, 1), abs=1e-12)
    assert np.isnan([got.AP_a, got.AP_b, got.AP_c, got.RP_a, got.RP_b, got.RP_c]).all()
    with pytest.raises(ModelError):
        pose_characteristics((np.zeros(3), None), (np.zeros((1, 3)), None))  # one cycle has no spread


def test_distance_characteristics_by_hand():
    # mm: commanded from (400, 100, 200) to (400, 400, 600): D_c = |(0, 300, 400)| = 500
    cmd_a, cmd_b = np.array([400, 100, 200]), np.array([400, 400, 600])
    att_a = np.array([[401, 100, 199], [400, 102, 200], [399, 99, 201], [402, 100, 200]])
    # attained b - a: |(300, 400, 0)| = 500, |(195, 0, 468)| = sqrt(38025 + 219024) = 507, |(0, 504, 0)| = 504,
    # |(303, 404, 0)| = sqrt(91809 + 163216) = 505
    att_b = att_a + np.array([[300, 400, 0], [195, 0, 468], [0, 504, 0], [303, 404, 0]])
    # Dbar = (500 + 507 + 504 + 505) / 4 = 2016 / 4 = 504; AD_p = 504 - 500 = 4
    # D - Dbar = -4, 3, 0, 1: S_D = sqrt((16 + 9 + 0 + 1) / 3) = sqrt(26 / 3), RD_p = 3 sqrt(26 / 3) = sqrt(78)
    got = distance_characteristics(cmd_a / 1e3, cmd_b / 1e3, att_a / 1e3, att_b / 1e3)
    assert (got.AD_p, got.RD_p, got.D_c, got.D_bar, got.n) == pytest.approx((4, np.sqrt(78), 500, 504, 4), abs=1e-12)


def corner(centre, side, signs):
    """A corner of an axis-aligned cube: signs along x, y, z."""
    return centre + 0.5 * side * np.array(signs, float)


@pytest.mark.parametrize("plane", list(PLANES))
def test_plane_points_geometry(plane):
    centre, side = np.array([0.1, -0.2, 0.3]), 0.4
    # the corner numbering of the module: C1..C4 round the bottom face, C5..C8 above them
    signs = {1: (-1, -1, -1), 2: (1, -1, -1), 3: (1, 1, -1), 4: (-1, 1, -1),
             5: (-1, -1, 1), 6: (1, -1, 1), 7: (1, 1, 1), 8: (-1, 1, 1)}
    C = {k: corner(centre, side, s) for k, s in signs.items()}
    np.testing.assert_allclose(cube_corners(centre, side, np.eye(3)), np.array([C[k] for k in range(1, 9)]))
    P = plane_points(centre, side, np.eye(3), plane)
    k1, k2, k3, k4 = PLANES[plane]
    # a diagonal plane: two opposite edges (k1 k2 and k3 k4) of the cube
    assert np.linalg.norm(C[k1] - C[k2]) == pytest.approx(side)
    assert np.linalg.norm(C[k3] - C[k4]) == pytest.approx(side)
    np.testing.assert_allclose(C[k2] - C[k1], C[k3] - C[k4], atol=1e-15)
    normal = np.cross(C[k2] - C[k1], C[k4] - C[k1])
    np.testing.assert_allclose((P - C[k1]) @ normal, 0, atol=1e-15)
    np.testing.assert_allclose(P[0], centre)
    # each point on its diagonal (k1-k3, k2-k4), 10 % of that diagonal's length (side sqrt(3)) from its corner
    for point, near, far in zip(P[1:], (k1, k2, k3, k4), (k3, k4, k1, k2)):
        np.testing.assert_allclose(point, C[near] + 0.1 * (C[far] - C[near]), atol=1e-15)
        assert np.linalg.norm(point - C[near]) == pytest.approx(0.1 * side * np.sqrt(3), abs=1e-15)


@pytest.fixture(scope="module")
def puma():
    return load_robot(ROBOTS / "puma560.yaml")


@pytest.fixture(scope="module")
def plan(puma):
    return plan_cube(puma, TOOL_DOWN)


def test_plan_cube_puma(puma, plan):
    assert plan.side_m > 0 and plan.cycles == CYCLES == 30 and plan.plane == "C1-C2-C7-C8"
    assert plan.q.shape == (5, puma.n) and plan.corner_q.shape == (8, puma.n)
    lower, upper = np.array([j.lower for j in puma.joints]), np.array([j.upper for j in puma.joints])
    for q, points in ((plan.q, plan.points), (plan.corner_q, plan.corners)):
        T = tool_poses(puma, q)[0]
        assert np.abs(T[:, :3, 3] - points).max() < 1e-9
        assert np.abs(T[:, :3, :3] - TOOL_DOWN).max() < 1e-9
        assert ((q >= lower) & (q <= upper)).all()
    # the points on the plane C1-C2-C7-C8, 10 % of a diagonal from C1, C2, C7, C8
    centre, side = plan.centre, plan.side_m
    C1, C2 = corner(centre, side, (-1, -1, -1)), corner(centre, side, (1, -1, -1))
    C7, C8 = corner(centre, side, (1, 1, 1)), corner(centre, side, (-1, 1, 1))
    np.testing.assert_allclose(plan.corners[[0, 1, 6, 7]], [C1, C2, C7, C8], atol=1e-15)
    normal = np.cross(C2 - C1, C8 - C1)
    np.testing.assert_allclose((plan.points - C1) @ normal, 0, atol=1e-15)
    np.testing.assert_allclose(plan.points[0], centre)
    diagonal = side * np.sqrt(3)
    for point, near in zip(plan.points[1:], (C1, C2, C7, C8)):
        assert np.linalg.norm(point - near) == pytest.approx(0.1 * diagonal, abs=1e-12)
        assert np.linalg.norm(point - centre) == pytest.approx(0.4 * diagonal, abs=1e-12)


def test_command_table(puma, plan):
    columns, rows = command_table(plan)
    assert columns == ("cycle", "point", "q1", "q2", "q3", "q4", "q5", "q6")
    assert rows.shape == (30 * 5, 8)
    np.testing.assert_array_equal(rows[:10, :2], [[1, 1], [1, 5], [1, 4], [1, 3], [1, 2],
                                                  [2, 1], [2, 5], [2, 4], [2, 3], [2, 2]])
    np.testing.assert_array_equal(rows[:, 2:], plan.q[rows[:, 1].astype(int) - 1])


def test_refusals(puma):
    with pytest.raises(ModelError, match="rotation"):
        plan_cube(puma, np.eye(3) * 2)
    with pytest.raises(ModelError, match="plane"):
        plan_cube(puma, TOOL_DOWN, plane="C1-C2-C3-C4")


def test_a_cube_out_of_reach_of_four_joints_says_why(tmp_path):
    """PUMA's first four joints alone cannot hold the tool in one orientation over a cube: the refusal
    counts the joints (once it only suggested another orientation, in the API's words)."""
    import yaml

    spec = yaml.safe_load((ROBOTS / "puma560.yaml").read_text())
    spec["joints"] = spec["joints"][:4]
    (tmp_path / "arm4.yaml").write_text(yaml.safe_dump(spec))
    with pytest.raises(ModelError, match=r"none of 32 candidate centres is reached with the tool \(moved by 4 joints: "
                                         r"fewer than 6 hold one orientation over a cube only by design\)"):
        plan_cube(load_robot(tmp_path / "arm4.yaml"), TOOL_DOWN)


def test_perfect_robot_with_repeatability_noise(puma, plan):
    """The commanded joints of every cycle, the tool where the nominal chain puts it plus Gaussian noise:
    sigma per coordinate in position, per axis (a small world-frame turn) in orientation."""
    rng = np.random.default_rng(7)
    sigma, sigma_rad = 20e-6, 50e-6
    _, rows = command_table(plan)
    T = tool_poses(puma, rows[:, 2:])[0]
    xyz = T[:, :3, 3] + rng.normal(0, sigma, (len(rows), 3))
    turn = rng.normal(0, sigma_rad, (len(rows), 3))
    R = np.stack([rz(t[2]) @ ry(t[1]) @ rx(t[0]) @ Rk for t, Rk in zip(turn, T[:, :3, :3])])
    for k in range(5):
        at = rows[:, 1] == k + 1
        got = pose_characteristics((plan.points[k], plan.tool_rotation), (xyz[at], R[at]))
        assert got.n == 30
        # the barycentre's error is sigma / sqrt(30) per coordinate
        assert got.AP_p < 1e3 * 3 * sigma * np.sqrt(3) / np.sqrt(30)
        l = np.linalg.norm(xyz[at] - xyz[at].mean(axis=0), axis=1)
        assert got.RP_l == pytest.approx(1e3 * (l.mean() + 3 * l.std(ddof=1)), abs=1e-12)
        # the angles are the turns themselves (extrinsic xyz), their sample standard deviation about sigma_rad
        np.testing.assert_allclose([got.RP_a, got.RP_b, got.RP_c], 1e3 * 3 * turn[at].std(axis=0, ddof=1), atol=1e-9)
        assert 0.6 * 3e3 * sigma_rad < min(got.RP_a, got.RP_b, got.RP_c)
        assert max(got.RP_a, got.RP_b, got.RP_c) < 1.4 * 3e3 * sigma_rad
        assert max(abs(got.AP_a), abs(got.AP_b), abs(got.AP_c)) < 1e3 * 4 * sigma_rad / np.sqrt(30)
