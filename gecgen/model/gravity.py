"""Static gravity torques on the joints of a URDF robot: the load signal of elastic errors.

The seed paper's elastic errors are linear in the measured wrench. A robot measured without a
force sensor is loaded all the same: every link's weight pulls on every joint above it, and a
compliant joint (harmonic drive, belt, long gear train) turns by an angle that grows with that
torque. The torque is not measured but known from the URDF's `<inertial>` masses and the joint
readings, so it can be written next to the joints as an auxiliary column `tau_<joint>` and used
by error terms (`er: ["1", tau_arm_2_joint]`, a joint stiffness) and by `gecgen diagnose`.

Convention: the torque (N m) gravity exerts about the joint's +axis, for a prismatic joint the
force (N) along it; tau_i = -dV/dq_i with V the potential energy, which the tests check. Every
link below the joint counts, branches off the chain included (a gripper's fingers, a camera), with
their own moving joints held at zero. The nominal kinematics is used: the millimetres a
calibration corrects change the torques far less than the uncertainty of the masses themselves.
"""
from __future__ import annotations

import numpy as np

from gecgen.model.kinematics import frames, joint_motion
from gecgen.model.robot import Robot
from gecgen.model.urdf import MassTree, load_mass_tree
from gecgen.model.validation import require

#: standard gravity in the base link's frame when the robot stands upright (z up), m/s^2
UPRIGHT = (0.0, 0.0, -9.80665)
#: postures per block: every link's transforms are held for a block, a few MB whatever the table's length
BLOCK = 2048


def gravity_torques(tree: MassTree, q: dict[str, np.ndarray], joints: list[str],
                    gravity=UPRIGHT) -> np.ndarray:
    """Torque (N m) or force (N) of gravity about/along each of `joints`, (P, len(joints)).

    q: joint name -> readings (P,) for the joints that move (others are held at zero, their mimic
    joints at the offset); gravity: the acceleration (m/s^2) in the base link's frame. A joint's
    mimic joints move with it, so their loads act on it through the multiplier (virtual work:
    tau_J = sum over the joints k it moves of dq_k/dq_J tau_k)."""
    by_joint = {j.name: link for link, j in tree.joint.items() if j.kind != "F"}
    for name in joints:
        link = by_joint.get(name)
        mimic = tree.joint[link].mimic if link else None
        require(mimic is None, f"{tree.source}: joint '{name}' mimics joint '{mimic.root if mimic else ''}', whose "
                               f"torque includes its load (times the multiplier); name '{mimic.root if mimic else ''}'")
        require(link, f"{tree.source}: '{name}' is not a moving joint below the base link; "
                      f"name one of {', '.join(n for n, k in by_joint.items() if tree.joint[k].mimic is None)}")
    P = len(next(iter(q.values())))
    g = np.asarray(gravity, float)
    world = {tree.links[0]: np.broadcast_to(np.eye(4), (P, 4, 4))}
    placed = {}  # link -> the joint frame before its motion: the joint's position and axis live there
    for link in tree.links[1:]:
        j = tree.joint[link]
        placed[link] = world[tree.parent[link]] @ j.origin
        world[link] = placed[link] if j.kind == "F" else placed[link] @ joint_motion(j.axis, j.kind, j.value(q, P))
    # mass and first moment of mass (sum m * c, world) of every subtree, leaves first
    M = {link: tree.mass.get(link, 0.0) for link in tree.links}
    S = {link: M[link] * (world[link][:, :3, :3] @ tree.com.get(link, np.zeros(3)) + world[link][:, :3, 3])
         for link in tree.links}
    for link in reversed(tree.links[1:]):
        M[tree.parent[link]] += M[link]
        S[tree.parent[link]] = S[tree.parent[link]] + S[link]

    def own(link: str) -> np.ndarray:
        """The load about/along the joint above `link` of everything below it."""
        axis = placed[link][:, :3, :3] @ tree.joint[link].axis
        if tree.joint[link].kind == "P":
            return M[link] * axis @ g
        arm = S[link] - M[link] * placed[link][:, :3, 3]  # sum over the subtree of (c - p) x m g = (S - M p) x g
        return np.einsum("pi,pi->p", axis, np.cross(arm, g))

    out = np.zeros((P, len(joints)))
    for k, name in enumerate(joints):
        moved = [(by_joint[name], 1.0)] + [(link, j.mimic.multiplier) for link, j in tree.joint.items()
                                           if j.mimic is not None and j.mimic.root == name]
        require(any(M[link] > 0 for link, _ in moved), f"{tree.source}: no link below joint '{name}' has a mass; "
                                                       f"give the links' <inertial> masses or leave the joint out")
        for link, multiplier in moved:
            out[:, k] += own(link) if multiplier == 1.0 else multiplier * own(link)
    return out


def base_link_gravity(robot: Robot, tree: MassTree) -> np.ndarray:
    """The robot file's `gravity` (world, m/s^2) in the URDF base link's frame, (3,): the world is the
    base link's frame turned by the file's `base`. Joint 1's child link sits at the chain's frame 1."""
    link1 = next(link for link, j in tree.joint.items() if j.name == robot.chain[0].name)
    world = frames(robot, np.zeros((1, robot.n)))[1][0] @ np.linalg.inv(tree.rest_poses()[link1])
    return world[:3, :3].T @ np.array([float(v) for v in robot.gravity])


def robot_gravity_torques(robot: Robot, q: np.ndarray, joints: list[str], gravity=None) -> np.ndarray:
    """`gravity_torques` of a robot built from a URDF, q (P, n) in robot order, joints by name;
    gravity in the base link's frame (default: the robot file's `gravity`)."""
    require(robot.urdf, f"{robot.source}: gravity torques need the link masses of a URDF; this robot file "
                        f"gives DH rows without masses (build the robot from its URDF)")
    tree = load_mass_tree(robot.urdf, robot.base_link)
    gravity = base_link_gravity(robot, tree) if gravity is None else gravity
    return np.concatenate([gravity_torques(tree, dict(zip(robot.joint_names, q[s:s + BLOCK].T)), joints, gravity)
                           for s in range(0, len(q), BLOCK)])
