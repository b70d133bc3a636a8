"""What a report is made of: its blocks (Report, Section, Table, Figure, Drawing, Bullets), the data
sets figures are drawn from (Residuals, DataSet), and how joints, terms and frames are labelled.
Both the report's sections (`content`) and its figures (`plots`) are built from these."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from gecgen.model.measurements import Measurements
from gecgen.model.robot import WRENCH, Robot
from gecgen.fit.identify import summary


@dataclass(frozen=True)
class Table:
    header: tuple[str, ...]
    rows: list[tuple[str, ...]]


@dataclass(frozen=True)
class Figure:
    name: str  # file stem of the Markdown report's PNG
    caption: str
    png: bytes
    axes: tuple[str, ...] = ()  # the labels of its axes


@dataclass(frozen=True)
class Drawing:
    """A figure still to draw: a `plots` function and its arguments. A report's figures are most of its
    time, and independent, so they are drawn together, side by side, as it is written (`drawn`)."""

    fn: Callable[..., Figure]
    args: tuple


@dataclass(frozen=True)
class Bullets:
    items: list[str]


@dataclass
class Section:
    """A titled part of a report; blocks are paragraphs (str, `code` in backticks), Bullets, Table, Figure or
    a Drawing, a Figure to come."""

    title: str
    blocks: list = field(default_factory=list)


@dataclass
class Report:
    title: str
    intro: list[str]
    sections: list[Section]


@dataclass(frozen=True)
class Residuals:
    """One model state (stage) on one data set, per measured row (G of them): the pose index (G,),
    measured - modelled position (G, 3) mm in the robot world, and the orientation error as a
    rotation vector about the world x, y, z (G, 3) mrad, NaN for position-only rows; None when no
    row measures a frame."""

    stage: str
    pose: np.ndarray
    position_mm: np.ndarray
    rotation_mrad: np.ndarray | None

    def summary(self) -> dict:
        """{rms_mm, max_mm} and with orientations {rot_rms_mrad, rot_max_mrad} (`identify.summary`)."""
        rot = None if self.rotation_mrad is None else 1e-3 * np.linalg.norm(self.rotation_mrad, axis=1)
        return summary(1e-3 * np.linalg.norm(self.position_mm, axis=1), rot)


@dataclass(frozen=True)
class DataSet:
    name: str  # "training" or "validation"
    data: Measurements
    stages: list[Residuals]


def variable(data: Measurements, name: str) -> np.ndarray:
    """Values (P,) of a term variable (q<k>, a wrench component, payload, an auxiliary signal) per pose."""
    if name.startswith("q") and name[1:].isdigit():
        return data.q[:, int(name[1:]) - 1]
    if name in WRENCH:
        return data.w[:, WRENCH.index(name)]
    if name == "payload":
        return np.linalg.norm(data.w[:, :3], axis=1)
    return data.aux[:, data.aux_names.index(name)]


def variable_label(name: str) -> str:
    """A term variable other than a joint as an axis names it: a wrench component or the payload's
    force with its unit ('fx (N)', 'mz (N m)'); an auxiliary signal as its column is named (its unit
    is the user's)."""
    if name in WRENCH:
        return f"{name} ({'N' if name in WRENCH[:3] else 'N m'})"
    return "payload force (N)" if name == "payload" else name


def joint_unit(robot: Robot, k: int) -> str:
    """The unit reports show joint variable k (0-based) in: the robot file's angle unit for a
    revolute joint, m for a prismatic one (as the robot file states lengths)."""
    return robot.angle_unit if robot.joints[k].kind == "R" else "m"


def joint_label(robot: Robot, k: int) -> str:
    """'q2 shoulder (deg)': joint variable k (0-based) with its name and its unit (`joint_unit`)."""
    j = robot.joints[k]
    name = "" if j.name == f"q{k + 1}" else f" {j.name}"
    return f"q{k + 1}{name} ({joint_unit(robot, k)})"


def joint_scale(robot: Robot, k: int) -> float:
    """Factor from joint k's internal unit (rad or m) to `joint_unit`."""
    return 180 / np.pi if joint_unit(robot, k) == "deg" else 1.0


def joint_values(robot: Robot, data: Measurements, k: int) -> np.ndarray:
    """Joint k (0-based) per pose in `joint_unit`."""
    return joint_scale(robot, k) * data.q[:, k]


def term_unit(robot: Robot, term: str) -> str:
    """What a coefficient of `term` is per: 'rad of q2' or 'm of q3' for a joint variable (terms take
    joints in rad or m, whatever unit the robot file states angles in), 'N of fz' or 'N m of mx' for
    a wrench component, else 'unit of TERM'."""
    names = {**{f"q{k + 1}": k for k in range(robot.n)}, **{j.name: k for k, j in enumerate(robot.joints)}}
    if term in names:
        return f"{'rad' if robot.joints[names[term]].kind == 'R' else 'm'} of {term}"
    if term in WRENCH:
        return f"{'N' if term in WRENCH[:3] else 'N m'} of {term}"
    return f"unit of {term}"


def frame_label(robot: Robot, i: int) -> str:
    """'0 base' or '2 after a2': frame i with the joint it follows."""
    return f"{i} base" if i == 0 else f"{i} after {robot.chain[i - 1].name}"
