"""URDF robots: the chain against an independent composition of the URDF transforms, J_e against
finite differences (symbolic and compiled C), and malformed URDFs refused with one line."""
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import ROBOTS, random_q
from scipy.spatial.transform import Rotation
from test_symbolic import fd_jacobian

from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import frames, target_positions
from gecgen.runtime.compiled import CompiledModel
from gecgen.symbolic.chain import jacobian_function


@dataclass(frozen=True)
class UJ:
    """One URDF joint of the synthetic arm: axis None means the URDF default (x); limits None, no <limit>."""

    name: str
    type: str
    parent: str
    child: str
    xyz: tuple
    rpy: tuple
    axis: tuple | None = None
    limits: tuple | None = None


# world -> (fixed) -> j1 revolute -> (fixed between two moving joints) -> j2 continuous about a skew,
# unnormalised axis -> j3 prismatic along -y -> j4 revolute about the default x -> (fixed) -> tool.
# `side` hangs off link2 by a floating joint: off the path, so it must not matter.
ARM = (
    UJ("mount", "fixed", "world", "base", (0.1, -0.2, 0.3), (0.1, 0.2, 0.3)),
    UJ("j1", "revolute", "base", "link1", (0.0, 0.0, 0.4), (0.0, 0.0, 0.5), (0, 0, 1), (-2.5, 2.5)),
    UJ("flange", "fixed", "link1", "link1_flange", (0.05, 0.02, 0.1), (-0.4, 0.3, 0.2)),
    UJ("j2", "continuous", "link1_flange", "link2", (0.3, 0.0, 0.0), (1.5707963267948966, 0.0, 0.0), (1, 2, -2)),
    UJ("j3", "prismatic", "link2", "link3", (0.0, 0.25, 0.02), (0.0, -0.7, 0.0), (0, -1, 0), (0.0, 0.5)),
    UJ("j4", "revolute", "link3", "link4", (0.1, 0.0, 0.2), (0.3, -0.2, 1.1), None, (-1.5, 1.5)),
    UJ("tool_mount", "fixed", "link4", "tool", (0.0, 0.0, 0.12), (0.0, 0.25, 0.0)),
    UJ("side_joint", "floating", "link2", "side", (0.2, 0.0, 0.0), (0.0, 0.0, 0.0)),
)
TARGETS = {"a": (0.05, 0.0, 0.1), "b": (0.0, -0.08, 0.03)}
MOVING = [j for j in ARM if j.type in ("revolute", "continuous", "prismatic")]


def urdf_text(arm=ARM) -> str:
    links = dict.fromkeys(link for j in arm for link in (j.parent, j.child))
    lines = ['<?xml version="1.0"?>', '<robot name="arm">']
    lines += [f'  <link name="{link}"><inertial><mass value="1"/></inertial></link>' for link in links]
    for j in arm:
        lines.append(f'  <joint name="{j.name}" type="{j.type}">')
        lines.append(f'    <parent link="{j.parent}"/>')
        lines.append(f'    <child link="{j.child}"/>')
        lines.append(f'    <origin xyz="{" ".join(map(repr, j.xyz))}" rpy="{" ".join(map(repr, j.rpy))}"/>')
        if j.axis is not None:
            lines.append(f'    <axis xyz="{" ".join(map(str, j.axis))}"/>')
        if j.limits is not None:
            lines.append(f'    <limit lower="{j.limits[0]!r}" upper="{j.limits[1]!r}" effort="10" velocity="1"/>')
        lines.append("  </joint>")
    # transmissions name joints too; they are not part of the tree
    lines += ['  <transmission name="t1"><joint name="j1"/></transmission>', "</robot>"]
    return "\n".join(lines) + "\n"


def write_robot(folder, urdf: str, base_link="world", tip_link="tool"):
    (folder / "arm.urdf").write_text(urdf)
    targets = "".join(f"  {k}: {list(v)}\n" for k, v in TARGETS.items())
    path = folder / "arm.yaml"
    path.write_text(f"name: arm\nangle_unit: rad\nurdf: arm.urdf\nbase_link: {base_link}\ntip_link: {tip_link}\ntargets:\n{targets}")
    return path


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    return load_robot(write_robot(tmp_path_factory.mktemp("urdf"), urdf_text()))


# -- the independent reference: compose the URDF transforms link by link --------------------------
def homogeneous(R=np.eye(3), p=(0.0, 0.0, 0.0)) -> np.ndarray:
    H = np.eye(4)
    H[:3, :3], H[:3, 3] = R, p
    return H


def elementary_rotation(axis: int, angle: float) -> np.ndarray:
    return Rotation.from_rotvec(angle * np.eye(3)[axis]).as_matrix()


def urdf_origin(xyz, rpy) -> np.ndarray:
    """Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)."""
    roll, pitch, yaw = rpy
    return homogeneous(elementary_rotation(2, yaw) @ elementary_rotation(1, pitch) @ elementary_rotation(0, roll), xyz)


def urdf_motion(joint: UJ, q: float) -> np.ndarray:
    u = np.array(joint.axis if joint.axis is not None else (1, 0, 0), float)
    u /= np.linalg.norm(u)
    if joint.type == "prismatic":
        return homogeneous(p=q * u)
    return homogeneous(Rotation.from_rotvec(q * u).as_matrix())


def link_poses(q) -> dict[str, np.ndarray]:
    """World pose of every link on the path at joint values q (one per moving joint, in order)."""
    value = dict(zip([j.name for j in MOVING], q))
    pose = {"world": np.eye(4)}
    for j in ARM:
        if j.type != "floating":
            motion = urdf_motion(j, value[j.name]) if j.name in value else np.eye(4)
            pose[j.child] = pose[j.parent] @ urdf_origin(j.xyz, j.rpy) @ motion
    return pose


# -- (a) the chain --------------------------------------------------------------------------------
def test_urdf_joints_types_axes_and_limits(arm):
    assert arm.joint_names == ("j1", "j2", "j3", "j4")
    assert [j.kind for j in arm.joints] == ["R", "R", "P", "R"]
    np.testing.assert_allclose([float(a) for a in arm.joints[1].axis], np.array([1, 2, -2]) / 3, rtol=1e-15)
    assert [tuple(j.axis) for j in (arm.joints[0], arm.joints[2], arm.joints[3])] == [(0, 0, 1), (0, -1, 0), (1, 0, 0)]
    assert [(j.lower, j.upper) for j in arm.joints] == [(-2.5, 2.5), (-np.inf, np.inf), (0.0, 0.5), (-1.5, 1.5)]


def test_chain_matches_independent_composition_of_urdf_transforms(arm, rng):
    for q in [np.zeros(arm.n), *random_q(arm, rng, 4)]:
        pose = link_poses(q)
        W = [F[0] for F in frames(arm, q)]
        j1 = MOVING[0]
        # frame 0 is the first joint's frame at zero; frame i the child link of moving joint i
        np.testing.assert_allclose(W[0], pose[j1.parent] @ urdf_origin(j1.xyz, j1.rpy), atol=1e-14)
        for i, joint in enumerate(MOVING, start=1):
            np.testing.assert_allclose(W[i], pose[joint.child], atol=1e-14)
        np.testing.assert_allclose(W[-1], pose["tool"], atol=1e-14)
        expected = [pose["tool"][:3, :3] @ t + pose["tool"][:3, 3] for t in TARGETS.values()]
        np.testing.assert_allclose(target_positions(arm, q)[0], expected, atol=1e-14)


# -- (b) J_e --------------------------------------------------------------------------------------
@pytest.fixture(scope="module", params=["synthetic arm", "tiago"])
def urdf_robot(request, arm):
    return arm if request.param == "synthetic arm" else load_robot(ROBOTS / "tiago.yaml")


@pytest.mark.parametrize("scale", [0.0, 0.02])
def test_J_e_symbolic_and_compiled_match_finite_differences(urdf_robot, rng, scale):
    robot = urdf_robot
    fn = jacobian_function(robot)
    cm = CompiledModel(robot, load_error_model(None, robot), backend="c")
    for q in random_q(robot, rng, 3):
        eps = rng.normal(0, scale, robot.n_errors)
        fd = fd_jacobian(robot, q, eps)
        assert np.abs(fd).max() > 0.1  # the check is not vacuous
        out = fn.evaluate(q=q, eps=eps)
        np.testing.assert_allclose(out["p"], target_positions(robot, q, eps).ravel(), atol=1e-14)
        np.testing.assert_allclose(out["J"].reshape(-1, robot.n_errors), fd, atol=1e-8)
        p, J = cm.J_e(q, eps)
        np.testing.assert_allclose(p[0], target_positions(robot, q, eps)[0], atol=1e-14)
        np.testing.assert_allclose(J[0], fd, atol=1e-8)


def test_tiago_loads_with_torso_and_seven_arm_joints():
    tiago = load_robot(ROBOTS / "tiago.yaml")
    assert tiago.joint_names == ("torso_lift_joint", *[f"arm_{k}_joint" for k in range(1, 8)])
    assert [j.kind for j in tiago.joints] == ["P"] + ["R"] * 7
    assert list(tiago.targets) == ["m1", "m2", "m3", "m4"]


# -- (c) malformed URDFs --------------------------------------------------------------------------
def replaced(old: str, new: str) -> str:
    text = urdf_text()
    assert text.count(old) == 1, old
    return text.replace(old, new)


def retyped(name: str, new_type: str) -> str:
    return replaced(f'<joint name="{name}" type="', f'<joint name="{name}" type="{new_type}" x="')


MALFORMED = {
    "missing base link": (urdf_text(), {"base_link": "nowhere"}, "base_link 'nowhere' is not a link"),
    "joint names a missing link": (replaced('<child link="link3"/>', '<child link="ghost"/>'), {},
                                   "joint 'j3': child link 'ghost' is not a <link>"),
    "tip above base": (urdf_text(), {"base_link": "link2", "tip_link": "link1"}, "'link1' is not below base_link"),
    "tip on another branch": (urdf_text(), {"base_link": "link3", "tip_link": "side"}, "'side' is not below"),
    "cycle of links": (replaced("</robot>", '<joint name="loop" type="fixed"><parent link="tool"/>'
                                            '<child link="world"/></joint></robot>'),
                       {"base_link": "side"}, "joint 'mount': link 'base' is its own ancestor"),
    "floating joint on the path": (retyped("j3", "floating"), {}, "joint 'j3': type 'floating' is not supported"),
    "planar joint on the path": (retyped("j2", "planar"), {}, "joint 'j2': type 'planar' is not supported"),
    "revolute without limits": (replaced('<limit lower="-1.5" upper="1.5" effort="10" velocity="1"/>', ""), {},
                                "joint 'j4': a revolute joint needs <limit"),
    "limit without upper": (replaced('<limit lower="0.0" upper="0.5"', '<limit lower="0.0"'), {},
                            "joint 'j3': a prismatic joint needs <limit"),
    "limits reversed": (replaced('lower="-2.5" upper="2.5"', 'lower="2.5" upper="-2.5"'), {},
                        "joint 'j1': limit lower 2.5 must be below upper -2.5"),
    "xyz with a word": (replaced('xyz="0.0 0.0 0.4"', 'xyz="0.0 0.0 0.4m"'), {},
                        "joint 'j1' origin xyz: '0.4m' is not a number"),
    "xyz with two numbers": (replaced('xyz="0.0 0.25 0.02"', 'xyz="0.0 0.25"'), {},
                             "joint 'j3' origin xyz: expected three numbers"),
    "xyz not finite": (replaced('xyz="0.1 0.0 0.2"', 'xyz="0.1 nan 0.2"'), {},
                       "joint 'j4' origin xyz: 'nan' is not finite"),
    "zero axis": (replaced('<axis xyz="0 -1 0"/>', '<axis xyz="0 0 0"/>'), {}, "joint 'j3': axis must not be zero"),
    "mimic of a floating joint": (replaced('<child link="link4"/>', '<child link="link4"/><mimic joint="side_joint"/>'),
                                  {}, "joint 'j4' mimics joint 'side_joint', a floating joint; a mimic joint follows"),
    "not XML": (urdf_text().replace("</robot>", ""), {}, "not valid XML"),
}


@pytest.mark.parametrize("case", MALFORMED)
def test_malformed_urdf_is_refused_with_one_line(tmp_path, case):
    urdf, links, expect = MALFORMED[case]
    with pytest.raises(ModelError) as err:
        load_robot(write_robot(tmp_path, urdf, **links))
    message = str(err.value)
    assert expect in message and "arm.urdf" in message and "\n" not in message, message
