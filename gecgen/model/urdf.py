"""Serial chains from URDF: the joints on the path from a base link to a tip link.

Every moving joint (revolute, continuous, prismatic) becomes a frame that carries the six
generalized errors; fixed joints fold into the next moving joint's origin (`pre`), those before
the first moving joint into the base and those after the last into the tool. Meshes, inertias
and everything else in the URDF are ignored.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import sympy as sp

from gecgen.model.robot import Elementary, Joint
from gecgen.model.validation import ModelError, require

MOVING = {"revolute": "R", "continuous": "R", "prismatic": "P"}


def _floats(text: str | None, default: str, where: str) -> list[float]:
    try:
        values = [float(v) for v in (text if text is not None else default).split()]
    except ValueError:
        raise ModelError(f"{where}: expected three numbers, got {text!r}") from None
    require(len(values) == 3, f"{where}: expected three numbers, got {text!r}")
    return values


def _origin(joint: ET.Element, where: str) -> tuple[Elementary, ...]:
    el = joint.find("origin")
    xyz = _floats(None if el is None else el.get("xyz"), "0 0 0", f"{where} origin xyz")
    rpy = _floats(None if el is None else el.get("rpy"), "0 0 0", f"{where} origin rpy")
    ops = [("Tx", xyz[0]), ("Ty", xyz[1]), ("Tz", xyz[2]), ("Rz", rpy[2]), ("Ry", rpy[1]), ("Rx", rpy[0])]
    return tuple((op, sp.Float(v, 17)) for op, v in ops if v != 0.0)


def urdf_chain(path: Path, base_link: str, tip_link: str):
    """(base ops, joints, tool ops) of the path base_link -> tip_link in a URDF file."""
    where = str(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ModelError(f"{where}: not valid XML ({exc})") from None
    links = {el.get("name") for el in root.findall("link")}
    for key, link in (("base_link", base_link), ("tip_link", tip_link)):
        require(link in links, f"{where}: {key} '{link}' is not a link of this URDF")
    parent_joint = {el.find("child").get("link"): el for el in root.findall("joint")}
    path_joints = []
    link = tip_link
    while link != base_link:
        require(link in parent_joint, f"{where}: tip_link '{tip_link}' is not below base_link '{base_link}'")
        joint = parent_joint[link]
        path_joints.append(joint)
        link = joint.find("parent").get("link")
    path_joints.reverse()

    pending: tuple[Elementary, ...] = ()
    base: tuple[Elementary, ...] | None = None
    joints = []
    for el in path_joints:
        name, jtype = el.get("name"), el.get("type")
        jwhere = f"{where}: joint '{name}'"
        origin = _origin(el, jwhere)
        if jtype == "fixed":
            pending += origin
            continue
        require(jtype in MOVING, f"{jwhere}: type '{jtype}' is not supported; use revolute, continuous, prismatic or fixed")
        require(el.find("mimic") is None, f"{jwhere}: mimic joints are not supported; give the chain without them")
        axis = _floats(None if el.find("axis") is None else el.find("axis").get("xyz"), "1 0 0", f"{jwhere} axis")
        norm = math.sqrt(sum(a * a for a in axis))
        require(norm > 0, f"{jwhere}: axis must not be zero")
        limit = el.find("limit")
        if jtype == "continuous":
            lo, hi = -math.inf, math.inf
        else:
            require(limit is not None and limit.get("lower") is not None and limit.get("upper") is not None,
                    f"{jwhere}: a {jtype} joint needs <limit lower=... upper=...>")
            lo, hi = float(limit.get("lower")), float(limit.get("upper"))
        if base is None:
            base, pre = pending + origin, ()
        else:
            pre = pending + origin
        pending = ()
        axis_exact = tuple(sp.Integer(int(a / norm)) if a / norm in (-1.0, 0.0, 1.0) else sp.Float(a / norm, 17)
                           for a in axis)
        joints.append(Joint(name=name, kind=MOVING[jtype], axis=axis_exact, pre=pre, post=(), lower=lo, upper=hi))
    require(joints, f"{where}: no moving joint between '{base_link}' and '{tip_link}'")
    return base, tuple(joints), pending
