"""diagnose: find the structure left in the residual, trace it to the effect the model lacks,
add it, regenerate, refit, and report before and after.

Each round:
1. Fit the current model (Gauss-Newton through the generated code).
2. Screen every candidate effect: a constant generalized error the model leaves out, or a
   generalized error e times a small group of new basis terms in one variable (higher powers of a joint; Fourier pairs over a scan of periods; sin/cos of a
   revolute joint, twice its angle, and of sums of parallel-axis joints; wrench or payload times
   a joint; auxiliary signals). The new columns are J_e[:, e] * f(pose); their worth is the drop
   in the residual sum of squares once the current model's columns are projected out, computed
   for all candidates of an error at once with one matrix product.
3. Decide on training data only, missing constant errors first (a small family, so a mild
   correction), then everything else: the best candidate must pass a chi-square test with a
   Bonferroni correction for the number of candidates tried in its tier, and must lower the k-fold
   cross-validated RMS (linearised at the current fit), and so must the choice itself: screening
   each fold's training poses alone and adding that fold's winner must predict the fold's held-out
   poses better (on real data, where the residual is never white noise, the winner of thousands
   of candidates passes any test on the poses it was picked on). The validation file, if any, is
   for the report only; nothing is chosen on it, nor on the training fit alone.
4. Candidates whose fitted effect is nearly the same vector as the winner's are reported as
   indistinguishable on this data.
5. Write the new error model, regenerate and compile its code, refit; repeat until nothing passes.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from gecgen.model.files import write_atomically
from gecgen.loop.confounding import ratio_load_confounding
from gecgen.loop.dictionary import candidates, refine_period, shown_family
from gecgen.loop.linear import Round, linear_system, pose_rows, weighted_J
from gecgen.loop.screening import MIN_CV_GAIN, Folded, Hit, folds, passing, screen, selection_cv_rms, significance_order
from gecgen.model.errors import ErrorModel
from gecgen.symbolic.terms import error_model_from_dict
from gecgen.model.measurements import Measurements
from gecgen.model.robot import ERROR_NAMES, Robot
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import fit_frames, identify, row_errors, squared_error, summary, to_world
from gecgen.fit.significance import T_MIN, noise_floor, noise_test
from gecgen.runtime.threads import one_blas_thread

#: rounds at most: a safety net, not the stopping rule (that is the statistics)
MAX_ROUNDS = 50
#: the strongest (candidate, error) pairs among which each cross-validation fold makes its own choice
SHORTLIST = 200
#: choices that fail the selection check before a tier is given up
SELECTION_TRIES = 3
#: candidates still listed as correlating with the final residual
CORRELATES = 5
#: fitted effects this similar (cosine) are indistinguishable on the data
SAME_EFFECT = 0.95


@dataclass
class Effect:
    error: str
    variables: list[str]
    terms: list[str]
    family: str
    gain_mm: float  # cross-validated RMS before minus after adding it
    p_value: float
    coefficients: list[dict] = field(default_factory=list)
    alternatives: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"error": self.error, "variables": self.variables, "terms": self.terms, "family": self.family,
                "gain_mm": self.gain_mm, "p_value": self.p_value, "coefficients": self.coefficients,
                "indistinguishable": self.alternatives}


@dataclass(frozen=True)
class Points:
    """Tracker points: how diagnose fits a model to them, linearises the fit and scores it (the loop
    itself does not care what was measured; `loop.pixels.ImagePoints` does the same for image points).
    registration_mode: of the training data; register_val: the validation data's frame is fitted
    before it is scored."""

    registration_mode: str = "auto"
    register_val: bool = False

    def fit(self, robot: Robot, model: ErrorModel, data: Measurements, quiet: bool = True) -> Round:
        """The model fitted; quiet: its warnings kept back (diagnose's rounds: conditioning is reported
        in the final fit, not per round)."""
        cm = CompiledModel(robot, model)
        with warnings.catch_warnings():
            if quiet:
                warnings.simplefilter("ignore")
            fit = identify(cm, data, registration_mode=self.registration_mode)
        return Round(model, cm, fit)

    @staticmethod
    def squared_error(rnd: Round, test: Measurements) -> tuple[float, float]:
        """(sum of squared point errors (m^2), the points they count for) of poses the fit did not see
        (`identify.squared_error`)."""
        return squared_error(rnd.cm, test, rnd.fit.to_world(test), rnd.fit.c)

    def system(self, rnd: Round, data: Measurements):
        """The fit's weighted linear system (H (3R, k), r (3R,)), each row's pose and degrees of freedom
        (3R,), and J_e (3R, ne), rows in the same order, each pose's adjacent (`loop.screening`)."""
        H, r = linear_system(rnd, data, rnd.fit.to_world(data))
        rows_pose, rows_dof, order = pose_rows(data)
        return H, r, rows_pose, rows_dof, weighted_J(rnd, data, order)

    @staticmethod
    def train_rms_mm(rnd: Round) -> float:
        return rnd.fit.train["rms_mm"]

    @staticmethod
    def noise(data: Measurements, robot: Robot, noise: float | None) -> dict | None:
        """The noise floor (`significance.noise_floor`); noise: mm per coordinate, when known."""
        return noise_floor(data, noise, robot)

    def scores(self, rnd: Round, val: Measurements) -> dict:
        return _scores(rnd, val, self.register_val)

    @staticmethod
    def remains(rnd: Round, data: Measurements, cv_rms_mm: float | None, noise: dict | None) -> dict:
        return what_remains(rnd, data, cv_rms_mm, noise)

    @staticmethod
    def confounding(rnd: Round, data: Measurements) -> list[dict]:
        return ratio_load_confounding(rnd.cm, rnd.fit, data)


def _with_terms(robot: Robot, model: ErrorModel, error: int, terms: tuple[str, ...], aux: tuple[str, ...]) -> ErrorModel:
    spec = model.to_yaml_dict(robot)
    frame, name = divmod(error, 6)
    block = spec["frames"].setdefault(frame, {})
    block[ERROR_NAMES[name]] = block.get(ERROR_NAMES[name], ["1"]) + list(terms)
    used_aux = sorted(set(spec.get("aux", [])) | {a for a in aux if any(a in t for t in terms)})
    if used_aux:
        spec["aux"] = used_aux
    return error_model_from_dict(spec, robot, "<diagnose>", aux)


@dataclass
class Diagnosis:
    robot: Robot
    initial: Round
    final: Round
    effects: list[Effect]
    rounds: int
    candidates_tested: int
    before: dict
    after: dict
    history: list[dict]
    remaining: dict
    #: the final model's coupling ratios whose value depends on the loads (`loop.confounding`)
    ratio_loads: list[dict] = field(default_factory=list)


def _choose(found: list[Hit], cands, fs: Folded, J, rows_pose, n_tests: int, base_cv: float):
    """The first candidate, most significant first, that passes the corrected chi-square test,
    lowers the cross-validated RMS, and whose choice cross-validates (`selection_cv_rms`): when a
    choice fails that check the next one is tried, with the failed one out of the folds' shortlist.
    Returns (hit, p, selection cv) or None."""
    shortlist = [(h.candidate, h.error) for h in found[:SHORTLIST]]
    for hit, p, _ in passing(found, cands, fs, J, rows_pose, n_tests, base_cv)[:SELECTION_TRIES]:
        cv = selection_cv_rms(fs, J, rows_pose, cands, shortlist)
        if cv < (1 - MIN_CV_GAIN) * base_cv:
            return hit, p, cv  # the gain reported is that of the choice, not of the winner
        shortlist.remove((hit.candidate, hit.error))
    return None


@one_blas_thread
def diagnose(robot: Robot, model: ErrorModel, data: Measurements, val: Measurements | None = None,
             registration_mode: str = "auto", seed: int = 0, progress=None, noise_mm: float | None = None,
             max_rounds: int = MAX_ROUNDS, register_val: bool = False, measure=None) -> Diagnosis:
    """Run the loop; without `val`, a seeded fifth of the poses is held out for the report.
    `noise_mm`: the measurement noise per coordinate (mm), when known; otherwise it is estimated
    from repeated poses of `data`, if any. It decides whether what remains is only noise. The loop
    stops when nothing passes the statistics, or after `max_rounds`. `register_val`: `val` was
    measured from another tracker stationing; each scored model fits its frame on it first. measure:
    what data holds and how it is fitted (`Points`, the default, with registration_mode and
    register_val; `loop.pixels.ImagePoints` for image points, whose noise is given in its own unit)."""
    measure = measure or Points(registration_mode, register_val)
    rng = np.random.default_rng(seed)
    noise = measure.noise(data, robot, noise_mm)
    if val is None:
        held = rng.permutation(data.n_poses)
        n_val = max(1, data.n_poses // 5)
        val, data = data.subset(np.sort(held[:n_val])), data.subset(np.sort(held[n_val:]))
    fold = folds(data.n_poses, rng)
    rnd = first = measure.fit(robot, model, data)
    if first.fit.failures:
        raise RuntimeError(f"the declared model's fit is not trustworthy: {first.fit.failures[0]}")
    effects: list[Effect] = []
    history, tested, correlates = [], 0, []
    loads: dict = {}  # the load candidates, the same every round (`dictionary.load_candidates`)
    for round_no in range(1, max_rounds + 1):
        if progress:
            progress(round_no, measure.train_rms_mm(rnd))
        H, r, rows_pose, rows_dof, J = measure.system(rnd, data)
        fs = Folded(H, r, rows_pose, fold, rows_dof)
        base = fs.basis()
        m, k = rows_dof.sum(), H.shape[1]
        sigma2 = float(r @ r) / (m - k)
        cands = candidates(rnd.cm, data, rng, loads)
        errors = [e for e in range(robot.n_errors) if np.any(J[:, e])]
        base_cv = fs.cv_rms()
        present = [{t.text for t in ts} for ts in rnd.model.terms]
        chosen, results = None, []
        # a missing constant error first (few candidates, so a mild multiplicity correction), then the rest
        for tier in (lambda c: c.family == "geometric", lambda c: c.family != "geometric"):
            indices = [k for k, c in enumerate(cands) if tier(c)]
            found = screen(J, rows_pose, r, base, sigma2, [cands[k] for k in indices], errors, indices)
            # a term the error already has (kept or eliminated) is never new, however its column moved
            found = [h for h in found if present[h.error].isdisjoint(cands[h.candidate].terms)]
            results += found
            n_tests = max(1, sum(len(errors) if cands[k].errors is None else len(cands[k].errors) for k in indices))
            tested += n_tests
            chosen = _choose(found, cands, fs, J, rows_pose, n_tests, base_cv)
            if chosen:
                break
        results.sort(key=significance_order)
        history.append({"round": round_no, "train_rms_mm": measure.train_rms_mm(rnd), "cv_rms_mm": 1e3 * base_cv,
                        "candidates": n_tests, "accepted": None})
        if chosen is None:
            correlates = [{"error": robot.error_names()[h.error], "terms": list(cands[h.candidate].terms),
                           "family": cands[h.candidate].family, "log10_p": h.log_p / np.log(10)}
                          for h in results[:CORRELATES]]
            break
        hit, p, cv = chosen
        e, c = hit.error, cands[hit.candidate]
        if c.family == "fourier":
            def drop_of(cand, e=e):
                found = screen(J, rows_pose, r, base, 0.0, [cand], [e])
                return found[0].drop if found else 0.0
            c = refine_period(c, data, drop_of)
        history[-1]["accepted"] = f"{robot.error_names()[e]}: {', '.join(c.terms)}"
        alternatives, seen = [], {(e, cands[hit.candidate].terms)}
        effect = hit.fitted / np.linalg.norm(hit.fitted)
        for h in results[:200]:
            key = (h.error, cands[h.candidate].terms)
            if key in seen or h.drop < 0.5 * hit.drop:
                continue
            seen.add(key)
            other = h.fitted
            cos = abs(other @ effect) / np.linalg.norm(other)
            if cos > SAME_EFFECT:
                alternatives.append({"error": robot.error_names()[h.error], "terms": list(key[1]),
                                     "similarity": float(cos)})
        new_model = _with_terms(robot, rnd.model, e, c.terms, data.aux_names)
        refit = measure.fit(robot, new_model, data)
        if refit.fit.failures:
            # an effect whose fit cannot be trusted is not added, however much it promised
            history[-1]["refused"] = f"{history[-1]['accepted']}: {refit.fit.failures[0]}"
            history[-1]["accepted"] = None
            break
        rnd = refit
        coefs = _effect_coefficients(robot, rnd, e, len(c.terms))
        effects.append(Effect(robot.error_names()[e], list(c.variables), list(c.terms), shown_family(c, data),
                              1e3 * (base_cv - cv), p, coefs, alternatives[:5]))
    rnd, effects, dropped = _drop_insignificant(robot, rnd, effects, data, measure.fit)
    before, after = measure.scores(first, val), measure.scores(rnd, val)
    # the last round's CV is the final model's unless that round added an effect (the round cap) or
    # an effect was dropped since
    final_cv = history[-1]["cv_rms_mm"] if history[-1]["accepted"] is None and not dropped else None
    remaining = {**measure.remains(rnd, data, final_cv, noise), "correlates": correlates,
                 "stopped": "round cap" if history[-1]["accepted"] else "nothing passes the statistics",
                 "dropped": dropped}
    return Diagnosis(robot, first, rnd, effects, len(history), tested, before, after, history, remaining,
                     measure.confounding(rnd, data))


#: largest residual points listed when structure remains
LARGEST = 5


def what_remains(rnd: Round, data: Measurements, cv_rms_mm: float | None, noise: dict | None) -> dict:
    """Whether the final residual is only noise, and what is left when it is not.

    `covered` is True when the fit's residual sigma passes an F test against the noise floor,
    False when it fails it, None when the noise is unknown (no repeated poses, no --noise-mm):
    then nobody can say that the model covers the data, only that nothing in the dictionary
    explains what remains."""
    fit, robot = rnd.fit, rnd.cm.robot
    rows = data.rows
    pos, rot, length = row_errors(rnd.cm, data, fit.to_world(data), fit.c)
    e = length * np.sqrt(3 / rows.row_dof)  # as the robust fit scales it
    inliers = np.nonzero(e <= fit.outlier_limit_m)[0]  # outliers are counted, not ranked with the rest
    top = inliers[np.argsort(-e[inliers])[:LARGEST]]
    names = robot.target_names
    out = {"train_rms_mm": fit.train_inliers["rms_mm"], "cv_rms_mm": cv_rms_mm, "sigma_mm": 1e3 * fit.sigma_m,
           "noise": noise, "covered": None, "outliers": len(fit.outliers),
           "largest": [{"row": int(data.file_rows[r]), "pose": int(data.pose_ids[data.pose[r]]),
                        "target": robot.vertex_of.get(names[data.target[r]], (names[data.target[r]],))[0],
                        "residual_mm": 1e3 * float(pos[g]),
                        **({} if np.isnan(rot[g]) else {"rotation_mrad": 1e3 * float(rot[g])})}
                       for g, r in zip(top, rows.first[top])]}
    if noise is not None and noise["noise_mm"] > 0:
        covered, p, ratio = noise_test(fit.sigma_m, max(fit.measured_dof - len(fit.redundancy.kept), 1), noise)
        out.update(covered=covered, noise_p_value=p, sigma_over_noise=ratio)
    return out


def verdict(remaining: dict) -> str:
    """One sentence for a person on what the final model leaves in the data."""
    r = remaining
    if r["covered"]:
        return (f"The residual ({r['sigma_mm']:.4f} mm per coordinate) is consistent with the measurement noise "
                f"({r['noise']['noise_mm']:.4f} mm, {r['noise']['source']}): the model covers the data.")
    # image points are ranked by their pixel residual, so it leads
    largest = ", ".join(f"row {p['row']} (" + (f"{p['residual_px']:.3f} px, " if "residual_px" in p else "")
                        + f"{p['residual_mm']:.3f} mm)" for p in r["largest"][:3])
    cv = f", cross-validated {r['cv_rms_mm']:.4f} mm" if r["cv_rms_mm"] is not None else ""
    outliers = f" without its {r['outliers']} outliers" if r["outliers"] else ""
    what = f"Structure remains: training RMS{outliers} {r['train_rms_mm']:.4f} mm{cv}; largest residuals {largest}"
    if r["covered"] is False:
        return (f"{what}. The residual is {r['sigma_over_noise']:.2f}x the noise floor ({r['noise']['noise_mm']:.4f} mm, "
                f"{r['noise']['source']}) and nothing in the candidate dictionary explains the rest.")
    how = ("give the corners' noise, --noise-px" if "sigma_px" in r
           else "no repeated poses; give --noise-mm, noise_mm in Python")
    return (f"{what}. The noise floor is unknown ({how}), so whether the model covers "
            f"the data cannot be decided; nothing in the candidate dictionary explains the rest.")


def _strength(robot: Robot, rnd: Round, effect: Effect) -> float:
    """The largest |value| / std of an effect's coefficients in the fit of `rnd` (0 when none has a
    finite std: the fit eliminated them all)."""
    names = rnd.model.coefficient_names(robot)
    t = [abs(rnd.fit.c[j]) / rnd.fit.std[j] for j in (names.index(c["name"]) for c in effect.coefficients)
         if np.isfinite(rnd.fit.std[j]) and rnd.fit.std[j] > 0]
    return max(t, default=0.0)


def _drop_insignificant(robot: Robot, rnd: Round, effects: list[Effect], data: Measurements,
                        fit) -> tuple[Round, list[Effect], list[dict]]:
    """Backward elimination of effects: while the weakest effect has no coefficient with |value| /
    std of at least T_MIN in the final fit, its terms are removed and the model refitted. An effect
    added early can end insignificant once later ones explain what it did (on the PPS paper design,
    0.er's fx, added first, ends at 0.0049 +- 0.0063 mrad/N). fit(robot, model, data): a Round. Returns the final round, the effects
    left (their coefficients as finally fitted) and the dropped ones ({error, terms, t})."""
    dropped = []
    while effects:
        weakest = min(effects, key=lambda eff: _strength(robot, rnd, eff))
        t = _strength(robot, rnd, weakest)
        if t >= T_MIN:
            break
        spec = rnd.model.to_yaml_dict(robot)
        frame, name = weakest.error.split(".")
        labels = [t.label for t in rnd.model.terms[robot.error_names().index(weakest.error)]]
        kept_labels = [x for x in labels if x not in weakest.terms]
        if kept_labels == labels:
            break  # its terms are not in the model as written: nothing to remove
        spec["frames"].setdefault(int(frame), {})[name] = kept_labels
        refit = fit(robot, error_model_from_dict(spec, robot, "<diagnose>", data.aux_names), data)
        if refit.fit.failures:
            break  # the model with the effect is the trustworthy one
        rnd, effects = refit, [e for e in effects if e is not weakest]
        dropped.append({"error": weakest.error, "terms": weakest.terms, "t": t})
    names = rnd.model.coefficient_names(robot)
    for eff in effects:  # as finally fitted
        eff.coefficients = [{"name": c["name"], "value": float(rnd.fit.c[j]),
                             "std": float(rnd.fit.std[j]) if np.isfinite(rnd.fit.std[j]) else None}
                            for c, j in ((c, names.index(c["name"])) for c in eff.coefficients)]
    return rnd, effects, dropped


def _effect_coefficients(robot: Robot, rnd: Round, error: int, n_new: int) -> list[dict]:
    """Fitted value and standard deviation of the n_new terms just added to `error`."""
    new = {t.text for t in rnd.model.terms[error][-n_new:]}
    names = rnd.model.coefficient_names(robot)
    # a term the refit eliminated (merged into others) has no std of its own: null, not NaN
    return [{"name": names[j], "value": float(rnd.fit.c[j]),
             "std": float(rnd.fit.std[j]) if np.isfinite(rnd.fit.std[j]) else None}
            for j, c in enumerate(rnd.model.coefficients) if c.error == error and c.term.text in new]


def _scores(rnd: Round, val: Measurements, register: bool) -> dict:
    """Training RMS and validation RMS and max (mm), and with measured orientations the same in
    mrad (`train_rot_rms_mrad`, `val_rot_rms_mrad`, `val_rot_max_mrad`); `register`: in val's own
    fitted frame."""
    frames = fit_frames(rnd.cm, val, rnd.fit.c) if register else rnd.fit.registrations
    yv = to_world(frames, val, "use diagnose --register")
    s = summary(*row_errors(rnd.cm, val, yv, rnd.fit.c)[:2])
    out = {"train_rms_mm": rnd.fit.train["rms_mm"], "val_rms_mm": s["rms_mm"], "val_max_mm": s["max_mm"]}
    if "rot_rms_mrad" in rnd.fit.train:
        out["train_rot_rms_mrad"] = rnd.fit.train["rot_rms_mrad"]
    if "rot_rms_mrad" in s:
        out.update(val_rot_rms_mrad=s["rot_rms_mrad"], val_rot_max_mrad=s["rot_max_mrad"])
    return out


def write_error_model(robot: Robot, model: ErrorModel, effects: list[Effect], path: str | Path):
    """The model as an error-model file, with a header naming what diagnose added."""
    lines = [f"# Error model of {robot.name} written by gecgen diagnose."]
    lines += [f"# added: {e.error} <- {', '.join(e.terms)} (cross-validated gain {e.gain_mm:.4f} mm)" for e in effects]
    if not effects:
        lines.append("# diagnose found nothing in its candidate dictionary to add; the model is unchanged")
    spec = model.to_yaml_dict(robot)
    write_atomically(path, "\n".join(lines) + "\n" + yaml.safe_dump(spec, sort_keys=False, width=120))
