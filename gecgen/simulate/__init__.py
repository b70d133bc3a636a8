"""Simulated measurements of truth robots: data with known truth for trials and tests.

    data = simulate(robot, truth, design, rng)

gives what a laser tracker would record: the exact nonlinear chain at the true joints and
generalized errors of every pose (`truth.true_state`), per-pose repeatability and per-point
tracker noise, and the wrench a force/torque sensor in the robot's wrench frame reads; with
`orientation`, what a 6-D probe or a camera rig records too: the orientation of the tool frame
at every measured target, with the truth's orientation noise.
"""
from __future__ import annotations

import numpy as np

from gecgen.model.kinematics import sensor_wrench, target_positions, tool_pose, tool_poses
from gecgen.model.measurements import Measurements
from gecgen.model.robot import Robot
from gecgen.simulate.designs import (Design, approach_directions, joined, one_at_a_time, paper_pps, paper_split,
                                     random_design)
from gecgen.simulate.truth import Truth, load_truth, thermal_profile, true_state

__all__ = ["Design", "Truth", "joined", "load_truth", "one_at_a_time", "paper_data", "paper_pps", "paper_split",
           "random_design", "simulate", "true_tool_points"]


def simulate(robot: Robot, truth: Truth, design: Design, rng: np.random.Generator,
             orientation: bool = False) -> Measurements:
    """Measurements of `design` on the truth robot, in the contract's layout; with `orientation`
    every row also gives the measured orientation of its target's frame (the true tool
    orientation turned by a random rotation vector of truth.orientation rad per axis)."""
    N = design.n_poses
    aux = thermal_profile(truth, N)
    robot = truth.robot or robot  # the robot as built: its couplings may differ from the file's
    q_true, eps = true_state(robot, truth, design.q, design.payload_kg, design.payload_at, aux,
                             approach_directions(design.q))
    wrench = sensor_wrench(robot, q_true, design.payload_kg, design.payload_at, truth.gravity, eps)
    names = list(robot.targets)
    targets = np.array([names.index(t) for t in design.targets])
    y = target_positions(robot, q_true, eps)[:, targets]  # (N, nt_measured, 3)
    y = y + rng.normal(0.0, truth.repeatability, (N, 1, 3)) + rng.normal(0.0, truth.tracker, y.shape)
    pose = np.repeat(np.arange(N), len(targets))
    measured = None
    if orientation:
        # here, not at the top: scipy's rotations cost a tenth of a second of start-up, and only pose
        # data needs them (`design` imports this package for its candidates)
        from scipy.spatial.transform import Rotation

        tools = np.stack(tool_poses(robot, q_true, eps))  # (branches, N, 4, 4): each row's target's tool
        R = tools[[robot.branch_of(names[t]) for t in np.tile(targets, N)], pose, :3, :3]
        measured = Rotation.from_rotvec(rng.normal(0.0, truth.orientation, (len(pose), 3))).as_matrix() @ R
    aux_names = tuple(aux)
    return Measurements(q=design.q, w=wrench, aux=np.column_stack([aux[a] for a in aux_names]) if aux_names
                        else np.zeros((N, 0)), aux_names=aux_names, pose_ids=np.arange(N), pose=pose,
                        target=np.tile(targets, N), xyz=y.reshape(-1, 3), source="simulated", orientation=measured)


def paper_data(robot: Robot, truth: Truth, rng: np.random.Generator) -> tuple[Measurements, Measurements]:
    """The seed paper's PPS design (`paper_pps`) measured on the truth robot and split as the paper
    splits it (`paper_split`): (training, validation) measurements."""
    design = paper_pps(robot)
    data = simulate(robot, truth, design, rng)
    train, val = paper_split(design, rng)
    return data.subset(train), data.subset(val)


def true_tool_points(robot: Robot, truth: Truth, q: np.ndarray, payload_kg: np.ndarray, payload_at: np.ndarray,
                     points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the truth robot puts tool-frame points (N, 3) when its joints read q (N, n) under payloads
    (N,) kg at payload_at (3,), m, and the wrench (N, 6) its sensor reads there: its systematic error
    only, without repeatability or tracker noise (what an accuracy statement is about). Every joint
    is taken as approached from below."""
    robot = truth.robot or robot
    q_true, eps = true_state(robot, truth, q, payload_kg, payload_at, {}, np.ones_like(q))
    T = tool_pose(robot, q_true, eps)
    return (np.einsum("nij,nj->ni", T[:, :3, :3], points) + T[:, :3, 3],
            sensor_wrench(robot, q_true, payload_kg, payload_at, truth.gravity, eps))
