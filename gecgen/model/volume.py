"""Volume files (YAML): the region of the workspace an accuracy statement is made for.

A calibration engineer states accuracy where it matters: "any point of the treatment volume, brought
to the isocenter at any couch angle, with or without a patient". The region is declared in the terms
of the robot file: which tool points (named targets, or a box in the tool frame), which joints range
over what, and, when the tool point is to be placed at a fixed world point, the joints left free solve
for it. Example (the seed paper's PPS):

    angle_unit: deg
    tool_box: {min: [-0.25, 0.0, -0.25], max: [0.25, 0.40, 0.25]}   # tool frame, m
    place_at: isocenter              # a `points` name of the robot file, or [x, y, z] in the world, m
    joints: {theta: [-90, 90], roll: 0, pitch: 0}   # a range or one value; unlisted joints solve place_at
    payload_kg: [0, 70]              # every sample is taken with each payload
    payload_at: [0, 0, 0]            # tool frame, m
    samples: 2000

Without `place_at`, unlisted joints range over their limits, within one turn about zero (as random
poses are drawn). Lengths in m, angles in `angle_unit`. The wrench at a sample is what a sensor tared
without payload reads of the payload's weight alone.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gecgen.model.robot import Robot
from gecgen.model.validation import excerpt, nearest, read_yaml, require, require_keys

#: samples a volume may ask for (each costs one H_e evaluation and a column of the Monte Carlo)
MAX_SAMPLES = 100_000
DEFAULT_SAMPLES = 2000
#: payloads a volume may list (every sample is taken with each)
MAX_PAYLOADS = 20


@dataclass(frozen=True)
class Volume:
    """A declared region. joints: per reading index, (lo, hi) in m or rad (lo == hi: held there);
    readings not listed range over their limits, or solve `place_at` when it is given.
    targets: names of the robot's targets whose accuracy is stated (empty with `tool_box`);
    tool_box: (min (3,), max (3,)) tool-frame points, m; place_at: (3,) world point, m;
    payload_kg: the payloads each sample is taken with; payload_at: (3,) tool frame, m."""

    source: str
    joints: dict[int, tuple[float, float]]
    targets: tuple[str, ...]
    tool_box: tuple[np.ndarray, np.ndarray] | None
    place_at: np.ndarray | None
    payload_kg: tuple[float, ...]
    payload_at: np.ndarray
    samples: int

    def free(self, robot: Robot) -> list[int]:
        """The readings `place_at` solves for (those the file does not list)."""
        return [k for k in range(robot.n) if k not in self.joints]


def _vector(value, where: str) -> np.ndarray:
    require(isinstance(value, (list, tuple)) and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value),
            f"{where}: expected [x, y, z] in m (three finite numbers), got {excerpt(value)}")
    return np.array(value, float)


def _number(value, where: str, unit: str) -> float:
    require(isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value),
            f"{where}: expected a number ({unit}), got {excerpt(value)}")
    return float(value)


def _joints(spec, robot: Robot, scale: float, where: str) -> dict[int, tuple[float, float]]:
    require(isinstance(spec, dict), f"{where}: expected a mapping from joint names to [low, high] or one value")
    names = [j.name for j in robot.joints]
    out = {}
    for name, value in spec.items():
        require(name in names, f"{where}: unknown joint {excerpt(name)}; {nearest(name, names)}")
        k = names.index(name)
        joint = robot.joints[k]
        unit = "rad" if joint.kind == "R" and scale == 1 else "deg" if joint.kind == "R" else "m"
        here = f"{where}.{name}"
        pair = value if isinstance(value, (list, tuple)) else [value, value]
        require(len(pair) == 2, f"{here}: expected [low, high] or one value ({unit}), got {excerpt(value)}")
        lo, hi = (_number(v, here, unit) * (scale if joint.kind == "R" else 1.0) for v in pair)
        require(lo <= hi, f"{here}: low {pair[0]} is above high {pair[1]}; swap them")
        tol = 1e-9 * max(1.0, abs(joint.lower), abs(joint.upper))
        require(joint.lower - tol <= lo and hi <= joint.upper + tol,
                f"{here}: {excerpt(value)} {unit} leaves the joint's limits "
                f"[{joint.lower / (scale if joint.kind == 'R' else 1):g}, "
                f"{joint.upper / (scale if joint.kind == 'R' else 1):g}]; narrow it")
        out[k] = (lo, hi)
    return out


def load_volume(path: str | Path, robot: Robot) -> Volume:
    """Read and check a volume file against the robot it is stated for (one-line refusals)."""
    where = str(path)
    require(not robot.branches, f"{where}: {robot.name} is branched; a statement over a volume is made for a serial "
                                f"chain (one tool) only: score held-out data with `gecgen evaluate` instead "
                                f"(images: `gecgen evaluate CALIB PIXELS.csv --cameras FILE`)")
    require(robot.n >= 6, f"{where}: {robot.name} has {robot.n} joints: compensation places the tool's pose (6 "
                          f"degrees of freedom), so a statement over a volume needs 6 joints or more")
    spec = read_yaml(Path(path), "volume")
    require(isinstance(spec, dict), f"{where}: expected a mapping (angle_unit, joints, tool_box or targets, ...)")
    require_keys(spec, where, required={"angle_unit"},
                 optional={"joints", "targets", "tool_box", "place_at", "payload_kg", "payload_at", "samples"})
    unit = spec["angle_unit"]
    require(unit in ("deg", "rad"), f"{where}: angle_unit: {excerpt(unit)}; use deg or rad")
    joints = _joints(spec.get("joints") or {}, robot, math.pi / 180 if unit == "deg" else 1.0, f"{where}: joints")

    require(not ("targets" in spec and "tool_box" in spec),
            f"{where}: give either targets (named points) or tool_box (points in the tool frame), not both")
    box = None
    if "tool_box" in spec:
        b = spec["tool_box"]
        require(isinstance(b, dict) and set(b) == {"min", "max"},
                f"{where}: tool_box: expected {{min: [x, y, z], max: [x, y, z]}} in the tool frame, m")
        box = (_vector(b["min"], f"{where}: tool_box.min"), _vector(b["max"], f"{where}: tool_box.max"))
        require((box[0] <= box[1]).all(), f"{where}: tool_box: min is above max on an axis; swap them")
        targets: tuple[str, ...] = ()
    else:
        targets = spec.get("targets", list(robot.targets))
        require(isinstance(targets, list) and targets and all(isinstance(t, str) for t in targets),
                f"{where}: targets: expected a list of the robot's target names")
        for t in targets:
            require(t in robot.targets, f"{where}: targets: unknown target {excerpt(t)}; {nearest(t, robot.targets)}")
        targets = tuple(dict.fromkeys(targets))

    place = None
    if "place_at" in spec:
        p = spec["place_at"]
        if isinstance(p, str):
            require(p in robot.points, f"{where}: place_at: {excerpt(p)} is not one of the robot file's points; "
                                       f"{nearest(p, robot.points) if robot.points else 'it has none: give [x, y, z]'}")
            place = np.array(robot.points[p], float)
        else:
            place = _vector(p, f"{where}: place_at")
        require(box is not None or len(targets) == 1,
                f"{where}: place_at places one point: give one target, or a tool_box")
        free = [j.name for k, j in enumerate(robot.joints) if k not in joints]
        require(len(free) == 3, f"{where}: place_at: the joints not listed under joints solve the point's 3 "
                                f"coordinates, so exactly 3 must be left free; {len(free)} are ({', '.join(free)})")

    payloads = spec.get("payload_kg", [0.0])
    payloads = payloads if isinstance(payloads, list) else [payloads]
    payloads = tuple(_number(v, f"{where}: payload_kg", "kg") for v in payloads)
    require(0 < len(payloads) <= MAX_PAYLOADS and all(v >= 0 for v in payloads),
            f"{where}: payload_kg: expected 1 to {MAX_PAYLOADS} masses >= 0 kg")
    samples = spec.get("samples", DEFAULT_SAMPLES)
    require(isinstance(samples, int) and not isinstance(samples, bool) and 1 <= samples <= MAX_SAMPLES,
            f"{where}: samples: expected a whole number from 1 to {MAX_SAMPLES}, got {excerpt(samples)}")
    at = _vector(spec.get("payload_at", [0.0, 0.0, 0.0]), f"{where}: payload_at")
    return Volume(where, joints, targets, box, place, payloads, at, samples)


__all__ = ["Volume", "load_volume"]
