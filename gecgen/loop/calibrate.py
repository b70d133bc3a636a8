"""calibrate: the whole pipeline, with the model chosen on the training data alone.

The candidates are ways of fitting a model, not just models:

* geometric: six constant generalized errors per frame (classical calibration, any robot);
* default: the robot's own error model (robots/NAME.errors.yaml), when it has one;
* elastic: geometric plus joint compliance, each joint's own angle error (the generalized error
  that turns or slides about its axis, `loop.dictionary.frame_own_errors`) times the loads it
  carries: the gravity torque from the URDF's masses when the robot has them, the torque of the
  measured wrench when the data has one (a coupled or passive joint: its own frame's moment);
* diagnosed: diagnose run from the geometric model (its terms chosen on the data).

The rule (docs/real-data-tiago.md used it first): every candidate is run whole inside each of 5
folds of the training poses (the poses split at random, seeded), so that diagnose's choices are
made again on each fold's other poses alone, and is scored on all measured points of the
held-out poses. The lowest cross-validated RMS is the choice; ties within 1% go to the candidate
with fewer coefficients, counted in the model it delivers: a diagnosed candidate's is what diagnose
builds on all the training poses, not its start. The chosen candidate is then fitted on all the
training poses.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from gecgen.loop import NAMES
from gecgen.loop.diagnose import Diagnosis, Points, diagnose
from gecgen.loop.linear import Round
from gecgen.loop.dictionary import frame_own_errors, loads_by_joint
from gecgen.model.errors import ErrorModel
from gecgen.symbolic.terms import error_model_from_dict
from gecgen.model.measurements import Measurements
from gecgen.model.robot import ERROR_NAMES, MATCHING, Robot
from gecgen.model.validation import ModelError
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import Fit
from gecgen.runtime.processes import mapped, side_by_side

FOLDS = 5
#: cross-validated RMS this close (relative) counts as a tie, won by the smaller model
TIE = 0.01


@dataclass(frozen=True)
class Pipeline:
    """One way of fitting: a start model, and whether diagnose extends it on the data."""

    name: str
    model: ErrorModel
    diagnose: bool = False


@dataclass
class Choice:
    """What calibrate chose and why: every pipeline's cross-validated RMS (mm, `None` when it
    could not be fitted in some fold, with the reason), the chosen one fitted on all the data."""

    table: list[dict]
    chosen: Pipeline
    model: ErrorModel
    cm: CompiledModel
    fit: Fit
    diagnosis: Diagnosis | None


def elastic_spec(robot: Robot, data: Measurements, seed: int = 0) -> dict | None:
    """Error-model spec of geometric + joint compliance under the loads the robot and the data
    give (gravity from known masses, the measured wrench), for every joint whose own error exists
    and whose load varies over the data; None when no joint has one. A joint that is its reading's
    only frame takes the reading's torques; a coupled or passive one its own frame's moment about
    that error's axis (`gravity_load`, `wrench_load`: what its reading feels is summed over frames)."""
    geometric = error_model_from_dict({"default": ["1"]}, robot, "<geometric>")
    names, values = CompiledModel(robot, geometric).load_signals(data.q, data.w)
    by_joint = loads_by_joint(names, values)
    varies = {n for n, v in zip(names, values.T) if np.ptp(v) > 1e-12 * max(1.0, float(np.abs(v).max()))}
    alone = {robot.frame_of(i): i for i in range(robot.n) if len(robot.driven(i)) == 1}
    frames: dict[int, dict[str, list[str]]] = {}
    for frame, error in frame_own_errors(robot, np.random.default_rng(seed)).items():
        f, e = divmod(error, 6)
        if frame in alone:
            loads = by_joint.get(alone[frame], {})
            terms = [names[k] for k in loads.get("gravity_torque", []) + loads.get("wrench_torque", [])]
        else:
            terms = [n for n in (f"{kind}({f},{MATCHING[e]})" for kind in ("gravity_load", "wrench_load"))
                     if n in varies]
        if terms:
            frames.setdefault(f, {})[ERROR_NAMES[e]] = ["1", *terms]
    return {"default": ["1"], "frames": frames} if frames else None


def pipelines(robot: Robot, data: Measurements, default: ErrorModel | None,
              names: tuple[str, ...] = NAMES) -> list[Pipeline]:
    """The candidates of the module docstring that apply to this robot and data, of those named."""
    geometric = error_model_from_dict({"default": ["1"]}, robot, "<geometric>")
    out = [Pipeline("geometric", geometric)]
    if default is not None and default.to_yaml_dict(robot) != geometric.to_yaml_dict(robot):
        out.append(Pipeline("default", default))
    spec = elastic_spec(robot, data)
    if spec:
        out.append(Pipeline("elastic", error_model_from_dict(spec, robot, "<elastic>")))
    out.append(Pipeline("diagnosed", geometric, diagnose=True))
    return [p for p in out if p.name in names]


def run_pipeline(robot: Robot, pipeline: Pipeline, data: Measurements,
                 measure=None) -> tuple[ErrorModel, CompiledModel, Fit, Diagnosis | None]:
    """Fit one pipeline on `data`: (final model, its compiled code, the fit, diagnose's record).
    measure: what data holds and how it is fitted (`loop.diagnose.Points`, the default, or
    `loop.pixels.ImagePoints`)."""
    measure = measure or Points()
    if pipeline.diagnose:
        # the second `data` is only reported on: diagnose then chooses on every pose it is given
        diag = diagnose(robot, pipeline.model, data, data, measure=measure)
        return diag.final.model, diag.final.cm, diag.final.fit, diag
    rnd = measure.fit(robot, pipeline.model, data, quiet=False)
    return pipeline.model, rnd.cm, rnd.fit, None


def fold_score(robot: Robot, pipeline: Pipeline, data: Measurements, fold: np.ndarray, f: int,
               measure=None) -> tuple[float, float]:
    """(sum of squared errors (m^2), the points they count for) over all measured points of the poses
    of fold f (fold (P,) each pose's fold), a measured frame counting as two
    (`identify.squared_error`; image points in m at the target), the pipeline run whole on the other
    folds. Raises RuntimeError when the fold's fit cannot be trusted."""
    measure = measure or Points()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # conditioning warnings of the fold fits; the score says it all
        model, cm, fit, _ = run_pipeline(robot, pipeline, data.subset(np.nonzero(fold != f)[0]), measure)
    if fit.failures:
        raise RuntimeError(f"fold {f + 1}: {fit.failures[0]}")
    return measure.squared_error(Round(model, cm, fit), data.subset(np.nonzero(fold == f)[0]))


def _scored(*task) -> tuple[float, float] | str:
    """fold_score of one task, or why it was refused (returned, not raised, as a worker process
    would: a fold too small, an untrustworthy fit)."""
    try:
        return fold_score(*task)
    except (RuntimeError, ModelError) as exc:
        return str(exc).splitlines()[0]


def _fitted_ahead(robot: Robot, pipeline: Pipeline, data: Measurements, measure):
    """run_pipeline before the choice: (its result, or the RuntimeError or ModelError it raised; the
    warnings it issued), held until it is known to be the choice's."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        try:
            return run_pipeline(robot, pipeline, data, measure), said
        except (RuntimeError, ModelError) as exc:
            return exc, said


def _row(table: list[dict], p: Pipeline) -> dict:
    return next(r for r in table if r["model"] == p.name)


def choose(robot: Robot, data: Measurements, default: ErrorModel | None, seed: int = 0,
           registration_mode: str = "auto", progress=None, names: tuple[str, ...] = NAMES, stage=None,
           measure=None) -> Choice:
    """Score the named pipelines that apply (see the module docstring) on the training data, fit
    the choice on all of it. progress(name) is called per candidate while its folds run, stage(text)
    with what it does after them. measure: as for `run_pipeline` (default: tracker points registered
    as registration_mode says). Raises RuntimeError when none applies or can be fitted, or when the
    chosen fit cannot be trusted."""
    stage = stage or (lambda text: None)
    measure = measure or Points(registration_mode)
    if data.n_poses < 2 * FOLDS:
        raise RuntimeError(f"{data.n_poses} poses: the model is chosen by {FOLDS}-fold cross-validation over poses, "
                           f"which needs at least {2 * FOLDS}; measure more poses")
    table, scored = [], []
    candidates = pipelines(robot, data, default, names)
    if not candidates:
        raise RuntimeError(f"none of the models {', '.join(names)} applies to this robot and data (default: the robot "
                           f"has no error-model file; elastic: neither URDF masses nor a wrench that varies)")
    fold = np.random.default_rng(seed).permutation(data.n_poses) % FOLDS
    # the folds are independent fits, scored side by side (`runtime.processes`), diagnose's (the long
    # ones) first so that the quick ones fill in around them; the sums below add each candidate's folds
    # in fold order, so the figures do not depend on how many processes ran them
    order = sorted(range(len(candidates)), key=lambda i: not candidates[i].diagnose)
    tasks = [(i, f) for i in order for f in range(FOLDS)]
    ahead = None
    with mapped([(_scored, (robot, candidates[i], data, fold, f, measure)) for i, f in tasks]) as results:
        if side_by_side(len(tasks)) > 1 and candidates[order[0]].diagnose:
            # while the workers score the folds, this process fits the longest candidate on all the data:
            # it is most often the choice, and otherwise the time would have been spent waiting. Its
            # failure matters only if it is chosen, and is raised then, as it would be after the choice.
            if progress:
                progress(candidates[order[0]].name)
            ahead = candidates[order[0]], *_fitted_ahead(robot, candidates[order[0]], data, measure)
        scores = {}
        for i in order:  # a candidate's name while its folds are awaited
            if progress:
                progress(candidates[i].name)
            scores.update({(i, f): next(results) for f in range(FOLDS)})
        for i, p in enumerate(candidates):
            folds = [scores[i, f] for f in range(FOLDS)]
            refused = next((r for r in folds if isinstance(r, str)), None)
            cv = None if refused is not None else 1e3 * float(np.sqrt(sum(sq for sq, _ in folds) /
                                                                    sum(m for _, m in folds)))
            table.append({"model": p.name, "cv_rms_mm": cv, "n_params": len(p.model.coefficients),
                          "diagnose": p.diagnose, **({"refused": refused} if refused is not None else {})})
            if cv is not None:  # else too few poses for it, or an untrustworthy fold fit
                scored.append((cv, p))
    if not scored:
        raise RuntimeError(f"no candidate model could be fitted in every fold ({table[0]['refused']})")
    best = min(cv for cv, _ in scored)
    tied = [s for s in scored if s[0] <= best * (1 + TIE)]
    # the size that breaks a tie is the delivered model's: diagnose's is known once it has run on all the data
    full = {ahead[0].name: ahead[1:]} if ahead else {}
    for _, p in tied:
        if p.diagnose and len(tied) > 1 and p.name not in full:
            stage(f"fitting the {p.name} model on all {data.n_poses} training poses: it ties the best, and the "
                  f"smaller of them is chosen")
            full[p.name] = _fitted_ahead(robot, p, data, measure)
    for _, p in tied:
        fitted = full.get(p.name, (None,))[0]
        if p.diagnose and fitted is not None and not isinstance(fitted, Exception):
            _row(table, p)["n_params_delivered"] = len(fitted[0].coefficients)

    def size(p: Pipeline) -> float:
        delivered = _row(table, p).get("n_params_delivered")
        # diagnose only ever adds to its start model: at the same size it counts as the larger one
        return (len(p.model.coefficients) if delivered is None else delivered) + p.diagnose / 2

    chosen = min(tied, key=lambda s: (size(s[1]), s[0]))[1]
    if chosen.name in full:
        fitted, said = full[chosen.name]
        for w in said:  # what the fit says, said now that it is the choice's
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if isinstance(fitted, Exception):
            raise fitted
        model, cm, fit, diag = fitted
    else:
        stage(f"fitting the chosen {chosen.name} model on all {data.n_poses} training poses")
        model, cm, fit, diag = run_pipeline(robot, chosen, data, measure)
    if chosen.diagnose:
        _row(table, chosen)["n_params_delivered"] = len(model.coefficients)
    if fit.failures:
        raise RuntimeError(f"the chosen model ({chosen.name}) cannot be trusted on all the data: {fit.failures[0]}")
    return Choice(table, chosen, model, cm, fit, diag)
