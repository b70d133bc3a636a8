"""Initial guesses of the TIAGo marker points on the hand (robots/tiago.yaml targets).

    python scripts/tiago_marker_guess.py

The marker body's placement on the hand is not recorded, and the motion-capture frame is an
unknown rigid transform X from the robot base. On the training file only, with the nominal
kinematics, solve y_ik = X T_i m_k for X and the four points m_k by nonlinear least squares from
several starting rotations; print the points (arm_7_link frame, mm resolution). These are only
starting values: identification then fits frame 7's errors (and the registration) properly.
"""
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from gecgen.model import load_robot
from gecgen.model.kinematics import tool_pose
from gecgen.model.wide import import_wide, load_mapping

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "tiago-mocap" / "train_2021-11-30.csv"


def main():
    robot = load_robot(ROOT / "robots" / "tiago.yaml")
    data = import_wide(DATA, robot, load_mapping(ROOT / "robots" / "tiago.import.yaml", robot))
    T = tool_pose(robot, data.q)
    y = data.xyz.reshape(data.n_poses, -1, 3)

    def residual(x):
        R, t, m = Rotation.from_rotvec(x[:3]).as_matrix(), x[3:6], x[6:].reshape(-1, 3)
        p = np.einsum("nij,kj->nki", T[:, :3, :3], m) + T[:, None, :3, 3]
        return (p @ R.T + t - y).ravel()

    best = None
    for start in Rotation.create_group("O").as_rotvec():  # the 24 axis-aligned rotations
        x0 = np.concatenate([start, y.mean((0, 1)), np.zeros(12)])
        sol = least_squares(residual, x0)
        if best is None or sol.cost < best.cost:
            best = sol
    rms = np.sqrt(np.mean(best.fun.reshape(-1, 3) ** 2) * 3)
    print(f"rms point error with the nominal model: {1e3 * rms:.2f} mm")
    for k, m in enumerate(best.x[6:].reshape(-1, 3), 1):
        print(f"  m{k}: [{m[0]:.4f}, {m[1]:.4f}, {m[2]:.4f}]")


if __name__ == "__main__":
    main()
