"""Import wide measurement tables (one row per pose, several points per row) through a column map.

Motion-capture exports and logs of other tools put every point of a pose on one row, with joint
names as headers. A small YAML mapping says which column is what:

    pose: row                           # or the name of an integer pose-id column
    joints: {q1: torso_lift_joint, q2: arm_1_joint}   # robot joint (q1.. or its name) -> column
    targets: {m1: [x1, y1, z1], m2: [x2, y2, z2]}     # robot target -> its x, y, z columns
    aux: [marker_std_mm]                # columns kept as auxiliary signals
    ignore: [shipped_row, t_start_robot]              # columns deliberately dropped

Every column of the table must be mapped, kept as aux or ignored: nothing is dropped silently.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from gecgen.model.measurements import Measurements
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.validation import ModelError, read_yaml, require, require_keys


def load_mapping(path: str | Path, robot: Robot) -> dict:
    path = Path(path)
    spec = read_yaml(path, "column-mapping")
    where = str(path)
    require(isinstance(spec, dict), f"{where}: expected a mapping with pose, joints, targets, aux, ignore")
    require_keys(spec, where, required={"joints", "targets"}, optional={"pose", "aux", "ignore", "wrench", "description"})
    joints = {}
    for key, col in spec["joints"].items():
        if key in robot.joint_names:
            key = f"q{robot.joint_names.index(key) + 1}"
        require(key in [f"q{i + 1}" for i in range(robot.n)],
                f"{where}: joints: '{key}' is not a joint of {robot.name} (use q1..q{robot.n} or {', '.join(robot.joint_names)})")
        joints[key] = str(col)
    missing = [f"q{i + 1}" for i in range(robot.n) if f"q{i + 1}" not in joints]
    require(not missing, f"{where}: joints: no column for {missing[0] if missing else ''}; map every joint")
    for name, cols in spec["targets"].items():
        require(name in robot.targets, f"{where}: targets: '{name}' is not a target of {robot.name} "
                                       f"({', '.join(robot.targets)})")
        require(isinstance(cols, list) and len(cols) == 3, f"{where}: targets.{name}: expected [x, y, z] column names")
    wrench = spec.get("wrench") or {}
    for k in wrench:
        require(k in WRENCH, f"{where}: wrench: '{k}' is not one of {', '.join(WRENCH)}")
    return {"pose": spec.get("pose", "row"), "joints": joints, "targets": spec["targets"], "wrench": wrench,
            "aux": list(spec.get("aux") or []), "ignore": list(spec.get("ignore") or []), "source": where}


def import_wide(path: str | Path, robot: Robot, mapping: dict) -> Measurements:
    """Read a wide table into Measurements (rows of targets per pose, target order as mapped)."""
    path = Path(path)
    where = str(path)
    require(path.is_file(), f"{where}: no such file")
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        header = [h.strip() for h in next(reader, [])]
        rows = list(reader)
    require(rows, f"{where}: no data rows after the header")
    used = list(mapping["joints"].values()) + [c for cols in mapping["targets"].values() for c in cols]
    used += list(mapping["wrench"].values()) + mapping["aux"] + ([] if mapping["pose"] == "row" else [mapping["pose"]])
    for col in used:
        require(col in header, f"{where}: row 1: no column '{col}' (named in {mapping['source']})")
    leftover = [h for h in header if h not in used and h not in mapping["ignore"]]
    require(not leftover, f"{where}: row 1: column '{leftover[0] if leftover else ''}' is neither mapped nor listed "
                          f"under ignore in {mapping['source']}")
    idx = {h: k for k, h in enumerate(header)}

    def column(col: str) -> np.ndarray:
        out = np.empty(len(rows))
        for r, row in enumerate(rows):
            require(len(row) == len(header), f"{where}: row {r + 2}: {len(row)} fields, the header has {len(header)}")
            try:
                out[r] = float(row[idx[col]])
            except ValueError:
                raise ModelError(f"{where}: row {r + 2}, column '{col}': {row[idx[col]]!r} is not a number") from None
            require(math.isfinite(out[r]), f"{where}: row {r + 2}, column '{col}': not finite; fix or remove the row")
        return out

    P = len(rows)
    q = np.column_stack([column(mapping["joints"][f"q{i + 1}"]) for i in range(robot.n)])
    w = np.zeros((P, 6))
    for k, col in mapping["wrench"].items():
        w[:, WRENCH.index(k)] = column(col)
    aux = np.column_stack([column(a) for a in mapping["aux"]]) if mapping["aux"] else np.zeros((P, 0))
    ids = np.arange(P) if mapping["pose"] == "row" else column(mapping["pose"]).astype(int)
    require(len(set(ids.tolist())) == P, f"{where}: column '{mapping['pose']}': pose ids repeat; one row per pose")
    names = list(robot.targets)
    targets = [names.index(t) for t in mapping["targets"]]
    xyz = np.stack([np.column_stack([column(c) for c in mapping["targets"][t]]) for t in mapping["targets"]], axis=1)
    return Measurements(q=q, w=w, aux=aux, aux_names=tuple(mapping["aux"]), pose_ids=ids,
                        pose=np.repeat(np.arange(P), len(targets)), target=np.tile(targets, P),
                        xyz=xyz.reshape(-1, 3), source=where)
