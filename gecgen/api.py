"""The Python API: calibrate a robot in a few lines, scikit-learn style (docs/python-api.md).

Nouns with their options in the constructor, verbs that fit, score, predict and compensate, and
results with named attributes. Every `gecgen` command that fits or applies a calibration is a thin
layer over this module, so the API and the command line give the same numbers. Bad input raises
`ModelError` (a ValueError) with one line naming what is wrong and the fix; a result that cannot be
trusted raises RuntimeError. Warnings (targets placed from the data, extrapolation) are Python
warnings.

Units: lengths in m (errors reported in mm), angles in rad (orientation errors in mrad), wrenches
in N and N m. Shapes: N poses, n joints, nt targets.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gecgen.fit import calibration as _calibration
from gecgen.fit.inputs import checked, error_model, measured_counts, on_points, placed
from gecgen.model import ModelError, Robot
from gecgen.model import load_robot as _load_robot
from gecgen.model.checks import check_terms_finite
from gecgen.model.measurements import Commands, Measurements, read_commands
from gecgen.model.measurements import read_measurements as _read_measurements
from gecgen.model.validation import excerpt, nearest, require
from gecgen.runtime.compiled import FAILED, OUTSIDE_LIMITS, STATUS_NAMES, CompiledModel

__all__ = ["Calibrator", "Compensation", "Diagnoser", "Errors", "FilteredProgram", "ModelError", "ProgramTarget",
           "Score", "Selection", "calibrate", "design_images", "filter_program", "load_calibration", "load_robot",
           "read_measurements"]

LOSSES = ("cauchy", "huber", "l2")
REGISTER = ("auto", "always", "never")


# -- reading ---------------------------------------------------------------------------------

def load_robot(path: str | Path) -> Robot:
    """The robot of a robot file (robots/NAME.yaml, or a URDF import's), validated."""
    return _load_robot(path)


def _robot(robot) -> Robot:
    return robot if isinstance(robot, Robot) else _load_robot(robot)


def read_measurements(source, robot) -> Measurements:
    """Measurements of `robot` (a Robot or its file) from a CSV path or a pandas DataFrame with the
    measurement file's columns (docs/reference.md, "Files": pose, q1..qn, target, x, y, z in m, and
    optional fx..mz, station, orientation and aux columns). A DataFrame is checked as the file would
    be; messages name it `DataFrame`, its rows numbered as in `to_csv(index=False)` (iloc[i] is row
    i + 2). Measurements are passed through, after checking that they fit the robot."""
    robot = _robot(robot)
    if isinstance(source, Measurements):
        require(source.q.shape[1] == robot.n and (source.target < len(robot.targets)).all(),
                f"{source.source or 'Measurements'}: {source.q.shape[1]} joints and targets up to #"
                f"{source.target.max() + 1 if len(source.target) else 0}, but robot {robot.name} has {robot.n} joints "
                f"and {len(robot.targets)} targets; read the data with this robot's file")
        return source
    return _read_measurements(source, robot)


def fit_option(value, name: str, label: str | None = None):
    """ridge or rank_tol as identify takes it: None (identify's default), "auto" (chosen by 5-fold
    cross-validation) or a number (ridge >= 0, 0 <= rank_tol < 1); `label` names it in messages."""
    if value is None or value == "auto":
        return value
    upper = 1.0 if name == "rank_tol" else np.inf
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    bound = "a non-negative number" if upper == np.inf else f"a number from 0 to below {upper:g}"
    require(0 <= number < upper, f"{label or name} {excerpt(value)}: give {bound}, or auto")
    return number


def _choice(value, name: str, allowed: tuple):
    require(value in allowed, f"{name}={excerpt(value)}: {nearest(value, allowed)}")
    return value


def _noise(noise_mm) -> float | None:
    """noise_mm (mm per coordinate, or None) as m, refused in one line unless a positive finite number."""
    if noise_mm is None:
        return None
    require(isinstance(noise_mm, (int, float)) and not isinstance(noise_mm, bool) and 0 < noise_mm < 1e3,
            f"noise_mm: {excerpt(noise_mm)}; give the instrument's noise per coordinate in mm, a number above 0")
    return 1e-3 * float(noise_mm)


def _length(value):
    from gecgen.model.pose_targets import LENGTH_M

    require(value is None or (isinstance(value, (int, float)) and 0 < value < np.inf),
            f"orientation_length={excerpt(value)}: give a positive length in m (default {LENGTH_M:g})")
    return value


# -- results ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class Errors:
    """Errors of the measured points: RMS and largest distance (mm); with measured orientations,
    RMS and largest orientation error (mrad) of the rows that measure one, else None; for a
    held-out score, the 95 % confidence interval of the RMS by pose."""

    rms_mm: float
    max_mm: float
    rot_rms_mrad: float | None = None
    rot_max_mrad: float | None = None
    #: the 95 % confidence interval of rms_mm for poses drawn like these (`significance.rms_interval`)
    rms_mm_ci95: tuple[float, float] | None = None
    #: with sockets and planes (`fit.relative.measures`): the RMS distance of a socket's rows from
    #: their mean, of a plane's from their plane, and the known distances' errors (mm)
    consistency_mm: float | None = None
    flatness_mm: float | None = None
    distance_error_mm: float | None = None
    distances: list | None = None
    #: each declared relation between planes: how far the fitted planes are from it (angle_mrad, offset_error_mm)
    relations: list | None = None

    @classmethod
    def of(cls, summary: dict) -> "Errors":
        """From `fit.identify.summary`'s dict."""
        return cls(**summary)

    def to_dict(self) -> dict:
        """The command line's JSON for it (the rot_ keys only with orientations)."""
        return {k: v for k, v in vars(self).items() if v is not None}


@dataclass(frozen=True)
class Score:
    """`Calibrator.score`: the errors of data before (the nominal model) and after the calibration;
    n_poses, n_points (a measured frame is one point) and n_orientations (rows that measure a frame)
    of the data; extrapolation the number of poses outside the training span per input
    ({"q2": 3}, only inputs with any); registrations, with register=True, each station's tracker
    frame fitted on the data and its distance from the calibration's (angle_deg, distance_mm); on a
    tree, branches the same before and after per branch; after_inside, when some poses but not all
    leave a training range, the calibrated errors of the poses inside them (the validated part)."""

    before: Errors
    after: Errors
    n_poses: int
    n_points: int
    n_orientations: int
    extrapolation: dict
    registrations: dict | None = None
    #: what a report plots: the compiled model scored, the data as points (a measured frame is its
    #: vertices), and the data in the robot world before and after (R, 3) m
    cm: object = field(default=None, repr=False, compare=False)
    data: Measurements | None = field(default=None, repr=False, compare=False)
    y_before: np.ndarray | None = field(default=None, repr=False, compare=False)
    y: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: on a tree, per branch the data measures: {"before": {rms_mm, max_mm}, "after": {...}}
    branches: dict = field(default_factory=dict)
    after_inside: Errors | None = None


@dataclass(frozen=True)
class Compensation:
    """`Calibrator.compensate`: corrected joint commands q (N, n) (m or rad) for the nominal ones,
    and per row its status (N,), the generated C's GECGEN_ codes (`STATUS_NAMES`): OK 0,
    NOT_CONVERGED 1, SINGULAR 2 (near a singular posture: the least damped correction the model's
    error justifies), OUTSIDE_LIMITS 3 (converged outside the joint limits; `outside_limits` lists
    those rows, 0-based), NONFINITE 4 (the row holds its command), BOUNDED 5 (a joint held at its
    bound); residual (N,) the tool error each row leaves (m, 1 rad of the tool counted as 1 m; inf
    where NONFINITE); `failed` the rows (0-based) whose tool is not placed (codes 1, 2, 4, 5);
    max_correction the largest |q - q_cmd| per joint name; extrapolation as in `Score`, on a robot
    with branches only of the inputs the placed branch's tool depends on."""

    q: np.ndarray
    status: np.ndarray
    outside_limits: list[int]
    max_correction: dict
    extrapolation: dict
    residual: np.ndarray | None = None
    failed: list[int] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        """How many rows have each status, by name ("ok", "singular", ...), only those that occur."""
        found = np.bincount(np.asarray(self.status), minlength=len(STATUS_NAMES))
        return {name: int(k) for name, k in zip(STATUS_NAMES, found) if k}


def _floats(values, what: str, wanted: str) -> np.ndarray:
    """values as a float array, or a one-line refusal naming `what` and what it should hold."""
    try:
        return np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{what}: {excerpt(values)} is not an array of numbers; give {wanted}") from None


def correction_bound(robot: Robot, bound) -> np.ndarray | None:
    """`Calibrator.compensate`'s bound as n values (m or rad; inf: free), or None for none: one number for
    every joint, n numbers, or {joint name: value}; each must be >= 0 (a one-line refusal otherwise)."""
    if bound is None:
        return None
    names = list(robot.joint_names)
    if isinstance(bound, dict):
        unknown = [k for k in bound if k not in names]
        require(not unknown, f"bound: no joint {excerpt(unknown[0]) if unknown else ''} in robot {robot.name}; "
                             f"name joints of {', '.join(names)}")
        values = _floats([bound.get(name, np.inf) for name in names], "bound", "numbers in the joints' units")
    else:
        values = _floats(bound, "bound", f"one number or {len(names)} (m or rad)")
        require(values.ndim == 0 or values.shape == (len(names),),
                f"bound: {values.size} values; give one for every joint or {len(names)} ({', '.join(names)})")
        values = np.broadcast_to(values, (len(names),)).astype(float)
    bad = [n for n, v in zip(names, values) if not v >= 0]
    require(not bad, f"bound: {bad[0] if bad else ''} has a negative or NaN bound; give a correction bound >= 0 "
                     f"(m or rad; inf leaves the joint free)")
    return np.ascontiguousarray(values)


# -- the calibrator --------------------------------------------------------------------------

class Calibrator:
    """Identify a robot's error model from measured points, then score, predict and compensate.

    errors: the error model (None: robots/NAME.errors.yaml beside the robot file, else six constant
    errors per frame; a path; or an ErrorModel). loss: "cauchy" (default), "huber" or "l2" on each
    point's residual (outliers down-weighted and listed in `report_["outliers"]`). ridge: a prior on
    the column-scaled coefficients (0: plain least squares; "auto": 5-fold cross-validation).
    rank_tol: coefficients whose normalised column keeps less than this outside the better-excited
    ones are held at zero (None: exact dependencies only; "auto"). register: "auto" (register the
    measurement frame onto the robot world when far apart), "always" or "never". orientation_length:
    for data with orientation columns, an orientation error of 1 mrad counts as L * 1 mrad of
    position error (m; None: 0.1 when fitting, the calibration's when scoring). keep_insignificant:
    carry every identifiable coefficient into the calibration; by default those the data do not
    determine (|value| / std below 2 after backward elimination, `fit.significance`) are held
    at zero and the rest refitted, and the report lists them (`report_["significance"]`). noise_mm:
    the instrument's noise per coordinate (mm), when known: `report_["significance"]["overall"]`
    says whether the fit leaves more than it (`fit.significance.overall`), with a warning.

    Fitted attributes: calibration_ (fit.calibration.Calibration, what `save` writes), fit_
    (fit.identify.Fit), report_ (the report the calibration file holds: metrics in mm, outliers,
    eliminated coefficients...), robot_ (the robot with its targets placed), placement_ (where the
    data placed the targets, or None), cv_ (the cross-validation table of ridge/rank_tol "auto"),
    counts_ ({n_poses, n_points[, n_orientations]} of the training data).
    """

    def __init__(self, errors=None, *, loss: str = "cauchy", ridge=0.0, rank_tol=None, register: str = "auto",
                 orientation_length: float | None = None, keep_insignificant: bool = False,
                 noise_mm: float | None = None):
        # refused here, not at fit, so the line that made the mistake is the one named
        _choice(loss, "loss", LOSSES), _choice(register, "register", REGISTER), _length(orientation_length)
        _noise(noise_mm)
        fit_option(ridge, "ridge"), fit_option(rank_tol, "rank_tol")
        self.errors, self.loss, self.ridge, self.rank_tol = errors, loss, ridge, rank_tol
        self.register, self.orientation_length = register, orientation_length
        self.keep_insignificant, self.noise_mm = keep_insignificant, noise_mm

    def __repr__(self) -> str:
        state = f"fitted on {self.calibration_.robot.name}" if hasattr(self, "calibration_") else "not fitted"
        return f"Calibrator(loss={self.loss!r}, ridge={self.ridge!r}, register={self.register!r}; {state})"

    def fit(self, robot, data, progress=None) -> "Calibrator":
        """Fit to measurements of `robot` (a Robot or its file): a CSV path, a DataFrame or
        Measurements. progress(iteration, rms_mm) is called after each Gauss-Newton step. Raises
        RuntimeError when the fit cannot be trusted (the Calibrator is left as it was). Returns
        self."""
        # here, as the fit's other modules, not at the top: they load scipy, which compensating with a
        # calibration does not need (start-up time)
        from gecgen.fit import significance
        from gecgen.fit.identify import RANK_TOL_GRID, RIDGE_GRID, choose, identify

        loss, register = _choice(self.loss, "loss", LOSSES), _choice(self.register, "register", REGISTER)
        options, grids = {"loss": loss}, {}
        for name, value, grid in (("ridge", self.ridge, RIDGE_GRID), ("rank_tol", self.rank_tol, RANK_TOL_GRID)):
            value = fit_option(value, name)
            if value == "auto":
                grids[name] = grid
            elif value is not None:
                options[name] = value
        robot = _robot(robot)
        data = read_measurements(data, robot)
        model = error_model(self.errors, robot, data.aux_names)
        robot, placement = placed(robot, data)
        fitted, data = on_points(robot, _length(self.orientation_length), data)
        cm = checked(model, fitted, data)
        cv = []
        if grids:
            chosen, cv = choose(cm, data, grids, **options)
            options.update(chosen)
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            # the stated noise decides which directions the data determine (`fit.weak`)
            fit = identify(cm, data, registration_mode=register, progress=progress, noise_m=_noise(self.noise_mm),
                           **options)
        if fit.failures:
            raise RuntimeError(f"the fit is not trustworthy, no calibration made or written: {'; '.join(fit.failures)}")
        full = fit
        fit, verdict = significance.determined(cm, data, fit, self.keep_insignificant, _noise(self.noise_mm),
                                               registration_mode=register, **options)
        if fit is full:  # not refitted: the fit's own notes stand (a refit said its own)
            for w in said:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        calib = _calibration.from_fit(robot, model, fit, _ratio_loads(cm, fit, data))
        calib.report["significance"] = verdict
        calib.report.update({**options, "cv": cv, "placement": placement.to_dict() if placement else None})
        if robot.branches:
            from gecgen.fit.identify import to_world

            calib.report["branches"] = by_branch(cm, data, to_world(fit.registrations, data),
                                                 {"before": None, "train": fit.c})
            for b in robot.branches:
                if b.name not in calib.report["branches"]:
                    warnings.warn(f"branch {b.name!r}: the data measures none of its targets, so its own joints' "
                                  f"errors are not calibrated and compensating it is refused; measure "
                                  f"{', '.join(robot.branch_targets(b.name))} to calibrate it", stacklevel=2)
        if fitted.vertex_of:
            calib.report["orientation_length_m"] = fitted.pose_length
        if data.relative is not None:  # the errors "relative" in `eliminated` are those it cannot see
            calib.report["relative"] = data.relative.summary()
        self._set(calib, fit)
        self.placement_, self.cv_, self.counts_ = placement, cv, measured_counts(data)
        self.cm_, self.data_ = cm, data  # the model fitted (a measured frame as its vertices) and its data
        return self

    def _set(self, calib, fit=None):
        self.calibration_, self.fit_, self.report_, self.robot_ = calib, fit, calib.report, calib.robot
        self._cm = None

    def _fitted(self):
        if not hasattr(self, "calibration_"):
            raise ModelError("this Calibrator is not fitted yet: call fit(robot, data) first, or load one with "
                             "gecgen.load_calibration(path)")
        return self.calibration_

    def _model(self) -> CompiledModel:
        if self._cm is None:
            self._cm = CompiledModel(self.calibration_.robot, self.calibration_.model)
        return self._cm

    def _inputs(self, q, w, aux, what: str):
        """q (N, n), w (N, 6) and aux (N, naux) as float arrays, checked against the robot."""
        calib = self._fitted()
        n, names = calib.robot.n, calib.model.aux
        q = _floats(q, what, f"(N, {n}) joint values in m or rad")
        q = q[None] if q.ndim == 1 else q
        require(q.ndim == 2 and q.shape[1] == n, f"{what}: shape {np.shape(q)}; give (N, {n}) joint values in m or "
                                                 f"rad (robot {calib.robot.name} has {n} joints)")
        N = len(q)
        w = np.zeros((N, 6)) if w is None else _floats(w, "w", "the wrench fx..mz (N and N m) as (N, 6) or (6,)")
        w = w[None] if w.ndim == 1 else w
        require(w.shape in ((N, 6), (1, 6)),
                f"w: shape {w.shape}; give the wrench fx..mz (N and N m) as (N, 6) or (6,)")
        if isinstance(aux, dict):
            missing = [a for a in names if a not in aux]
            require(not missing, f"aux: no values for {excerpt(missing[0]) if missing else ''}, an auxiliary signal "
                                 f"the error model uses ({', '.join(names)})")
            aux = np.column_stack([np.broadcast_to(np.asarray(aux[a], float), (N,)) for a in names]) if names else None
        require(not names or aux is not None, f"aux: the error model uses auxiliary signals {', '.join(names)}; "
                                              f"pass aux as (N, {len(names)}) values in that order, or a dict by name")
        if names:
            aux = _floats(aux, "aux", f"(N, {len(names)}) values of {', '.join(names)}")
            aux = aux[None] if aux.ndim == 1 else aux
            require(aux.shape in ((N, len(names)), (1, len(names))),
                    f"aux: shape {aux.shape}; give (N, {len(names)}) values of {', '.join(names)}")
        else:
            aux = np.zeros((N, 0))
        for name, a in (("q", q), ("w", w), ("aux", aux)):
            bad = np.argwhere(~np.isfinite(a))
            require(not len(bad), f"{what if name == 'q' else name}: row {bad[0][0] if len(bad) else 0} is not "
                                  f"finite; give finite numbers")
        return q, np.broadcast_to(w, (N, 6)).copy(), np.broadcast_to(aux, (N, aux.shape[1])).copy()

    def _extrapolation(self, q, w, aux, inputs: set[str] | None = None) -> dict:
        calib = self.calibration_
        counts = _calibration.extrapolation(calib, q, w, aux, inputs)
        note = _calibration.extrapolation_note(counts, len(q), calib.robot)
        if note:
            warnings.warn(note, stacklevel=3)  # at the caller of score, predict or compensate
        return counts

    def predict(self, q, w=None, aux=None) -> np.ndarray:
        """Calibrated positions of every target (N, nt, 3) in m, in the robot world, at joint values
        q (N, n) m/rad, wrench w (N, 6) N and N m (default zero) and aux (N, naux) or {name: (N,)}
        (the error model's auxiliary signals, `calibration_.model.aux`). Targets in
        `robot_.target_names` order."""
        q, w, aux = self._inputs(q, w, aux, "q")
        cm = self._model()
        model = self.calibration_.model
        check_terms_finite(model, cm.robot, Commands(q, w, aux, model.aux, [], [], "q"), cm)
        self._sound(cm, q, w, aux)
        self._extrapolation(q, w, aux)
        return cm.model_targets(q, w, aux, self.calibration_.c)

    def _sound(self, cm, q, w, aux):
        """Refuse (RuntimeError) to score or predict with generalized errors no real robot has at these
        poses: an edited file (a coefficient of 1e300) or a calibration of another robot. (compensate
        names the rows whose correction overflows or fails instead.)"""
        from gecgen.fit.identify import absurd_error

        absurd = absurd_error(cm, q, w, aux, self.calibration_.c)
        if absurd:
            raise RuntimeError(f"the calibration's {absurd} at these poses: no real robot is that far from its model; "
                               f"the file was edited or belongs to another robot: identify again")

    def compensate(self, q_cmd, w=None, aux=None, max_iter: int = 50, branch: str | None = None,
                   bound=None) -> Compensation:
        """Corrected joint commands: the smallest joint change that puts the calibrated robot where the
        nominal one goes at q_cmd, with a status per row (`Compensation`): a row that cannot be placed
        (near a singular posture, bounded, not converged, overflowing) keeps its best correction and
        says so, and no row stops the others. q_cmd: (N, n) m/rad, or a CSV path or DataFrame of
        commands (q1..qn and optional fx..mz and aux columns; w and aux are then read from it). bound:
        the largest correction per joint, in the joint's unit (m or rad): one number for every joint,
        n numbers, or {joint name: value} (the others free); a joint that reaches it is held there and
        its row is BOUNDED. On a robot with branches, `branch` names the one whose tool is placed: its
        own joints are corrected, every other reading (the trunk's, the other branches') is held at its
        command."""
        calib = self._fitted()
        index = calib.robot.branch_index(branch)
        measured = calib.report.get("branches")  # the branches the data measured (older files: unknown)
        if calib.robot.branches and isinstance(measured, dict) and branch not in measured:
            raise ModelError(f"branch={excerpt(branch)}: the calibration's data measured no target of this branch "
                             f"(only of {', '.join(measured)}), so its own joints' errors were not calibrated and the "
                             f"correction would rest on the other branches' fit alone; measure "
                             f"{', '.join(calib.robot.branch_targets(branch))} and calibrate again")
        require(isinstance(max_iter, int) and max_iter >= 0,
                f"max_iter={excerpt(max_iter)}: give a non-negative number of Newton steps")
        limit = correction_bound(calib.robot, bound)
        if isinstance(q_cmd, Commands):
            cmds = q_cmd
        elif isinstance(q_cmd, (str, Path)) or hasattr(q_cmd, "to_csv"):
            cmds = read_commands(q_cmd, calib.robot, calib.model.aux)
        else:
            q, w, aux = self._inputs(q_cmd, w, aux, "q_cmd")
            cmds = Commands(q, w, aux, calib.model.aux, [], [], "q_cmd")
        cm = checked(calib.model, calib.robot, cmds)
        q, status, residual = cm.correct(cmds.q, cmds.w, cmds.aux, calib.c, max_iter=max_iter, branch=index,
                                         bound=limit)
        dq = np.abs(q - cmds.q)
        return Compensation(q, status, np.nonzero(status == OUTSIDE_LIMITS)[0].tolist(),
                            {name: float(dq[:, j].max()) for j, name in enumerate(calib.robot.joint_names)},
                            self._extrapolation(cmds.q, cmds.w, cmds.aux,
                                                _calibration.branch_inputs(calib.robot, calib.model, index)),
                            residual,
                            np.nonzero(np.isin(status, FAILED))[0].tolist())

    def score(self, data, register: bool | str = False) -> Score:
        """Errors of new measurements (CSV path, DataFrame or Measurements) before and after the
        calibration, in the calibration's tracker frames. register=True: the data was measured from
        a new tracker stationing; each side is scored in the frame fitted on the data (the
        calibration's coefficients held), so before and after differ by the calibration alone.
        register="auto": so when that frame is far from the calibration's (over 1 degree or 20 mm, as
        identify's "auto" decides) or a station is new, else in the calibration's frames; Score's
        `registrations` is None when it did not register."""
        from gecgen.fit.identify import fit_frames, to_world
        from gecgen.fit.registration import FAR_ANGLE_RAD, FAR_DISTANCE_M

        calib = self._fitted()
        data = read_measurements(data, calib.robot)
        length = self.orientation_length
        if length is None:  # the length scale the calibration was fitted with, if it measured frames
            length = calib.report.get("orientation_length_m")
        robot, data = on_points(calib.robot, _length(length), data)
        cm = checked(calib.model, robot, data)
        self._sound(cm, data.q, data.w, data.aux_columns(calib.model.aux))
        outside = self._extrapolation(data.q, data.w, data.aux_columns(calib.model.aux))
        moved = None
        _choice(register, "register", (True, False, "auto"))
        frames = fit_frames(cm, data, calib.c) if register else None
        if register == "auto":
            apart = [frames[k].relative_to(calib.frames[k]) if k in calib.frames else None for k in frames]
            register = any(a is None or np.radians(a["angle_deg"]) > FAR_ANGLE_RAD
                           or a["distance_mm"] > 1e3 * FAR_DISTANCE_M for a in apart)
        if register:
            y_before, y = to_world(fit_frames(cm, data, None), data), to_world(frames, data)
            known = calib.frames
            moved = {k: {**r.to_dict(), **r.relative_to(known.get(k, calib.registration))} for k, r in frames.items()}
        else:
            y = y_before = to_world(calib.frames, data, "the tracker was re-stationed: score it with register=True "
                                                        "(gecgen evaluate or calibrate --register)")
        counts = measured_counts(data)
        before, after = by_branch(cm, data, y_before, {"before": None}), by_branch(cm, data, y, {"after": calib.c})
        branches = {name: before[name] | after[name] for name in after}
        inside = None
        if outside:
            within = ~np.any(list(_calibration.outside(calib, data.q, data.w, data.aux_columns(calib.model.aux))
                                  .values()), axis=0)
            if within.any():
                inside = Errors.of(_summary(cm, data.subset(np.nonzero(within)[0]), y[within[data.pose]], calib.c, True))
        from gecgen.fit.identify import stray_placements

        for note in stray_placements(cm, data, calib.c):  # held-out sockets recorded badly score wrongly too
            warnings.warn(note, stacklevel=2)
        return Score(Errors.of(_summary(cm, data, y_before, None, True)),
                     Errors.of(_summary(cm, data, y, calib.c, True)),
                     counts["n_poses"], counts["n_points"], counts.get("n_orientations", 0), outside, moved,
                     cm, data, y_before, y, branches, inside)

    def save(self, path: str | Path) -> Path:
        """Write the calibration JSON (docs/reference.md, "Files"; read back by `load_calibration`, `gecgen
        evaluate`, `compensate` and `export`). Returns the path."""
        _calibration.save(self._fitted(), path)
        return Path(path)


def _ratio_loads(cm, fit, data) -> list[dict]:
    """The coupling ratios whose value depends on the loads (`loop.confounding`), each said."""
    from gecgen.loop.confounding import describe, ratio_load_confounding

    found = ratio_load_confounding(cm, fit, data)
    for item in found:
        warnings.warn(describe(item), stacklevel=3)
    return found


def _summary(cm, data, y, c, interval: bool = False) -> dict:
    """`fit.identify.summary` of data at coefficients c; with interval, the RMS's 95 %
    confidence interval by pose (mm) too."""
    from gecgen.fit import significance
    from gecgen.fit.identify import fixture_measures, row_errors, summary

    position, rotation, _ = row_errors(cm, data, y, c)
    out = summary(position, rotation)
    if interval:
        out["rms_mm_ci95"] = [1e3 * v for v in significance.rms_interval(position, data.pose[data.rows.first])]
    return out if data.relative is None else {**out, **fixture_measures(cm, data, c)}


def by_branch(cm, data, y, stages: dict) -> dict:
    """On a tree, per branch that the data measures: {stage: {rms_mm, max_mm}} for each of `stages`
    (name -> coefficients, None for the nominal model) over that branch's points; {} on a chain."""
    robot = cm.robot
    if not robot.branches:
        return {}
    side = np.array([robot.branch_of(robot.target_names[t]) for t in data.target])
    return {b.name: {stage: _summary(cm, data.rows_of(side == k), y[side == k], c) for stage, c in stages.items()}
            for k, b in enumerate(robot.branches) if (side == k).any()}


def load_calibration(path: str | Path, orientation_length: float | None = None) -> Calibrator:
    """A fitted Calibrator from a calibration file (refused when its robot file changed, or any
    number in it is not finite); fit_ is None (the file keeps the fit's report, `report_`)."""
    cal = Calibrator(orientation_length=orientation_length)
    cal._set(_calibration.load(path))
    cal.placement_, cal.cv_, cal.counts_ = None, cal.report_.get("cv", []), None
    return cal


# -- diagnose and calibrate ------------------------------------------------------------------

def _held_out(data, val, holdout, seed, robot):
    from gecgen.model.measurements import hold_out

    require(val is None or holdout is None, "give val or holdout, not both")
    val = None if val is None else read_measurements(val, robot)
    if holdout is not None:
        data, val = hold_out(data, holdout, seed)
    return data, val


class Diagnoser:
    """Trace the residual of a fit to missing effects, add them to the error model, refit.

    errors: the declared error model (as for Calibrator). register: "auto", "always" or "never", the
    registration of the training data; register_val: the validation data was measured from another
    tracker stationing, and each round's model re-fits its frame before scoring it. max_rounds:
    rounds at most. noise_mm: measurement noise per coordinate (mm), to say whether what remains is
    only noise (None: from repeated poses, if any). seed: of the hold-out split and the folds.
    holdout: share of the data's poses held out for the report when no val is given (None: an
    internal fifth). orientation_length: as for Calibrator.

    Fitted attributes: diagnosis_ (loop.diagnose.Diagnosis: before/after, history, remaining),
    effects_ (the effects added, loop.diagnose.Effect: error, terms, gain_mm, p_value),
    error_model_ (the new ErrorModel: pass it to Calibrator(errors=...)), verdict_ (one line: what
    remains), robot_ (targets placed), placement_, data_ (the training measurements fitted).
    """

    def __init__(self, errors=None, *, register: str = "auto", register_val: bool = False, max_rounds: int = 50,
                 noise_mm: float | None = None, seed: int = 0, holdout: float | None = None,
                 orientation_length: float | None = None):
        self.errors, self.register, self.register_val, self.max_rounds = errors, register, register_val, max_rounds
        self.noise_mm, self.seed, self.holdout, self.orientation_length = noise_mm, seed, holdout, orientation_length

    def fit(self, robot, data, val=None, progress=None) -> "Diagnoser":
        """Diagnose on `data` (CSV path, DataFrame or Measurements of `robot`); `val` is scored only,
        never used to choose terms. progress(round, rms_mm) is called each round. Returns self."""
        from gecgen.loop.confounding import describe
        from gecgen.loop.diagnose import diagnose, verdict

        register = _choice(self.register, "register", REGISTER)
        require(not self.register_val or val is not None,
                "register_val re-fits the tracker frame of the validation data: pass val")
        robot = _robot(robot)
        data, val = _held_out(read_measurements(data, robot), val, self.holdout, self.seed, robot)
        model = error_model(self.errors, robot, data.aux_names)
        robot, placement = placed(robot, data)
        fitted, data, val = on_points(robot, _length(self.orientation_length), data, val)
        checked(model, fitted, data, val)
        diag = diagnose(fitted, model, data, val, registration_mode=register, progress=progress,
                        noise_mm=self.noise_mm, max_rounds=self.max_rounds, seed=self.seed,
                        register_val=self.register_val)
        self.diagnosis_, self.effects_, self.error_model_ = diag, diag.effects, diag.final.model
        for item in diag.ratio_loads:
            warnings.warn(describe(item), stacklevel=2)
        self.verdict_, self.robot_, self.placement_, self.data_ = verdict(diag.remaining), robot, placement, data
        self.val_ = val  # None: diagnose held part of data out itself
        return self

    def save(self, path: str | Path) -> Path:
        """Write the new error model (YAML, each added effect commented). Returns the path."""
        from gecgen.loop.diagnose import write_error_model

        require(hasattr(self, "diagnosis_"), "this Diagnoser is not fitted yet: call fit(robot, data) first")
        write_error_model(self.robot_, self.error_model_, self.effects_, path)
        return Path(path)


@dataclass
class Selection:
    """`calibrate`: the model chosen on the training data and its calibration. model: the chosen
    candidate's name; table: every candidate's cross-validated RMS (mm); calibrator: a fitted
    Calibrator (score, predict, compensate, save); choice: loop.calibrate.Choice (its error model,
    fit and diagnosis); effects: what diagnose added, if the choice was diagnosed; counts: of the
    training data; val_before, val: the validation data's errors (nominal and calibrated), None
    without validation data; val_inside: as `Score.after_inside`; val_extrapolation: as
    `Score.extrapolation`, of the validation data."""

    model: str
    table: list[dict]
    calibrator: Calibrator
    choice: object
    effects: list
    counts: dict
    val_before: Errors | None
    val: Errors | None
    #: the training and validation data as fitted and scored (a measured frame as its vertices)
    data: Measurements | None = field(default=None, repr=False, compare=False)
    val_data: Measurements | None = field(default=None, repr=False, compare=False)
    #: on a tree, the validation data's errors per branch ({name: {before, after}}, as `Score.branches`)
    val_branches: dict = field(default_factory=dict)
    val_inside: Errors | None = None
    val_extrapolation: dict = field(default_factory=dict)


def model_names(names, label: str = "models") -> tuple[str, ...]:
    """The candidate names of `calibrate`, each one of loop.NAMES; `label` names them in
    messages."""
    from gecgen.loop import NAMES

    names = (names,) if isinstance(names, str) else tuple(names)
    unknown = [n for n in names if n not in NAMES]
    require(names and not unknown, f"{label}: {excerpt(unknown[0]) if unknown else 'none given'} is not a candidate; "
                                   f"choose from {', '.join(NAMES)}")
    return names


def calibrate(robot, data, val=None, *, holdout: float | None = None, errors=None,
              models: tuple[str, ...] | None = None, seed: int = 0, orientation_length: float | None = None,
              register_val: bool = False, progress=None, keep_insignificant: bool = False,
              noise_mm: float | None = None, register: str = "auto", stage=None) -> Selection:
    """The whole pipeline (gecgen/loop/calibrate.py says the rule): choose among `models` (default
    all of loop.NAMES) by 5-fold cross-validation on `data` alone, fit the choice on it,
    and score it on `val` (or on a `holdout` share of data's poses, split by `seed`) afterwards.
    errors: the robot's default model among the candidates (as for Calibrator; skipped when None
    and the robot has no error-model file). register_val: `val` was measured from another tracker
    stationing; it is scored as Calibrator.score(val, register=True) does. progress(name) is called
    per candidate, stage(text) with what it does once they are scored (the final fits, the
    significance test, the scoring of val). keep_insignificant, noise_mm, register (the training
    data's registration: "auto", "always" or "never"): as for Calibrator."""
    from gecgen.fit import significance
    from gecgen.loop import NAMES
    from gecgen.loop.calibrate import choose

    names = model_names(NAMES if models is None else models)
    register = _choice(register, "register", REGISTER)
    robot = _robot(robot)
    require(not register_val or val is not None, "register_val re-fits the tracker frame of the validation data: "
                                                 "pass val")
    data, raw_val = _held_out(read_measurements(data, robot), val, holdout, seed, robot)
    robot, placement = placed(robot, data)
    default = error_model(errors, robot, data.aux_names, constant=False)
    fitted, data, val = on_points(robot, _length(orientation_length), data, raw_val)
    if default is not None:
        checked(default, fitted, data, val)
    stage = stage or (lambda text: None)
    choice = choose(fitted, data, default, seed, registration_mode=register, progress=progress, names=names,
                    stage=stage)
    stage(f"testing which of the {choice.chosen.name} model's coefficients the data determine")
    fit, verdict = significance.determined(choice.cm, data, choice.fit, keep_insignificant, _noise(noise_mm))
    # the report's diagnosed stage is the delivered fit (insignificant coefficients held), not diagnose's own
    diagnosis = replace(choice.diagnosis, final=replace(choice.diagnosis.final, fit=fit)) if choice.diagnosis else None
    choice = replace(choice, fit=fit, diagnosis=diagnosis)
    calib = _calibration.from_fit(robot, choice.model, choice.fit, _ratio_loads(choice.cm, choice.fit, data))
    calib.report.update({"model": choice.chosen.name, "candidates": choice.table,
                         "placement": placement.to_dict() if placement else None, "significance": verdict})
    if fitted.vertex_of:
        calib.report["orientation_length_m"] = fitted.pose_length
    cal = Calibrator(choice.model, orientation_length=orientation_length, keep_insignificant=keep_insignificant)
    cal._set(calib, choice.fit)
    cal.placement_, cal.cv_, cal.counts_ = placement, [], measured_counts(data)
    effects = choice.diagnosis.effects if choice.diagnosis else []
    if raw_val is None:
        return Selection(choice.chosen.name, choice.table, cal, choice, effects, cal.counts_, None, None, data)
    stage(f"scoring the calibration on the {'validation' if holdout is None else 'held-out'} poses")
    scored = cal.score(raw_val, register=register_val)
    return Selection(choice.chosen.name, choice.table, cal, choice, effects, cal.counts_, scored.before, scored.after,
                     data, scored.data, scored.branches, scored.after_inside, scored.extrapolation)


# -- robot programs ------------------------------------------------------------------------------

@dataclass(frozen=True)
class ProgramTarget:
    """One target of a filtered program, in program order: `name` (as the program names it, or the
    motion and its line), `file` and `line` where its numbers are, `kind` "joint", "pose" or "motion"
    (a motion with no target of its own: a relative motion, a target set at run time, a position
    register); `before` its numbers as written and `after` as rewritten (the controller's text and
    units: mm and deg, UR m and rad; None when kept as written); `corrected`, and `reason`
    ("corrected", or why it is kept: "no correction needed", "outside the joint limits", "compensation
    singular", ...). The correction: `position_mm` and `rotation_deg` the move of its tool point and
    orientation (joint targets: the flange's) on the nominal robot, `joints_deg` the largest joint
    change (deg, UR's too), `residual_mm` the tool error the compensation leaves (1 rad as 1 m)."""

    name: str
    file: Path
    line: int
    kind: str
    before: tuple[str, ...]
    after: tuple[str, ...] | None
    corrected: bool
    reason: str
    position_mm: float = 0.0
    rotation_deg: float = 0.0
    joints_deg: float = 0.0
    residual_mm: float = 0.0


@dataclass(frozen=True)
class FilteredProgram:
    """`filter_program`: the program's `format` ("krl", "rapid", "tp" or "ur"), its `targets`
    (ProgramTarget, every one the filter found, corrected or kept), `corrected` how many were
    rewritten, `kept` those kept as written that still carry the uncalibrated error (the calibration
    would have moved them, or they are motions without a target of their own), `counts` the targets
    per reason ("corrected", "no correction needed", ...), `texts` each file's corrected text ({input
    path: text}; KRL: the .src and its .dat), `written` where each went and `log` the change log's
    path ({} and None when no output was given)."""

    format: str
    targets: list[ProgramTarget]
    corrected: int
    kept: list[ProgramTarget]
    counts: dict[str, int]
    texts: dict[Path, str]
    written: dict[Path, Path] = field(default_factory=dict)
    log: Path | None = None


def filter_program(calibrator, program: str | Path, output: str | Path | None = None, *,
                   frames: str | Path | None = None, format: str | None = None,
                   max_iter: int = 50) -> FilteredProgram:
    """What `gecgen filter` does: the robot program `program` (KUKA .src with its .dat beside it, ABB
    RAPID .mod/.modx/.prg, FANUC TP .ls, UR .script/.urscript; or `format` "krl", "rapid", "tp", "ur")
    with its targets corrected through `calibrator` (a fitted Calibrator or a calibration file's path)
    and every other byte as it was. With `output`, the corrected program is written there (KRL: its
    .dat beside it, under the program's name) with the change log OUTPUT.log.csv beside it; without,
    nothing is written and `texts` holds the result. `frames`: a YAML file with the tools, bases and
    flange the program names but does not declare. `max_iter`: Newton steps at most per compensation.
    Raises ModelError (one line naming the file and line) for a program the filter cannot read, a
    frame nobody describes, or a robot that is not a serial arm of six revolute joints."""
    from gecgen.deliver.programs import filter_program as run
    from gecgen.deliver.programs import program_format

    require(isinstance(calibrator, (Calibrator, str, Path)), f"calibrator: {excerpt(calibrator)} is neither a "
                                                             f"Calibrator nor a calibration file's path; give one")
    cal = calibrator if isinstance(calibrator, Calibrator) else load_calibration(calibrator)
    cal._fitted()
    outcome, written, log = run(cal, program, output, frames, format, max_iter)
    targets = {id(c): ProgramTarget(c.target.name, c.target.file, c.target.line, c.target.kind,
                                    tuple(n.text for n in c.target.numbers), c.after, c.after is not None, c.reason,
                                    c.position_mm, c.rotation_deg, c.joints_deg, c.residual_mm)
               for c in outcome.changes}
    return FilteredProgram(program_format(program, format).name, list(targets.values()), outcome.corrected,
                           [targets[id(c)] for c in outcome.kept], outcome.counts(), outcome.texts, written, log)


# -- planning images ------------------------------------------------------------------------------

@dataclass(frozen=True)
class ImageDesign:
    """What `design_images` chose: q (N, n) the joints to take the images at, in the order chosen;
    `design` the figures (`plan.camera_design.CameraDesign`: the designed set against as many random
    in-view candidates); n_sampled the candidates drawn or given, n_in_view those that keep
    everything in view."""

    q: np.ndarray
    design: object
    n_sampled: int
    n_in_view: int
    rig: object
    candidates: np.ndarray

    @property
    def random(self) -> np.ndarray:
        """(N, n) the joints of the random comparison: as many in-view candidates drawn at random."""
        return self.candidates[self.design.random]


def design_images(robot, cameras, rig, n_poses: int, *, board=None, errors=None, candidates=None, home=None,
                  span=None, seed: int = 0, criterion: str = "D", noise_px: float | None = None,
                  margin_px: float | None = None, max_angle_deg: float | None = None,
                  distance_m=None) -> ImageDesign:
    """What `gecgen design --cameras` does: n_poses poses at which every camera sees every board corner
    (a camera on the tool) or every marker (fixed cameras), chosen to inform the pixel fit most.
    robot: a Robot or its file; cameras: the camera file (or its cameras by name); board: the board
    file (or Board) a camera on the tool sees; rig: the rig file, where the cameras (and the board)
    are (`model.cameras.read_rig`); errors: the error model (default: the robot file's beside it).
    candidates: how many poses to draw uniformly in home +- span (rad or m; home defaults to the
    middle of each joint's range, span to `camera_design.SPAN`, one value or one per joint), or the
    joints (K, n) to choose from. The view: margin_px inside the image, max_angle_deg between the line
    of sight and the board's face (for markers, their tool's z axis; unchecked unless given), depths
    distance_m (near, far) m; defaults in `plan.camera_design`. noise_px scales the predicted figures."""
    from gecgen.model.cameras import Board, read_board, read_cameras, read_rig
    from gecgen.plan import camera_design as CD

    robot = _robot(robot)
    cams = cameras if isinstance(cameras, dict) else read_cameras(cameras)
    tool = next(iter(cams.values())).mount == "tool"
    require(not tool or board is not None, "the camera is on the tool: give the board it sees (--board)")
    require(tool or board is None, "--board goes with a camera on the tool (mount: tool); these cameras are fixed")
    board = board if board is None or isinstance(board, Board) else read_board(board)
    require(not (robot.branches and tool), f"{robot.source}: a tree; a camera on the tool is supported on serial "
                                           f"chains only: see the tree's markers with fixed cameras (mount: world)")
    require(tool or not robot.estimated, f"{robot.source}: targets {', '.join(robot.estimated)} are left to estimate; "
                                         f"a design needs every marker's place on the tool: give it in the robot file")
    poses, board_pose = rig if isinstance(rig, tuple) else read_rig(rig, cams, board)
    near, far = CD.DISTANCE_M if distance_m is None else tuple(float(d) for d in distance_m)
    require(0 <= near < far, f"--distance-m {near:g},{far:g}: give the nearest and farthest depth, 0 <= near < far (m)")
    setup = CD.Rig(cams, poses, board, board_pose, CD.MARGIN_PX if margin_px is None else float(margin_px),
                   max_angle_deg if max_angle_deg is not None or not tool else CD.MAX_ANGLE_DEG, (near, far))
    model = error_model(errors, robot)
    lo, hi = (np.array(v) for v in robot.sampling_box())
    if candidates is None or np.isscalar(candidates):
        n = CD.SAMPLED if candidates is None else int(candidates)
        centre = (lo + hi) / 2 if home is None else _floats(home, "home", f"{robot.n} joint values (rad or m)")
        half = np.array([CD.SPAN] if span is None else _floats(span, "span", "one value or one per joint"))
        require(len(centre) == robot.n and len(half) in (1, robot.n),
                f"--home, --span: give {robot.n} home values and one span or {robot.n} (rad or m)")
        a, b = np.maximum(lo, centre - half), np.minimum(hi, centre + half)
        require((a <= b).all(), f"--home: {excerpt(home)} is outside the joint limits; give joints within them")
        q = np.random.default_rng(seed).uniform(a, b, (n, robot.n))
    else:
        q = np.asarray(candidates, float)
        require(q.ndim == 2 and q.shape[1] == robot.n, f"candidates: give the joints (K, {robot.n}) to choose from")
    ok = CD.in_view(robot, setup, q)
    inside = q[ok]
    if len(inside) > CD.MAX_CANDIDATES:  # a seeded sample: the Jacobian of every one would cost minutes
        inside = inside[np.sort(np.random.default_rng([seed, 3]).choice(len(inside), CD.MAX_CANDIDATES, False))]
    d = CD.design_images(robot, model, setup, inside, n_poses, seed, CD.NOISE_PX if noise_px is None else noise_px,
                         criterion)
    return ImageDesign(inside[d.chosen], d, len(q), int(ok.sum()), setup, inside)
