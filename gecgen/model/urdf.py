"""Serial chains from URDF: the joints on the path from a base link to a tip link.

Every moving joint (revolute, continuous, prismatic) becomes a frame that carries the six
generalized errors. A joint's `<origin>` is `Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)` and its motion
a rotation about, or translation along, its unit `<axis>` (default x) in the frame after the
origin. Fixed joints fold into the next moving joint's origin (`pre`); those before the first
moving joint and that joint's own origin form the base (so frame 0 is the first joint's frame at
zero, as in DH), and those after the last moving joint form the tool. Meshes, inertias,
transmissions and joints off the path are ignored by the chain; `load_mass_tree` reads the masses
of every link below a base link, on the path or not, for gravity torques (`model.gravity`).
"""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from xml.parsers import expat
from pathlib import Path
from typing import NamedTuple

import numpy as np

from gecgen.model.kinematics import constant, joint_motion
from gecgen.model.robot import Coupling, Elementary, Joint
from gecgen.model.validation import ModelError, excerpt, nearest, read_text, require

MOVING = {"revolute": "R", "continuous": "R", "prismatic": "P"}


@dataclass(frozen=True)
class UrdfJoint:
    """One `<joint>` element of the tree: its name, type, parent and child link and the element."""

    name: str
    type: str
    parent: str
    child: str
    element: ET.Element


class Follow(NamedTuple):
    """A joint's value as multiplier * q_root + offset, `<mimic>` elements followed to the joint that
    mimics nothing (root; the joint itself, 1 and 0, when it mimics nothing)."""

    root: str
    multiplier: float
    offset: float


def _number(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ModelError(f"{where}: {excerpt(text)} is not a number; fix the URDF") from None
    require(math.isfinite(value), f"{where}: {excerpt(text)} is not finite; fix the URDF")
    return value


def _triple(text: str | None, default: str, where: str) -> list[float]:
    """Three numbers from an attribute such as xyz="0 0.1 0"; `default` when it is absent."""
    words = (text if text is not None else default).split()
    require(len(words) == 3, f"{where}: expected three numbers, got {excerpt(text)}; fix the URDF")
    return [_number(w, where) for w in words]


def _origin(joint: ET.Element, where: str) -> tuple[Elementary, ...]:
    """The joint's `<origin>` as elementary transforms Trans(xyz) Rz(y) Ry(p) Rx(r) (zeros dropped)."""
    el = joint.find("origin")
    xyz = _triple(None if el is None else el.get("xyz"), "0 0 0", f"{where} origin xyz")
    rpy = _triple(None if el is None else el.get("rpy"), "0 0 0", f"{where} origin rpy")
    ops = [("Tx", xyz[0]), ("Ty", xyz[1]), ("Tz", xyz[2]), ("Rz", rpy[2]), ("Ry", rpy[1]), ("Rx", rpy[0])]
    return tuple((op, v) for op, v in ops if v != 0.0)


#: a joint axis may be this far from unit length (either way) and still be read as a direction
MAX_AXIS_SCALE = 1e3


def _axis(joint: ET.Element, where: str) -> tuple:
    """The unit joint axis; components that are exactly 0 or +-1 stay exact so the chain prunes them."""
    el = joint.find("axis")
    axis = _triple(None if el is None else el.get("xyz"), "1 0 0", f"{where} axis xyz")
    norm = math.hypot(*axis)
    require(norm > 0, f"{where}: axis must not be zero; give the direction of motion")
    # a URDF axis is a unit vector; one of 1e308 (whose length overflows to inf, leaving a zero
    # axis) or 1e-300 is a broken export, not a direction to guess from
    require(1 / MAX_AXIS_SCALE <= norm <= MAX_AXIS_SCALE,
            f"{where} axis xyz: length {norm:.3g}; a joint axis is a unit vector (length 1); fix the URDF")
    unit = [a / norm for a in axis]
    return tuple(int(u) if u in (-1.0, 0.0, 1.0) else u for u in unit)


def _limits(joint: ET.Element, jtype: str, where: str) -> tuple[float, float]:
    """(lower, upper) in m or rad; a continuous joint has none."""
    if jtype == "continuous":
        return -math.inf, math.inf
    el = joint.find("limit")
    require(el is not None and el.get("lower") is not None and el.get("upper") is not None,
            f"{where}: a {jtype} joint needs <limit lower=... upper=...>; add its joint limits")
    lo, hi = _number(el.get("lower"), f"{where} limit lower"), _number(el.get("upper"), f"{where} limit upper")
    require(lo < hi, f"{where}: limit lower {lo:g} must be below upper {hi:g}")
    return lo, hi


def _mimic(uj: UrdfJoint, where: str) -> tuple[str, float, float] | None:
    """(followed joint's name, multiplier, offset) of a joint's `<mimic>` element, or None."""
    el = uj.element.find("mimic")
    if el is None:
        return None
    jwhere = f"{where}: joint {excerpt(uj.name)} mimic"
    require(uj.type in MOVING, f"{jwhere}: a {uj.type} joint cannot mimic (only revolute, continuous and prismatic "
                               f"joints move here); remove its <mimic>")
    require(el.get("joint"), f"{jwhere}: <mimic> names no joint; give joint=\"...\", the joint it follows")
    multiplier = _number(el.get("multiplier", "1"), f"{jwhere} multiplier")
    require(multiplier != 0, f"{jwhere}: multiplier 0 holds the joint at its offset; make it a fixed joint "
                             f"with the offset in its origin")
    return el.get("joint"), multiplier, _number(el.get("offset", "0"), f"{jwhere} offset")


def follow(joints: dict[str, UrdfJoint], name: str, where: str) -> Follow:
    """Where joint `name`'s value comes from (joints: every joint of the URDF by name). A mimic of a
    mimic composes: m1 * (m2 * q + o2) + o1."""
    multiplier, offset, uj, seen = 1.0, 0.0, joints[name], [name]
    while (mimic := _mimic(uj, where)) is not None:
        target, m, o = mimic
        require(target in joints, f"{where}: joint {excerpt(uj.name)} mimics joint {excerpt(target)}, which this URDF "
                                  f"does not have; name an existing joint in its <mimic>")
        require(target not in seen, f"{where}: joint {excerpt(name)}: the mimic joints {' -> '.join(seen + [target])} "
                                    f"form a loop; let one of them mimic nothing")
        multiplier, offset = multiplier * m, multiplier * o + offset
        seen.append(target)
        uj = joints[target]
    require(uj.type in MOVING, f"{where}: joint {excerpt(name)} mimics joint {excerpt(uj.name)}, a {uj.type} joint; "
                               f"a mimic joint follows a revolute, continuous or prismatic joint: fix its <mimic>")
    return Follow(uj.name, multiplier, offset)


def _exact(value: float) -> int | float:
    """A URDF number as an exact number (`model.exact`): integers stay exact so `1 * q + 0` prunes to q."""
    return int(value) if value == int(value) and abs(value) < 2 ** 53 else value


def _parse(path: str | Path) -> ET.Element:
    try:
        return ET.fromstring(read_text(Path(path), "URDF file"))
    except ET.ParseError as exc:
        raise ModelError(f"{path}: not valid XML ({exc})") from None


def _tree(root: ET.Element, where: str) -> tuple[set[str], dict[str, UrdfJoint]]:
    """Link names and, for each child link, the joint above it (a URDF is a tree of links)."""
    links = {el.get("name") for el in root.findall("link")}
    above: dict[str, UrdfJoint] = {}
    names: set[str] = set()
    for el in root.findall("joint"):  # top-level only: <transmission> also holds <joint> elements
        name = el.get("name")
        jwhere = f"{where}: joint {excerpt(name)}"
        require(name, f"{where}: a <joint> has no name; name every joint")
        ends = {}
        for end in ("parent", "child"):
            tag = el.find(end)
            ends[end] = None if tag is None else tag.get("link")
            require(ends[end], f"{jwhere}: missing <{end} link=...>")
            require(ends[end] in links, f"{jwhere}: {end} link {excerpt(ends[end])} is not a <link> of this URDF; "
                                        f"declare it or fix the name")
        child = ends["child"]
        require(name not in names, f"{jwhere}: a second joint of this name; joint names must be unique")
        names.add(name)
        require(child not in above, f"{jwhere}: link {excerpt(child)} is already the child of joint "
                                    f"{excerpt(above[child].name) if child in above else ''}; a URDF is a tree")
        above[child] = UrdfJoint(name, el.get("type"), ends["parent"], child, el)
    # a loop of joints (a link its own ancestor) would send every walk along the tree round forever
    done: set[str] = set()
    for start in above:
        trail, link = set(), start
        while link in above and link not in done:
            require(link not in trail, f"{where}: joint {excerpt(above[link].name)}: link {excerpt(link)} is its own "
                                       f"ancestor (the joints form a loop); a URDF is a tree, remove a joint of the loop")
            trail.add(link)
            link = above[link].parent
        done.update(trail)
    return links, above


def _path(above: dict[str, UrdfJoint], base_link: str, tip_link: str, where: str) -> list[UrdfJoint]:
    """The joints from base_link down to tip_link, in order."""
    path: list[UrdfJoint] = []
    link = tip_link
    while link != base_link:
        require(link in above, f"{where}: tip_link {excerpt(tip_link)} is not below base_link {excerpt(base_link)}; "
                               f"choose links on one branch")
        path.append(above[link])
        link = above[link].parent
    return path[::-1]


def urdf_chain(path: Path, base_link: str, tip_link: str):
    """(base ops, joints, tool ops) of the path base_link -> tip_link in a URDF file.

    Lengths in m, angles in rad; joints are `Joint(pre=origin, post=())` with their URDF names, a
    mimic joint's `coupling` naming the independent joint it follows.
    """
    where = str(path)
    root = _parse(path)
    links, above = _tree(root, where)
    for key, link in (("base_link", base_link), ("tip_link", tip_link)):
        require(link in links, f"{where}: {key} {excerpt(link)} is not a link of this URDF; {nearest(link, links)}")
    by_name = {uj.name: uj for uj in above.values()}

    pending: tuple[Elementary, ...] = ()  # fixed transforms not yet folded into a frame
    base: tuple[Elementary, ...] | None = None
    joints, follows = [], []
    for uj in _path(above, base_link, tip_link, where):
        jwhere = f"{where}: joint {excerpt(uj.name)}"
        origin = _origin(uj.element, jwhere)
        if uj.type == "fixed":
            pending += origin
            continue
        require(uj.type in MOVING, f"{jwhere}: type {excerpt(uj.type)} is not supported on the chain; "
                                   f"use revolute, continuous, prismatic or fixed")
        lo, hi = _limits(uj.element, uj.type, jwhere)
        if base is None:
            base, pre = pending + origin, ()
        else:
            pre = pending + origin
        pending = ()
        joints.append(Joint(name=uj.name, kind=MOVING[uj.type], axis=_axis(uj.element, jwhere), pre=pre, post=(),
                            lower=lo, upper=hi))
        follows.append(follow(by_name, uj.name, where))
    require(joints, f"{where}: no moving joint between {excerpt(base_link)} and {excerpt(tip_link)}")
    return base, _with_mimics(joints, follows, base_link, tip_link, where), pending


def _with_mimics(joints: list[Joint], follows: list[Follow], base_link: str, tip_link: str,
                 where: str) -> tuple[Joint, ...]:
    """The chain's joints with each mimic joint's `coupling` set and its limits mapped onto the joint
    it follows, which keeps the values both sets of limits allow."""
    variable = {j.name: k for k, j in enumerate(j for j, f in zip(joints, follows) if f.root == j.name)}
    limits = {j.name: (j.lower, j.upper) for j in joints if j.name in variable}
    mimics = {}
    for joint, f in zip(joints, follows):
        if f.root == joint.name:
            continue
        require(f.root in variable, f"{where}: joint {excerpt(joint.name)} on the chain mimics joint "
                                    f"{excerpt(f.root)}, which is not on the chain from {excerpt(base_link)} to "
                                    f"{excerpt(tip_link)}; choose links whose chain holds {excerpt(f.root)}, or make "
                                    f"{excerpt(joint.name)} fixed")
        mimics[joint.name] = Coupling(((f.root, _exact(f.multiplier)),), _exact(f.offset))
        if math.isfinite(joint.lower):
            ends = sorted(((joint.lower - f.offset) / f.multiplier, (joint.upper - f.offset) / f.multiplier))
            lo, hi = max(limits[f.root][0], ends[0]), min(limits[f.root][1], ends[1])
            require(lo < hi, f"{where}: joint {excerpt(joint.name)}: its limits [{joint.lower:g}, {joint.upper:g}] "
                             f"allow joint {excerpt(f.root)} only [{ends[0]:g}, {ends[1]:g}], outside that joint's "
                             f"limits [{limits[f.root][0]:g}, {limits[f.root][1]:g}]; fix the limits in the URDF")
            limits[f.root] = (lo, hi)
    out = []
    for j in joints:
        lo, hi = limits.get(j.name, (j.lower, j.upper))
        out.append(replace(j, coupling=mimics.get(j.name), lower=lo, upper=hi))
    return tuple(out)


class TreeJoint(NamedTuple):
    """The joint above a link of a MassTree: kind "R", "P" or "F" (fixed, or any joint held still),
    origin 4x4 (m), unit axis (3,) in the frame after the origin; for a mimic joint, the joint that
    moves it (`follow`)."""

    name: str
    kind: str
    origin: np.ndarray
    axis: np.ndarray
    mimic: Follow | None = None

    def value(self, q: dict[str, np.ndarray], P: int) -> np.ndarray:
        """Its joint value (P,) when the joints `q` names take those values and all others are zero."""
        if self.mimic is None:
            return np.asarray(q.get(self.name, np.zeros(P)), float)
        return self.mimic.multiplier * np.asarray(q.get(self.mimic.root, np.zeros(P)), float) + self.mimic.offset


@dataclass(frozen=True)
class MassTree:
    """The links below a base link, parents before children: for each, the joint above it, and its
    mass (kg) and centre of mass (3,) in its own frame, m."""

    links: tuple[str, ...]
    parent: dict[str, str]
    joint: dict[str, TreeJoint]
    mass: dict[str, float]
    com: dict[str, np.ndarray]
    source: str

    def rest_poses(self) -> dict[str, np.ndarray]:
        """Every link's pose (4x4, m) in the base link's frame with all independent joints at zero
        (a mimic joint then sits at its offset)."""
        pose = {self.links[0]: np.eye(4)}
        for link in self.links[1:]:
            j = self.joint[link]
            pose[link] = pose[self.parent[link]] @ j.origin
            if j.mimic is not None and j.mimic.offset != 0:
                pose[link] = pose[link] @ joint_motion(j.axis, j.kind, np.array(j.mimic.offset))
        return pose


def load_mass_tree(path: str | Path, base_link: str) -> MassTree:
    """Read the links below `base_link` of a URDF with their masses (links without `<inertial>`
    are massless, as the URDF format says)."""
    where = str(path)
    root = _parse(path)
    links, above = _tree(root, where)
    require(base_link in links, f"{where}: base_link {excerpt(base_link)} is not a link of this URDF; "
                                f"{nearest(base_link, links)}")
    by_name = {uj.name: uj for uj in above.values()}
    below: dict[str, list[str]] = {}
    for child, uj in above.items():
        below.setdefault(uj.parent, []).append(child)
    order, todo = [], [base_link]
    while todo:
        link = todo.pop()
        order.append(link)
        todo.extend(sorted(below.get(link, [])))
    joint = {}
    for link in order[1:]:
        uj = above[link]
        jwhere = f"{where}: joint {excerpt(uj.name)}"
        kind = MOVING.get(uj.type, "F")
        axis = np.array([float(a) for a in _axis(uj.element, jwhere)]) if kind != "F" else np.zeros(3)
        f = follow(by_name, uj.name, where) if kind != "F" else None
        joint[link] = TreeJoint(uj.name, kind, constant(_origin(uj.element, jwhere)), axis,
                                f if f is not None and f.root != uj.name else None)
    mass, com = {}, {}
    for el in root.findall("link"):
        name, inertial = el.get("name"), el.find("inertial")
        if (name not in joint and name != base_link) or inertial is None:
            continue
        lwhere = f"{where}: link {excerpt(name)} inertial"
        m = inertial.find("mass")
        require(m is not None and m.get("value") is not None, f"{lwhere}: no <mass value=...>; give the link's mass")
        mass[name] = _number(m.get("value"), f"{lwhere} mass")
        require(mass[name] >= 0, f"{lwhere}: mass {mass[name]:g} kg is negative; fix the URDF")
        origin = inertial.find("origin")
        com[name] = np.array(_triple(None if origin is None else origin.get("xyz"), "0 0 0", f"{lwhere} origin xyz"))
    return MassTree(links=tuple(order), parent={k: above[k].parent for k in order[1:]}, joint=joint, mass=mass,
                    com=com, source=where)


def rpy(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) with R = Rz(yaw) Ry(pitch) Rx(roll), the URDF convention. Roll is taken
    from what is left after yaw and pitch, so near pitch +-90 degrees (where yaw and roll are
    nearly one angle, and many URDFs sit) the three still compose R to rounding."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    yaw = math.atan2(R[1, 0], R[0, 0])
    rest = constant((("Ry", -pitch), ("Rz", -yaw)))[:3, :3] @ R
    return math.atan2(rest[2, 1], rest[1, 1]), pitch, yaw


#: the rest of a start tag after its name: attributes, then > or />
_TAG_REST = re.compile(r"""(?:\s+[^\s=/>]+\s*=\s*(?:"[^"]*"|'[^']*'))*\s*/?>""")


def _start_tags(text: str) -> tuple[dict[tuple[str, str], tuple[int, int]], tuple[int, int]]:
    """Character spans of start tags in a URDF's text: ("joint", name) for every top-level joint and
    ("origin", name) for its first <origin>; and the span of the root's start tag."""
    data = text.encode()
    parser = expat.ParserCreate()
    path: list[str] = []  # the open elements
    joint = ""  # the top-level joint being read
    found: dict[tuple[str, str], int] = {}

    def start(tag, attrs):
        nonlocal joint
        path.append(tag)
        if len(path) == 1:
            found[("root", "")] = parser.CurrentByteIndex
        elif len(path) == 2 and tag == "joint":
            joint = attrs.get("name", "")
            found[("joint", joint)] = parser.CurrentByteIndex
        elif len(path) == 3 and tag == "origin" and path[1] == "joint":
            found.setdefault(("origin", joint), parser.CurrentByteIndex)

    parser.StartElementHandler = start
    parser.EndElementHandler = lambda tag: path.pop()
    parser.Parse(data, True)

    char, done, count = {}, 0, 0  # byte index -> character index, decoding each stretch once
    for at in sorted(set(found.values())):
        count += len(data[done:at].decode())  # a tag starts with "<": a character boundary
        char[at], done = count, at

    def span(i: int) -> tuple[int, int]:
        name = re.match(r"<[^\s/>]+", text[i:i + 1000])
        return i, _TAG_REST.match(text, i + name.end()).end()

    spans = {k: span(char[v]) for k, v in found.items()}
    return spans, spans.pop(("root", ""))


def _origin_tag(T: np.ndarray, close: str = "/>") -> str:
    xyz = " ".join(repr(float(v)) for v in T[:3, 3])
    return f'<origin xyz="{xyz}" rpy="{" ".join(repr(v) for v in rpy(T[:3, :3]))}"{close}'


def folded_copy(path: str | Path, base_link: str, tip_links: list[str], errors: list[np.ndarray],
                note: str, tools: list[dict[str, np.ndarray]]) -> tuple[str, list[str], dict[str, str], list[str]]:
    """The URDF's text with constant error transforms folded into joint origins, and each measured
    tool point as a link of its own.

    errors[i] (4x4, one per frame 0..n) sits right after frame i's nominal transform; the frames are
    the moving joints of the paths base_link -> each of tip_links (one on a chain; on a tree every
    branch's, shared joints once, numbered as `urdf_chain` and the robot file number them). E_0 goes
    into the first moving joint's origin (after it: frame 0 is that joint's frame at zero), or when
    the branches part before any joint, before the origin of every joint below base_link. E_i of a
    frame inside a path goes before the origin of every joint below the i-th moving joint's child
    link, on the chain or off it, so everything that link carries moves with it. The last frame of a
    path is where the measured tool hangs, and the data cannot tell its errors from the tool's own
    placement (a ball's, a probe's, a reflector nest's): its E goes into the tool, not the robot, so
    the tip link and everything on it keep their frames. tools[b]: branch b's measured points, name
    -> their frame (4x4) in the last frame's (the tool transform, the fixed joints to the tip link
    included, and the point); each becomes a fixed joint `<tip>_<name>_joint` and a link
    `<tip>_<name>` below the tip link, at inv(fixed joints to the tip) E_last frame. Only those
    origins change, byte for byte, and the tool links are added; `note` becomes a comment after the
    root's start tag. Returns (text, the tip link of each branch, {point name: its link}, the names
    of the joints added or changed)."""
    # here, not at the top: xml.sax.saxutils imports urllib.request (and http, email, ssl), 30 ms of
    # start-up for every command that reads a robot file; only writing a URDF needs it
    from xml.sax.saxutils import quoteattr

    where = str(path)
    text = read_text(Path(path), "URDF file")
    links, above = _tree(_parse(path), where)
    full = [_path(above, base_link, tip, where) for tip in tip_links]
    paths = [[uj for uj in p if uj.type != "fixed"] for p in full]
    chain = list({uj.name: uj for p in paths for uj in p}.values())  # first seen first: the frames' order
    require(len(chain) + 1 == len(errors), f"{where}: {len(chain)} moving joints from {base_link} to "
                                           f"{', '.join(tip_links)}, but {len(errors) - 1} frames of errors; the "
                                           f"URDF changed")
    below: dict[str, list[UrdfJoint]] = {}
    for uj in above.values():
        below.setdefault(uj.parent, []).append(uj)

    def origin(uj: UrdfJoint) -> np.ndarray:
        return constant(_origin(uj.element, f"{where}: joint {excerpt(uj.name)}"))

    identity = [np.array_equal(E, np.eye(4)) for E in errors]
    last = {p[-1].name for p in paths}  # the frames the tools hang from
    changed = {}
    if not identity[0] and len({p[0].name for p in paths}) == 1:
        changed[chain[0].name] = origin(chain[0]) @ errors[0]
    elif not identity[0]:
        changed.update({child.name: errors[0] @ origin(child) for child in below.get(base_link, [])})
    for uj, E, unit in zip(chain, errors[1:], identity[1:]):
        for child in [] if unit or uj.name in last else below.get(uj.child, []):
            changed[child.name] = E @ origin(child)
    tags, (root_start, root_end) = _start_tags(text)
    edits = [(root_end, root_end, f"\n  <!-- {note.replace('--', '- -')} -->")]
    for name, T in changed.items():
        if ("origin", name) in tags:
            a, b = tags[("origin", name)]
            edits.append((a, b, _origin_tag(T, "/>" if text[b - 2:b] == "/>" else ">")))
        else:  # the URDF's default origin, the identity, was left out
            a, b = tags[("joint", name)]
            indent = text[text.rfind("\n", 0, a) + 1:a]
            edits.append((b, b, f"\n{indent}  {_origin_tag(T)}"))
    names = sorted(changed)
    taken, tool_links, added = set(links) | {uj.name for uj in above.values()}, {}, []
    end = text.rindex("</" + text[root_start + 1:root_end].split()[0].rstrip("/>"))  # the root's end tag
    for tip_link, p, moving, points in zip(tip_links, full, paths, tools):
        E = errors[chain.index(moving[-1]) + 1]
        fixed = np.eye(4)  # the fixed joints from the last frame's link to the tip link
        for uj in p[p.index(moving[-1]) + 1:]:
            fixed = fixed @ origin(uj)
        for point, T in points.items():
            link = f"{tip_link}_{point}"
            while link in taken or f"{link}_joint" in taken:
                link += "_"
            taken |= {link, f"{link}_joint"}
            tool_links[point] = link
            names.append(f"{link}_joint")
            added.append(f'  <joint name={quoteattr(link + "_joint")} type="fixed">\n'
                         f'    <parent link={quoteattr(tip_link)}/>\n    <child link={quoteattr(link)}/>\n'
                         f'    {_origin_tag(np.linalg.inv(fixed) @ E @ T)}\n  </joint>\n'
                         f'  <link name={quoteattr(link)}/>\n')
    edits.append((end, end, "".join(added)))
    for a, b, new in sorted(edits, reverse=True):
        text = text[:a] + new + text[b:]
    return text, list(tip_links), tool_links, names
