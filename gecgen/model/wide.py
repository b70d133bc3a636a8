"""Import wide measurement tables (one row per pose, several points per row) through a column map.

Motion-capture exports and the logs of other tools put every point of a pose on one row, with
joint names as headers. A small YAML mapping says which column is what:

    pose: row                      # 'row' (pose ids 0, 1, ... in row order) or a column of integer ids
    joints:                        # robot joint (q1..qn or its name) -> column; every joint is mapped
      q1: torso_lift_joint
      arm_1_joint: arm_1_joint
    targets:                       # robot target -> its x, y, z columns (m)
      m1: [x1, y1, z1]
    orientations:                  # optional: a mapped target -> the orientation of its frame
      m1: {columns: [rx1, ry1, rz1], convention: rpy, unit: rad}
    wrench: {fz: force_z}          # optional: fx fy fz mx my mz -> column (sensor frame, N and N m)
    aux: [marker_std_mm]           # optional: columns kept as auxiliary signals
    ignore: [shipped_row]          # optional: columns deliberately dropped (absent ones are fine)
    units: {angles: deg, lengths: mm}   # optional: the table's units (default rad and m)

Every column of the table must be mapped, kept as aux or ignored: nothing is dropped silently.
Values are copied exactly but for `units` (no clipping): a controller's export in degrees and
millimetres (revolute readings in deg; prismatic readings and target coordinates in mm) is
converted to the contract's rad and m, and nothing else is; `read_measurements` applies the
contract's checks (limits, millimetres) to the written file. An orientation (the target frame's,
parallel to the tool frame, in the measuring frame; `model.orientation`) has a `convention`:
`quaternion` (columns w, x, y, z), `matrix` (nine columns, row by row), `rpy` (roll, pitch, yaw:
R = Rz(yaw) Ry(pitch) Rx(roll), as URDF and pinocchio) or `euler_<seq>` (scipy's sequence: three of
xyz, extrinsic, or XYZ, intrinsic), and for angles a `unit`, deg or rad. It is converted to a
rotation matrix, checked (a unit quaternion, an orthonormal matrix) and written as a quaternion.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import math

import numpy as np

from gecgen.model.errors import is_aux_name
from gecgen.model.measurements import MAX_AUX, MAX_WRENCH, Measurements, pose_id_column
from gecgen.model.orientation import Convention, parse_convention, rotations
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.table import at, read_table
from gecgen.model.validation import excerpt, read_yaml, require, require_keys

#: columns of the contract's measurement file, which an aux column must not shadow
CONTRACT_COLUMNS = ("pose", "target", "x", "y", "z", *WRENCH)
#: the units a table may be in: each in rad (angles) or m (lengths)
UNITS = {"angles": {"rad": 1.0, "deg": math.pi / 180}, "lengths": {"m": 1.0, "mm": 1e-3}}


@dataclass(frozen=True)
class ColumnMap:
    """Which column of a wide table holds what; validated against one robot by `load_mapping`."""

    pose: str  # "row" or the column of integer pose ids
    joints: tuple[str, ...]  # the column of q1..qn, in robot order
    targets: dict[str, tuple[str, str, str]]  # target name -> its x, y, z columns, in mapping order
    wrench: dict[str, str]  # "fx".."mz" -> column
    aux: tuple[str, ...]
    ignore: tuple[str, ...]
    source: str  # the mapping file, for messages
    orientations: dict[str, tuple[tuple[str, ...], Convention]] | None = None  # target -> its columns, convention
    #: what one unit of the table's revolute readings and of its lengths (prismatic readings, target
    #: coordinates) is in rad and m
    angle_scale: float = 1.0
    length_scale: float = 1.0

    def columns(self) -> list[str]:
        """Every column the mapping reads (ignored ones excluded), in mapping order."""
        return [*([] if self.pose == "row" else [self.pose]), *self.joints,
                *[c for xyz in self.targets.values() for c in xyz],
                *[c for cols, _ in (self.orientations or {}).values() for c in cols], *self.wrench.values(), *self.aux]


def _names(value, where: str, what: str) -> list[str]:
    require(isinstance(value, list) and all(isinstance(v, str) and v for v in value),
            f"{where}: expected a list of {what}, got {excerpt(value)}")
    return value


def _mapping(value, where: str, what: str) -> dict:
    require(isinstance(value, dict) and value, f"{where}: expected a mapping {what}, got {excerpt(value)}")
    return value


def load_mapping(path: str | Path, robot: Robot) -> ColumnMap:
    """Read and validate a column-mapping YAML for `robot`; every problem names the file, key and fix."""
    path = Path(path)
    where = str(path)
    spec = read_yaml(path, "column-mapping")
    require(isinstance(spec, dict), f"{where}: expected a mapping with pose, joints, targets, aux, ignore")
    require_keys(spec, where, required={"joints", "targets"},
                 optional={"pose", "wrench", "aux", "ignore", "description", "orientations", "units"})
    units = _mapping(spec["units"], f"{where}: units", "{angles: deg or rad, lengths: mm or m}") if "units" in spec else {}
    require_keys(units, f"{where}: units", optional=set(UNITS))
    for key, value in units.items():
        require(value in UNITS[key], f"{where}: units.{key}: {excerpt(value)}; use {' or '.join(UNITS[key])}")

    qnames = [f"q{i + 1}" for i in range(robot.n)]
    joints: dict[str, str] = {}
    for key, col in _mapping(spec["joints"], f"{where}: joints", "from joint to column").items():
        q = qnames[robot.joint_names.index(key)] if key in robot.joint_names else key
        require(q in qnames, f"{where}: joints: {excerpt(key)} is not a joint of {robot.name}; "
                             f"use q1..q{robot.n} or {', '.join(robot.joint_names)}")
        require(q not in joints, f"{where}: joints: {excerpt(key)} is mapped twice (as {q} and by name); keep one")
        require(isinstance(col, str), f"{where}: joints.{key}: expected a column name, got {excerpt(col)}")
        joints[q] = col
    missing = [f"{q} ({name})" for q, name in zip(qnames, robot.joint_names) if q not in joints]
    require(not missing, f"{where}: joints: no column for {missing[0] if missing else ''}; map every joint")

    targets = {}
    for name, cols in _mapping(spec["targets"], f"{where}: targets", "from target to [x, y, z] columns").items():
        require(name in robot.targets, f"{where}: targets: {excerpt(name)} is not a target of {robot.name} "
                                       f"({', '.join(robot.targets)}); add it to the robot file or fix the name")
        require(len(_names(cols, f"{where}: targets.{name}", "three column names [x, y, z]")) == 3,
                f"{where}: targets.{name}: expected three column names [x, y, z], got {excerpt(cols)}")
        targets[name] = tuple(cols)

    orientations = {}
    if "orientations" in spec:
        for name, o in _mapping(spec["orientations"], f"{where}: orientations",
                                "from target to {columns, convention, unit}").items():
            ow = f"{where}: orientations.{excerpt(str(name))}"
            require(name in targets, f"{ow}: not a target mapped under targets; an orientation belongs to a measured "
                                     f"target's frame")
            require(isinstance(o, dict), f"{ow}: expected {{columns: [...], convention: ..., unit: ...}}")
            require_keys(o, ow, required={"columns", "convention"}, optional={"unit"})
            convention = parse_convention(o["convention"], o.get("unit"), ow)
            cols = _names(o["columns"], f"{ow}.columns", "column names")
            require(len(cols) == convention.width, f"{ow}.columns: a {o['convention']} has {convention.width} "
                                                   f"columns, got {len(cols)}")
            orientations[name] = (tuple(cols), convention)

    wrench = _mapping(spec["wrench"], f"{where}: wrench", "from fx..mz to column") if "wrench" in spec else {}
    for k, col in wrench.items():
        require(k in WRENCH, f"{where}: wrench: {excerpt(k)} is not one of {', '.join(WRENCH)}")
        require(isinstance(col, str), f"{where}: wrench.{k}: expected a column name, got {excerpt(col)}")

    aux = _names(spec.get("aux") or [], f"{where}: aux", "column names")
    for a in aux:
        require(is_aux_name(a) and a not in CONTRACT_COLUMNS and a not in robot.joint_names,
                f"{where}: aux: {excerpt(a)} cannot be an auxiliary signal (it is a contract, joint or reserved name, "
                f"or not an identifier); list it under ignore")
    ignore = _names(spec.get("ignore") or [], f"{where}: ignore", "column names")

    mapping = ColumnMap(pose=spec.get("pose", "row"), joints=tuple(joints[q] for q in qnames), targets=targets,
                        wrench=dict(wrench), aux=tuple(aux), ignore=tuple(ignore), source=where,
                        orientations=orientations or None,
                        angle_scale=UNITS["angles"][units.get("angles", "rad")],
                        length_scale=UNITS["lengths"][units.get("lengths", "m")])
    require(isinstance(mapping.pose, str) and mapping.pose,
            f"{where}: pose: expected 'row' or the name of the pose-id column, got {excerpt(mapping.pose)}")
    used = mapping.columns()
    twice = [c for c in dict.fromkeys(used) if used.count(c) > 1] + [c for c in ignore if c in used]
    require(not twice, f"{where}: column {excerpt(twice[0]) if twice else ''} is used twice (mapped, aux or ignored); "
                       f"give each column one role")
    return mapping


def import_wide(path: str | Path, robot: Robot, mapping: ColumnMap | str | Path, sep: str = ",",
                decimal: str = ".") -> Measurements:
    """Read a wide table (CSV, one row per pose) into Measurements.

    `mapping` is a ColumnMap or the path of its YAML. `sep` separates the table's columns and
    `decimal` marks the decimals of its numbers ("," reads 1,234 as 1.234, as European exports
    write; a point beside it is refused). Returns P poses (q (P, n), w (P, 6), aux
    (P, len(mapping.aux))) and P * T measured points, pose by pose, targets in mapping order.
    """
    if not isinstance(mapping, ColumnMap):
        mapping = load_mapping(mapping, robot)
    where = str(path)
    # ignored columns may hold anything: read them as text
    table = read_table(path, "file", "the column names of the mapping " + str(mapping.source), text=mapping.ignore,
                       sep=sep, decimal=decimal)
    header = table.header
    for col in mapping.columns():
        require(col in header, f"{where}: row 1: no column {excerpt(col)} (named in {mapping.source}); "
                               f"fix the mapping or the table")
    unused = [h for h in header if h not in mapping.columns() and h not in mapping.ignore]
    require(not unused, f"{where}: row 1: column {excerpt(unused[0]) if unused else ''} is neither mapped nor ignored in "
                        f"{mapping.source}; map it, keep it under aux or list it under ignore")

    def column(col: str, limit: float = math.inf) -> np.ndarray:
        return table.numbers(col, limit=limit)

    P = len(table)
    q = np.column_stack([column(c) * (mapping.angle_scale if j.kind == "R" else mapping.length_scale)
                         for c, j in zip(mapping.joints, robot.joints)])
    w = np.zeros((P, 6))
    for k, col in mapping.wrench.items():
        w[:, WRENCH.index(k)] = column(col, MAX_WRENCH)
    aux = np.column_stack([column(a, MAX_AUX) for a in mapping.aux]) if mapping.aux else np.zeros((P, 0))
    if mapping.pose == "row":
        ids = np.arange(P)
    else:
        ids = pose_id_column(table, mapping.pose)
        _, first = np.unique(ids, return_index=True)
        again = np.setdiff1d(np.arange(P), first)
        require(not len(again), f"{at(where, again[0] + 2 if len(again) else 0, mapping.pose)}: "
                                f"pose id repeats an earlier row; one row per pose")
    names = list(robot.targets)
    xyz = mapping.length_scale * np.stack([np.column_stack([column(c) for c in cols])
                                           for cols in mapping.targets.values()], axis=1)
    nt = len(mapping.targets)
    orientation = None
    if mapping.orientations:
        orientation = np.full((P, nt, 3, 3), np.nan)
        for k, target in enumerate(mapping.targets):
            if target in mapping.orientations:
                cols, convention = mapping.orientations[target]
                orientation[:, k] = rotations(np.column_stack([column(c) for c in cols]), convention,
                                              lambda r, cols=cols: f"{where}: row {r + 2}, columns {', '.join(cols)}")
        orientation = orientation.reshape(P * nt, 3, 3)
    return Measurements(q=q, w=w, aux=aux, aux_names=mapping.aux, pose_ids=ids,
                        pose=np.repeat(np.arange(P), nt), target=np.tile([names.index(t) for t in mapping.targets], P),
                        xyz=xyz.reshape(P * nt, 3), source=where, orientation=orientation)
