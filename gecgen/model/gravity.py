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

from gecgen.model.kinematics import frames, joint_motion, joint_values
from gecgen.model.robot import GRAVITY, Robot
from gecgen.model.urdf import MassTree, load_mass_tree
from gecgen.model.validation import require

#: standard gravity in the base link's frame when the robot stands upright (z up), m/s^2
UPRIGHT = tuple(float(v) for v in GRAVITY)
#: postures per block: every link's transforms are held for a block, a few MB whatever the table's length
BLOCK = 2048


def _walk(tree: MassTree, q: dict[str, np.ndarray], gravity) -> tuple[dict, dict, dict, dict]:
    """One pass down the tree at joints q (name -> (P,); others at zero, mimic joints at their offset):
    per link its world pose (P, 4, 4), the joint frame before its motion (`placed`: the joint's
    position and axis live there), and the mass (kg) and first moment of mass (P, 3; sum m c, world)
    of the subtree it heads."""
    P = len(next(iter(q.values())))
    world = {tree.links[0]: np.broadcast_to(np.eye(4), (P, 4, 4))}
    placed = {}
    for link in tree.links[1:]:
        j = tree.joint[link]
        placed[link] = world[tree.parent[link]] @ j.origin
        world[link] = placed[link] if j.kind == "F" else placed[link] @ joint_motion(j.axis, j.kind, j.value(q, P))
    M = {link: tree.mass.get(link, 0.0) for link in tree.links}
    S = {link: M[link] * (world[link][:, :3, :3] @ tree.com.get(link, np.zeros(3)) + world[link][:, :3, 3])
         for link in tree.links}
    for link in reversed(tree.links[1:]):  # leaves first
        M[tree.parent[link]] += M[link]
        S[tree.parent[link]] = S[tree.parent[link]] + S[link]
    return world, placed, M, S


def transmitted_wrenches(tree: MassTree, q: dict[str, np.ndarray], links: list[str], gravity=UPRIGHT) -> np.ndarray:
    """The static gravity wrench (P, len(links), 6) that each of `links` and everything below it put
    on the joint above it: force (N) and moment about the link's origin (N m), in the link's axes
    (for a URDF joint: its child frame, whose origin lies on the axis); the opposite of what
    pinocchio's static RNEA calls the force the joint transmits (`data.f`). q, gravity as for
    `gravity_torques`."""
    world, _, M, S = _walk(tree, q, gravity)
    g = np.asarray(gravity, float)
    out = []
    for link in links:
        R, p = world[link][:, :3, :3], world[link][:, :3, 3]
        force, moment = M[link] * np.broadcast_to(g, p.shape), np.cross(S[link] - M[link] * p, g)
        out.append(np.concatenate([np.einsum("pji,pj->pi", R, force), np.einsum("pji,pj->pi", R, moment)], axis=1))
    return np.stack(out, axis=1)


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
    _, placed, M, S = _walk(tree, q, gravity)
    g = np.asarray(gravity, float)

    def own(link: str) -> np.ndarray:
        """The load about/along the joint above `link` of everything below it."""
        axis = placed[link][:, :3, :3] @ tree.joint[link].axis
        if tree.joint[link].kind == "P":
            return M[link] * axis @ g
        arm = S[link] - M[link] * placed[link][:, :3, 3]  # sum over the subtree of (c - p) x m g = (S - M p) x g
        return np.einsum("pi,pi->p", axis, np.cross(arm, g))

    out = np.zeros((len(next(iter(q.values()))), len(joints)))
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


def _chain_values(robot: Robot, q: np.ndarray) -> dict[str, np.ndarray]:
    """The URDF joints' values at readings q (P, n): every chain joint's, through the robot file's
    couplings (a URDF mimic joint follows its root in the walk itself)."""
    values = joint_values(robot, q)
    return {j.name: values[:, i] for i, j in enumerate(robot.chain) if not (j.coupling and not j.coupling.declared)}


def robot_gravity_torques(robot: Robot, q: np.ndarray, joints: list[str], gravity=None) -> np.ndarray:
    """`gravity_torques` of a robot built from a URDF, q (P, n) in robot order, joints by name;
    gravity in the base link's frame (default: the robot file's `gravity`). A reading that the robot
    file's couplings tie to other joints carries their loads too, by virtual work: tau_J = sum over
    the frames k it moves of dv_k/dq_J tau_k."""
    require(robot.urdf, f"{robot.source}: gravity torques need the link masses of a URDF; this robot file "
                        f"gives DH rows without masses (build the robot from its URDF)")
    tree = load_mass_tree(robot.urdf, robot.base_link)
    gravity = base_link_gravity(robot, tree) if gravity is None else gravity
    declared = [(i, [(robot.chain[k - 1].name, float(m)) for k, m in robot.driven(i)
                     if not (robot.chain[k - 1].coupling and not robot.chain[k - 1].coupling.declared)])
                for i in (robot.joint_names.index(name) if name in robot.joint_names else None for name in joints)]
    frames_needed = list(dict.fromkeys(name for i, moved in declared if i is not None for name, _ in moved))
    own = [name for name in joints if name not in robot.joint_names] + frames_needed

    def block(qb: np.ndarray) -> np.ndarray:
        tau = dict(zip(own, gravity_torques(tree, _chain_values(robot, qb), own, gravity).T))
        return np.column_stack([tau[name] if i is None else sum(m * tau[k] for k, m in moved)
                                for name, (i, moved) in zip(joints, declared)])
    return np.concatenate([block(q[s:s + BLOCK]) for s in range(0, len(q), BLOCK)])


def robot_frame_wrenches(robot: Robot, q: np.ndarray, frames: list[int], gravity=None) -> np.ndarray:
    """The static gravity wrench (P, len(frames), 6) that each chain frame (0..m, passive joints'
    too; 0 the base link) carries, from the URDF's masses at readings q (P, n): `transmitted_wrenches` of the frame's
    joint's child link (N, N m; in the frame's axes, about its origin). gravity as for
    robot_gravity_torques."""
    require(robot.urdf, f"{robot.source}: gravity wrenches need the link masses of a URDF; this robot file "
                        f"gives DH rows without masses (build the robot from its URDF)")
    tree = load_mass_tree(robot.urdf, robot.base_link)
    gravity = base_link_gravity(robot, tree) if gravity is None else gravity
    child = {j.name: link for link, j in tree.joint.items()}
    links = [child[robot.chain[f - 1].name] if f else tree.links[0] for f in frames]  # frame 0: the base link
    return np.concatenate([transmitted_wrenches(tree, _chain_values(robot, q[s:s + BLOCK]), links, gravity)
                           for s in range(0, len(q), BLOCK)])
