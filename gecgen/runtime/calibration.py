"""Calibration files (JSON): everything needed to predict and compensate, tied to its model.

A calibration records the robot file and the error model it was fitted with (by content hash)
and refuses to load against anything else, so coefficients can never be applied to the wrong
chain or basis.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gecgen import __version__
from gecgen.model.errors import ErrorModel, error_model_from_dict
from gecgen.model.robot import WRENCH, Robot, load_robot
from gecgen.model.validation import ModelError, require
from gecgen.runtime.identify import Fit
from gecgen.runtime.registration import Registration


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
    registration: Registration
    report: dict  # metrics, statistics and redundancy as written

    def to_dict(self) -> dict:
        names = self.model.coefficient_names(self.robot)
        return {
            "gecgen_version": __version__,
            "robot": self.robot.name,
            "robot_file": str(Path(self.robot.source).resolve()),
            "robot_hashes": self.robot.source_hashes,
            "error_model": self.model.to_yaml_dict(self.robot),
            "error_model_hash": model_hash(self.robot, self.model),
            "coefficients": [{"name": n, "value": float(v), "std": None if np.isnan(s) else float(s),
                              "identified": k in set(self.kept)}
                             for k, (n, v, s) in enumerate(zip(names, self.c, self.std))],
            "kept": list(self.kept),
            "covariance": self.cov.tolist(),
            "registration": self.registration.to_dict(),
            **self.report,
        }


def from_fit(robot: Robot, model: ErrorModel, fit: Fit) -> Calibration:
    report = {"n_params": fit.redundancy.n_params, "n_identifiable": fit.redundancy.n_identifiable,
              "eliminated": [e.to_dict() for e in fit.redundancy.eliminated],
              "before": fit.before, "train": fit.train, "sigma_mm": 1e3 * fit.sigma_m,
              "condition_number": fit.condition_number, "observability_index": fit.observability_index,
              "iterations": fit.iterations, "converged": fit.converged, "warnings": list(fit.warnings),
              "loss": fit.loss, "outlier_limit_mm": 1e3 * fit.outlier_limit_m if np.isfinite(fit.outlier_limit_m) else None,
              "outliers": [o.to_dict() for o in fit.outliers], "train_inliers": fit.train_inliers,
              "training_ranges": fit.ranges}
    return Calibration(robot, model, fit.c, fit.std, fit.redundancy.kept, fit.cov, fit.registration, report)


def extrapolation(calib: Calibration, q: np.ndarray, w: np.ndarray, aux: np.ndarray) -> dict[str, int]:
    """How many poses take each input outside the span it was fitted over ({name: poses}, only
    the names with any): q (P, n), w (P, 6), aux (P, len(calib.model.aux)). There the model
    extrapolates, and a polynomial term can grow without bound. A span-relative margin of 1e-9
    keeps the training poses themselves inside."""
    ranges = calib.report.get("training_ranges") or {}
    names = [f"q{i + 1}" for i in range(calib.robot.n)] + list(WRENCH) + list(calib.model.aux)
    values = np.column_stack([q, w, aux])
    out = {}
    for name, v in zip(names, values.T):
        if name not in ranges:
            continue
        lo, hi = ranges[name]
        margin = 1e-9 * max(hi - lo, abs(lo), abs(hi), 1e-300)
        count = int(np.sum((v < lo - margin) | (v > hi + margin)))
        if count:
            out[name] = count
    return out


def extrapolation_note(counts: dict[str, int], n_poses: int, robot: Robot) -> str | None:
    """One line for a person: how many poses leave the training ranges, per joint or signal."""
    if not counts:
        return None
    label = {f"q{i + 1}": f"q{i + 1} ({j.name})" if j.name != f"q{i + 1}" else j.name for i, j in enumerate(robot.joints)}
    parts = ", ".join(f"{label.get(n, n)} {k}" for n, k in counts.items())
    return (f"extrapolation: poses outside the training ranges, per input: {parts} (of {n_poses}); "
            f"the calibration is not validated there")


def save(calib: Calibration, path: str | Path):
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(json.dumps(calib.to_dict(), indent=1) + "\n")


def load(path: str | Path) -> Calibration:
    """Read a calibration; refused when its robot file changed or its model does not match."""
    path = Path(path)
    where = str(path)
    require(path.is_file(), f"{where}: no such calibration file")
    try:
        d = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ModelError(f"{where}: not a calibration file (invalid JSON: {exc})") from None
    for key in ("robot_file", "robot_hashes", "error_model", "error_model_hash", "coefficients", "kept",
                "covariance", "registration"):
        require(key in d, f"{where}: missing key '{key}'; not a gecgen calibration file")
    robot = load_robot(d["robot_file"])
    require(robot.source_hashes == d["robot_hashes"],
            f"{where}: the robot file {d['robot_file']} changed since this calibration was made; identify again")
    spec = dict(d["error_model"])
    spec["frames"] = {int(k): v for k, v in spec.get("frames", {}).items()}  # JSON keys are strings
    model = error_model_from_dict(spec, robot, f"{where}: error_model")
    names = model.coefficient_names(robot)
    require(model_hash(robot, model) == d["error_model_hash"] and names == [c["name"] for c in d["coefficients"]],
            f"{where}: the error model does not match its coefficients; the file was edited or made by another version")
    c = np.array([x["value"] for x in d["coefficients"]])
    std = np.array([np.nan if x["std"] is None else x["std"] for x in d["coefficients"]])
    report = {k: v for k, v in d.items() if k not in ("gecgen_version", "robot", "robot_file", "robot_hashes",
                                                       "error_model", "error_model_hash", "coefficients", "kept",
                                                       "covariance", "registration")}
    return Calibration(robot, model, c, std, tuple(d["kept"]), np.array(d["covariance"]),
                       Registration.from_dict(d["registration"]), report)
