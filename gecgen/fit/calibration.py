"""Calibration files (JSON): everything needed to predict and compensate, tied to its model.

A calibration records the robot file and the error model it was fitted with (by content hash)
and refuses to load against anything else, so coefficients can never be applied to the wrong
chain or basis. The robot file is recorded by its absolute path and by its path relative to the
calibration's folder, so a checkout that moved (calibration and robot files together) still loads.
Every number a calibration applies is checked on load: finite coefficients and covariance, a
proper rotation and a finite translation for the registration.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gecgen.version import __version__
from gecgen.model.files import write_atomically
from gecgen.model.errors import ErrorModel
from gecgen.symbolic.terms import error_model_from_dict
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.robot_file import load_robot
from gecgen.model.validation import ModelError, require
from gecgen.fit.placement import with_targets
from gecgen.fit.registration import Registration

if TYPE_CHECKING:  # an annotation only: the fit's module loads scipy, which reading a calibration does not need
    from gecgen.fit.identify import Fit


def model_hash(robot: Robot, model: ErrorModel) -> str:
    """Content hash of an error model (its terms per error and aux), independent of file layout."""
    text = json.dumps(model.to_yaml_dict(robot), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class Calibration:
    robot: Robot
    model: ErrorModel
    c: np.ndarray  # (nc,)
    std: np.ndarray  # (nc,), NaN where eliminated
    kept: tuple[int, ...]
    cov: np.ndarray  # (k, k) over kept
    registration: Registration  # the first (or only) station's
    report: dict  # metrics, statistics and redundancy as written
    registrations: dict[int, Registration] | None = None  # per station id; None: one, station 0

    @property
    def frames(self) -> dict[int, Registration]:
        """The tracker frame of every station the calibration was fitted with (station id -> frame)."""
        return self.registrations or {0: self.registration}

    def to_dict(self) -> dict:
        names = self.model.coefficient_names(self.robot)
        return {
            "gecgen_version": __version__,
            "robot": self.robot.name,
            **({"controller": self.robot.controller} if self.robot.controller else {}),
            "robot_file": str(Path(self.robot.source).resolve()),
            "robot_hashes": self.robot.source_hashes,
            "error_model": self.model.to_yaml_dict(self.robot),
            "error_model_hash": model_hash(self.robot, self.model),
            "targets": {n: list(xyz) for n, xyz in self.robot.targets.items()},
            **({"target_frames": {n: list(x) for n, x in self.robot.target_frames.items()}}
               if self.robot.target_frames else {}),
            "coefficients": [{"name": n, "value": float(v), "std": None if np.isnan(s) else float(s),
                              "identified": k in set(self.kept)}
                             for k, (n, v, s) in enumerate(zip(names, self.c, self.std))],
            "kept": list(self.kept),
            "covariance": self.cov.tolist(),
            "registration": self.registration.to_dict(),
            "registrations": {str(k): r.to_dict() for k, r in self.frames.items()},
            **self.report,
        }


def from_fit(robot: Robot, model: ErrorModel, fit: Fit, ratio_loads: list[dict] | None = None) -> Calibration:
    """The calibration of a fit. ratio_loads: the coupling ratios whose value depends on the loads
    (`loop.confounding`), recorded for a robot whose couplings carry ratio coefficients."""
    report = {"n_params": fit.redundancy.n_params, "n_identifiable": fit.redundancy.n_identifiable,
              "n_carried": len(fit.redundancy.kept),
              "eliminated": [e.to_dict() for e in fit.redundancy.eliminated],
              "before": fit.before, "train": fit.train, "sigma_mm": 1e3 * fit.sigma_m,
              "condition_number": fit.condition_number, "observability_index": fit.observability_index,
              "iterations": fit.iterations, "converged": fit.converged, "warnings": list(fit.warnings),
              "loss": fit.loss, "outlier_limit_mm": 1e3 * fit.outlier_limit_m if np.isfinite(fit.outlier_limit_m) else None,
              "outliers": [o.to_dict() for o in fit.outliers],
              "suspect_poses": [p.to_dict() for p in fit.suspects], "train_inliers": fit.train_inliers,
              "training_ranges": fit.ranges, "held": [h.to_dict() for h in fit.held]}
    if robot.ratio_terms():
        report["ratio_loads"] = list(ratio_loads or [])
    return Calibration(robot, model, fit.c, fit.std, fit.redundancy.kept, fit.cov, fit.registration, report,
                       fit.registrations)


#: keys every calibration file holds; the rest, but for these three, is its report
REQUIRED = ("robot_file", "robot_hashes", "error_model", "error_model_hash", "coefficients", "kept",
            "covariance", "registration")
NOT_REPORT = {"gecgen_version", "robot", "controller", "robot_file_relative", "registrations", "targets",
              "target_frames", *REQUIRED}
#: R^T R may differ from the identity by this much (JSON keeps R to full precision)
ROTATION_TOL = 1e-6


def outside(calib: Calibration, q: np.ndarray, w: np.ndarray, aux: np.ndarray) -> dict[str, np.ndarray]:
    """Per input, which poses take it outside the span it was fitted over ({name: (P,) bool}):
    q (P, n), w (P, 6), aux (P, len(calib.model.aux)). There the model extrapolates, and a
    polynomial term can grow without bound. A span-relative margin of 1e-9 keeps the training poses
    themselves inside."""
    ranges = calib.report.get("training_ranges") or {}
    names = [f"q{i + 1}" for i in range(calib.robot.n)] + list(WRENCH) + list(calib.model.aux)
    out = {}
    for name, v in zip(names, np.column_stack([q, w, aux]).T):
        if name in ranges:
            lo, hi = ranges[name]
            margin = 1e-9 * max(hi - lo, abs(lo), abs(hi), 1e-300)
            out[name] = (v < lo - margin) | (v > hi + margin)
    return out


def extrapolation(calib: Calibration, q: np.ndarray, w: np.ndarray, aux: np.ndarray,
                  inputs: set[str] | None = None) -> dict[str, int]:
    """How many poses take each input outside the span it was fitted over ({name: poses}, only
    the names with any; `outside`); inputs: only these names (`branch_inputs`), None: all."""
    return {name: int(m.sum()) for name, m in outside(calib, q, w, aux).items()
            if m.any() and (inputs is None or name in inputs)}


def branch_inputs(robot: Robot, model: ErrorModel, branch: int) -> set[str] | None:
    """The inputs (q1.., wrench components, aux names) the error of branch `branch`'s (index) tool
    depends on: the readings that turn a frame on its path, and what those frames' error terms use.
    A load signal sums over the whole tree, so a term with one depends on every reading and the
    wrench. None on a serial robot: every input."""
    if not robot.branches:
        return None
    path = robot.path(robot.tips()[branch][0])
    drives = robot.drives()
    every = {f"q{k + 1}" for k in range(robot.n)} | set(WRENCH)
    plain = every | set(model.aux)
    used = {f"q{k + 1}" for i in path if i > 0 for k, _ in drives[i - 1][0]}
    for i in path:
        for terms in model.terms[6 * i:6 * i + 6]:
            for v in (v for t in terms for v in t.variables):
                used |= {v} if v in plain else every
    return used


def extrapolation_note(counts: dict[str, int], n_poses: int, robot: Robot) -> str | None:
    """One line for a person: how many poses leave the training ranges, per joint or signal."""
    if not counts:
        return None
    label = {f"q{i + 1}": f"q{i + 1} ({j.name})" if j.name != f"q{i + 1}" else j.name for i, j in enumerate(robot.joints)}
    parts = ", ".join(f"{label.get(n, n)} {k}" for n, k in counts.items())
    return (f"extrapolation: poses outside the training ranges, per input: {parts} (of {n_poses}); "
            f"the calibration is not validated there")


def save(calib: Calibration, path: str | Path):
    """Write the calibration JSON (atomically), with the robot file also relative to its folder."""
    path = Path(path)
    d = calib.to_dict()
    d["robot_file_relative"] = os.path.relpath(d["robot_file"], path.parent.resolve())
    write_atomically(path, json.dumps(d, indent=1) + "\n")


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _finite_array(value, shape: tuple[int, ...]) -> np.ndarray | None:
    """value (nested JSON lists) as a float array of the given shape when every entry is a finite
    number; None otherwise."""
    try:
        a = np.array(value, dtype=object)
    except ValueError:  # ragged nesting
        return None
    if a.size == 0 and 0 in shape:  # a 0 x 0 matrix is written as []
        return np.zeros(shape)
    return a.astype(float) if a.shape == shape and all(_finite(x) for x in a.ravel()) else None


def _robot(d: dict, path: Path) -> Robot:
    """The robot file at its recorded absolute path, else relative to the calibration's folder:
    the first whose content hashes match the calibration's."""
    where = str(path)
    candidates = [Path(str(d["robot_file"]))]
    if isinstance(d.get("robot_file_relative"), str):
        candidates.append((path.parent / d["robot_file_relative"]).resolve())
    found = [c for c in candidates if c.is_file()]
    require(found, f"{where}: the robot file {' and '.join(map(str, candidates))} is missing; restore it "
                   f"next to the calibration as it was, or identify again")
    for candidate in found:
        robot = load_robot(candidate)
        if robot.source_hashes == d["robot_hashes"]:
            return robot
    raise ModelError(f"{where}: the robot file {found[0]} changed since this calibration was made; identify again")


def _targets(robot: Robot, d, where: str, frames=None) -> Robot:
    """The robot with the targets the calibration was fitted with: those the robot file leaves to
    estimate, or that the data placed elsewhere (fit.placement), and the measured frames of
    pose data the data turned (`frames`, target -> rotation vector, rad). A file written before
    targets were recorded holds the robot file's."""
    turned = {}
    if frames is not None:
        ok = isinstance(frames, dict) and set(frames) <= set(robot.targets)
        turned = {n: _finite_array(v, (3,)) for n, v in frames.items()} if ok else {}
        require(ok and all(v is not None for v in turned.values()),
                f"{where}: target_frames: expected some of the robot's targets ({', '.join(robot.targets)}) each "
                f"as a rotation vector of three finite numbers (rad); identify again")
        turned = {n: tuple(v.tolist()) for n, v in turned.items()}
    if d is None:
        require(not robot.estimated, f"{where}: targets: missing, and the robot file leaves "
                                     f"'{robot.estimated[0] if robot.estimated else ''}' to estimate; identify again")
        return with_targets(robot, {}, turned)
    ok = isinstance(d, dict) and set(d) == set(robot.targets)
    xyz = {n: _finite_array(v, (3,)) for n, v in d.items()} if ok else {}
    require(ok and all(v is not None for v in xyz.values()),
            f"{where}: targets: expected the robot's targets ({', '.join(robot.targets)}) each as three finite "
            f"numbers (m); identify again")
    return with_targets(robot, {n: tuple(v.tolist()) for n, v in xyz.items()}, turned)


def _registration(d, where: str) -> Registration:
    fix = "identify again (or restore the file)"
    require(isinstance(d, dict) and "applied" in d, f"{where}: registration: expected rotation, translation and "
                                                    f"applied; {fix}")
    R, t = _finite_array(d.get("rotation"), (3, 3)), _finite_array(d.get("translation"), (3,))
    require(R is not None and np.abs(R.T @ R - np.eye(3)).max() <= ROTATION_TOL and np.linalg.det(R) > 0,
            f"{where}: registration.rotation is not a proper rotation (3 x 3 finite numbers with R^T R = I within "
            f"{ROTATION_TOL:g} and det +1); {fix}")
    require(t is not None, f"{where}: registration.translation: expected three finite numbers (m); {fix}")
    require(isinstance(d["applied"], bool), f"{where}: registration.applied: {json.dumps(d['applied'])} is not true "
                                            f"or false; {fix}")
    return Registration(R, t, d["applied"])


def load(path: str | Path) -> Calibration:
    """Read a calibration; refused when its robot file changed, its model does not match or any
    number it applies is not finite (one line naming the file, the key and the fix)."""
    path = Path(path)
    where = str(path)
    require(path.is_file(), f"{where}: no such calibration file")
    try:
        d = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ModelError(f"{where}: not a calibration file (invalid JSON: {exc})") from None
    require(isinstance(d, dict), f"{where}: not a calibration file (a JSON object is expected)")
    for key in REQUIRED:
        require(key in d, f"{where}: missing key '{key}'; not a gecgen calibration file")
    robot = _targets(_robot(d, path), d.get("targets"), where, d.get("target_frames"))
    spec = d["error_model"]
    require(isinstance(spec, dict) and isinstance(spec.get("frames", {}), dict)
            and all(str(k).isdigit() for k in spec.get("frames", {})),
            f"{where}: error_model: expected an object with default and frames (frame number -> terms); the file was "
            f"edited: identify again")
    spec = {**spec, "frames": {int(k): v for k, v in spec.get("frames", {}).items()}}  # JSON keys are strings
    model = error_model_from_dict(spec, robot, f"{where}: error_model")
    names = model.coefficient_names(robot)
    entries = d["coefficients"]
    require(isinstance(entries, list) and all(isinstance(x, dict) and {"name", "value", "std"} <= set(x) for x in entries)
            and model_hash(robot, model) == d["error_model_hash"] and names == [x["name"] for x in entries],
            f"{where}: the error model does not match its coefficients; the file was edited or made by another version")
    fix = "identify again (a calibration holds finite numbers only)"
    for x in entries:
        require(_finite(x["value"]), f"{where}: coefficient '{x['name']}': value {json.dumps(x['value'])} is not "
                                     f"a finite number; {fix}")
        require(x["std"] is None or _finite(x["std"]), f"{where}: coefficient '{x['name']}': std "
                                                       f"{json.dumps(x['std'])} is neither a finite number nor null; {fix}")
        require(x["std"] is None or x["std"] >= 0, f"{where}: coefficient '{x['name']}': std {json.dumps(x['std'])} is "
                                                   f"negative; {fix}")
    kept = d["kept"]
    require(isinstance(kept, list) and all(isinstance(k, int) and 0 <= k < len(names) for k in kept)
            and len(set(kept)) == len(kept), f"{where}: kept: expected distinct coefficient indices; {fix}")
    cov = _finite_array(d["covariance"], (len(kept), len(kept)))
    require(cov is not None, f"{where}: covariance: expected a {len(kept)} x {len(kept)} matrix (the kept "
                             f"coefficients) of finite numbers; {fix}")
    c = np.array([x["value"] for x in entries], dtype=float)
    std = np.array([np.nan if x["std"] is None else x["std"] for x in entries], dtype=float)
    ranges = d.get("training_ranges") or {}
    require(isinstance(ranges, dict) and all(_finite_array(v, (2,)) is not None and v[0] <= v[1]
                                             for v in ranges.values()),
            f"{where}: training_ranges: expected each input's [lowest, highest] value as two finite numbers; {fix}")
    report = {k: v for k, v in d.items() if k not in NOT_REPORT}
    return Calibration(robot, model, c, std, tuple(kept), cov, _registration(d["registration"], where), report,
                       _registrations(d.get("registrations"), where))


def _registrations(d, where: str) -> dict[int, Registration] | None:
    """The per-station frames ({"id": registration}); None in a file written before stations."""
    if d is None:
        return None
    require(isinstance(d, dict) and d and all(isinstance(k, str) and k.lstrip("-").isdigit() for k in d),
            f"{where}: registrations: expected an object of station ids (integers) to registrations; identify again")
    return {int(k): _registration(v, f"{where}: registrations.{k}") for k, v in d.items()}
