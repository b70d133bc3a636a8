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
from scipy import stats

from gecgen.files import write_atomically
from gecgen.model.errors import ErrorModel, error_model_from_dict
from gecgen.model.kinematics import constant, frames
from gecgen.model.measurements import Measurements
from gecgen.model.robot import ERROR_NAMES, WRENCH, Robot
from gecgen.runtime.compiled import CompiledModel
from gecgen.runtime.identify import Fit, identify, position_errors, rows_H_and_residual, summary

#: family-wise false-alarm rate of one screening round
ALPHA = 1e-3
#: a candidate must lower the cross-validated RMS by at least this fraction
MIN_CV_GAIN = 0.01
FOLDS = 5
MAX_ROUNDS = 8
PERIODS = 40
#: a candidate's columns must keep this share of their squared norm outside the current model
MIN_INDEPENDENCE = 1e-6
#: the strongest (candidate, error) pairs among which each cross-validation fold makes its own choice
SHORTLIST = 200
#: fitted effects this similar (cosine) are indistinguishable on the data
SAME_EFFECT = 0.95


@dataclass(frozen=True)
class Candidate:
    """A group of new terms, all in the variables `variables`, for one generalized error."""

    family: str
    variables: tuple[str, ...]
    terms: tuple[str, ...]
    values: np.ndarray  # (P, len(terms)) term values per pose


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


def _range(v: np.ndarray) -> float:
    return float(v.max() - v.min()) if len(v) else 0.0


def parallel_joint_groups(robot: Robot, rng: np.random.Generator) -> list[tuple[int, ...]]:
    """Runs of consecutive revolute joints whose axes stay parallel (e.g. shoulder and elbow)."""
    lo = np.array([max(j.lower, -np.pi) for j in robot.joints])
    hi = np.array([min(j.upper, np.pi) for j in robot.joints])
    q = rng.uniform(lo, hi, (16, robot.n))
    W = frames(robot, q)
    axes = [W[i][:, :3, :3] @ constant(j.pre)[:3, :3] @ np.array([float(a) for a in j.axis])
            for i, j in enumerate(robot.joints)]
    groups, run = [], [0]
    for i in range(1, robot.n):
        both_r = robot.joints[i].kind == robot.joints[run[-1]].kind == "R"
        if both_r and np.allclose(np.cross(axes[run[-1]], axes[i]), 0, atol=1e-9):
            run.append(i)
        else:
            if len(run) > 1:
                groups.append(tuple(run))
            run = [i]
    if len(run) > 1:
        groups.append(tuple(run))
    return groups


def fourier_candidate(name: str, v: np.ndarray, period: float) -> Candidate:
    """sin and cos of 2 pi v / period (period rounded to 4 significant digits, as written)."""
    period = float(f"{period:.4g}")
    a = 2 * np.pi * v / period
    return Candidate("fourier", (name,), (f"sin(2*pi*{name}/{period:g})", f"cos(2*pi*{name}/{period:g})"),
                     np.column_stack([np.sin(a), np.cos(a)]))


def refine_period(best: Candidate, data: Measurements, screen_one) -> Candidate:
    """A fine scan of periods around a Fourier winner of the coarse scan (one grid step each way)."""
    name = best.variables[0]
    v = data.q[:, int(name[1:]) - 1]
    period = float(best.terms[0].split("/")[-1].rstrip(")"))
    span = _range(v)
    step = (2 * span / max(span / 60, 1e-12)) ** (1 / (PERIODS - 1))
    fine = [fourier_candidate(name, v, p) for p in np.geomspace(period / step, period * step, 41)]
    return max(fine, key=screen_one)


def candidates(robot: Robot, model: ErrorModel, data: Measurements, rng: np.random.Generator) -> list[Candidate]:
    """Every candidate term group the data can support (variables that actually vary)."""
    out: list[Candidate] = []
    present = {t.text for ts in model.terms for t in ts}

    def add(family, variables, terms, values):
        out.append(Candidate(family, tuple(variables), tuple(terms), np.column_stack(values)))

    moving = [i for i in range(robot.n) if _range(data.q[:, i]) > 1e-9]
    # a constant generalized error the model leaves out (screen() only pairs it with errors that lack it)
    add("geometric", [], ["1"], [np.ones(data.n_poses)])
    for i in moving:
        v, name, joint = data.q[:, i], f"q{i + 1}", robot.joints[i]
        top = max([k for k in range(1, 9) if f"{name}**{k}" in present or (k == 1 and name in present)], default=0)
        for k in range(1, top + 3):  # every order up to two above the model's highest
            add("polynomial", [name], [f"{name}**{k}" if k > 1 else name], [v ** k])
        if joint.kind == "R":
            add("trigonometric", [name], [f"sin({name})", f"cos({name})"], [np.sin(v), np.cos(v)])
            add("trigonometric", [name], [f"sin(2*{name})", f"cos(2*{name})"], [np.sin(2 * v), np.cos(2 * v)])
        span = _range(v)
        if joint.kind == "P" or span < np.pi:
            distinct = np.unique(v)
            spacing = np.median(np.diff(distinct)) if len(distinct) > 2 else span / 2
            # at least four distinct values of the variable per period, or a sinusoid can alias through the data
            shortest = max(2.5 * spacing, span / 60, 4 * span / max(len(distinct), 1))
            for period in np.geomspace(shortest, 2 * span, PERIODS) if 2 * span > shortest else ():
                out.append(fourier_candidate(name, v, period))
    for group in parallel_joint_groups(robot, rng):
        for a, b in zip(group, group[1:]):
            names = [f"q{a + 1}", f"q{b + 1}"]
            s = data.q[:, a] + data.q[:, b]
            add("trigonometric", names, [f"sin({names[0]} + {names[1]})", f"cos({names[0]} + {names[1]})"],
                [np.sin(s), np.cos(s)])
    wrench = [k for k in range(6) if _range(data.w[:, k]) > 1e-9]
    for k in wrench:
        f, fn = data.w[:, k], WRENCH[k]
        add("wrench", [fn], [fn], [f])
        for i in moving:
            name = f"q{i + 1}"
            add("wrench x joint", [fn, name], [f"{fn}*{name}"], [f * data.q[:, i]])
            add("wrench x joint", [fn, name], [f"{fn}*{name}**2"], [f * data.q[:, i] ** 2])
    force = np.linalg.norm(data.w[:, :3], axis=1)
    # only when the force turns in the sensor frame does its magnitude differ from one component
    if sum(_range(data.w[:, k]) > 0.01 * _range(force) for k in range(3)) > 1:
        # the payload's weight, whatever direction the sensor sees it in
        magnitude = "sqrt(fx**2 + fy**2 + fz**2)"
        add("payload", ["payload"], [magnitude], [force])
        for i in moving:
            add("payload x joint", ["payload", f"q{i + 1}"], [f"{magnitude}*q{i + 1}"], [force * data.q[:, i]])
    for k, a in enumerate(data.aux_names):
        v = data.aux[:, k]
        if _range(v) > 1e-12 * max(1.0, np.abs(v).max()):
            add("auxiliary", [a], [a], [v])
            add("auxiliary", [a], [f"{a}**2"], [v ** 2])
    return out


def screen(J: np.ndarray, rows_pose: np.ndarray, resid: np.ndarray, Q: np.ndarray, sigma2: float,
           cands: list[Candidate], errors: list[int]) -> list[tuple[float, int, int, np.ndarray]]:
    """(drop in RSS, candidate index, error index, projected fitted effect (3R,)) for every pair.

    J (3R, ne) is J_e at the current fit for the measured rows; rows_pose (3R,) the pose of each
    row; resid (3R,) is orthogonal to the columns of Q (3R, k).
    """
    results = []
    F = np.concatenate([c.values for c in cands], axis=1)[rows_pose]  # (3R, total columns)
    sizes = [c.values.shape[1] for c in cands]
    starts = np.cumsum([0] + sizes)
    for e in errors:
        X = J[:, e:e + 1] * F  # all candidate columns for error e
        norms = np.linalg.norm(X, axis=0)
        if not np.any(norms > 0):
            continue
        QtX = Q.T @ X
        rX = resid @ X
        for ci, c in enumerate(cands):
            s = slice(starts[ci], starts[ci + 1])
            Xs = X[:, s]
            G = Xs.T @ Xs - QtX[:, s].T @ QtX[:, s]  # Gram matrix of the projected columns
            scale = np.sqrt(np.maximum(np.diag(Xs.T @ Xs), 1e-300))
            Gs = G / np.outer(scale, scale)
            if np.linalg.eigvalsh(Gs).min() < MIN_INDEPENDENCE:
                continue  # (nearly) inside the current model: nothing new to add
            b = rX[s] / scale
            beta = np.linalg.solve(Gs, b)
            drop = float(b @ beta)
            if drop > 9 * sigma2:  # cheap pre-filter; the real test follows
                fitted = (Xs - Q @ QtX[:, s]) @ (beta / scale)
                results.append((drop, ci, e, fitted))
    results.sort(key=lambda t: -t[0])
    return results


def _folds(n_poses: int, rng: np.random.Generator) -> np.ndarray:
    return rng.permutation(n_poses) % FOLDS


def _held_out_sq(X: np.ndarray, r: np.ndarray, test: np.ndarray) -> float:
    """Squared error on the `test` rows of the correction X dc ~ r fitted on the other rows."""
    scale = np.maximum(np.linalg.norm(X[~test], axis=0), 1e-300)
    dc = np.linalg.lstsq(X[~test] / scale, r[~test], rcond=None)[0] / scale
    return float(np.sum((r[test] - X[test] @ dc) ** 2))


def cv_rms(H: np.ndarray, r: np.ndarray, rows_pose: np.ndarray, fold: np.ndarray) -> float:
    """k-fold cross-validated RMS point error (m) of a linear correction H dc ~ r (3R rows)."""
    sq = sum(_held_out_sq(H, r, fold[rows_pose] == f) for f in range(FOLDS))
    return float(np.sqrt(sq / (len(r) / 3)))


def selection_cv_rms(J: np.ndarray, H: np.ndarray, r: np.ndarray, rows_pose: np.ndarray, fold: np.ndarray,
                     cands: list[Candidate], shortlist: list[tuple[int, int]]) -> float:
    """k-fold cross-validated RMS point error (m) of the choice itself: in each fold the screening
    runs on the training part alone, its strongest candidate is added, and the held-out poses are
    predicted. The best of thousands of candidates always fits the poses it was picked on better
    than new ones; only an effect that wins on the other folds' poses too is real. The folds
    choose among `shortlist`, the (candidate, error) pairs strongest on all poses: a pair far down
    that list does not win on four fifths of them."""
    by_error: dict[int, list[int]] = {}
    for ci, e in shortlist:
        by_error.setdefault(e, []).append(ci)
    sq = 0.0
    for f in range(FOLDS):
        test = fold[rows_pose] == f
        Ht, rt = H[~test], r[~test]
        Q = np.linalg.qr(Ht / np.maximum(np.linalg.norm(Ht, axis=0), 1e-300))[0]
        resid = rt - Q @ (Q.T @ rt)
        sigma2 = float(resid @ resid) / max(len(rt) - H.shape[1], 1)
        best = max(((drop, cis[ci], e) for e, cis in by_error.items()
                    for drop, ci, _, _ in screen(J[~test], rows_pose[~test], resid, Q, sigma2,
                                                  [cands[k] for k in cis], [e])), default=None)
        X = H if best is None else np.column_stack([H, J[:, best[2]:best[2] + 1] * cands[best[1]].values[rows_pose]])
        sq += _held_out_sq(X, r, test)
    return float(np.sqrt(sq / (len(r) / 3)))


def _first_accepted(found, cands, J, H, r, rows_pose, fold, sigma2, n_tests, base_cv):
    """The strongest candidate that passes the corrected chi-square test and lowers the CV RMS."""
    for drop, ci, e, fitted in found[:8]:
        p = float(stats.chi2.sf(drop / sigma2, len(cands[ci].terms)))
        if p * n_tests > ALPHA:
            return None  # sorted by drop: nothing further can pass either
        X = J[:, e:e + 1] * cands[ci].values[rows_pose]
        cv = cv_rms(np.column_stack([H, X]), r, rows_pose, fold)
        if cv < (1 - MIN_CV_GAIN) * base_cv:
            return drop, ci, e, fitted, p, cv
    return None


@dataclass
class Round:
    model: ErrorModel
    cm: CompiledModel
    fit: Fit


def _fit(robot, model, data, registration_mode) -> Round:
    cm = CompiledModel(robot, model)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # conditioning is reported in the final fit, not per round
        fit = identify(cm, data, registration_mode=registration_mode)
    return Round(model, cm, fit)


def _with_terms(robot: Robot, model: ErrorModel, error: int, terms: tuple[str, ...], aux: tuple[str, ...]) -> ErrorModel:
    spec = model.to_yaml_dict(robot)
    frame, name = divmod(error, 6)
    block = spec["frames"].setdefault(frame, {})
    block[ERROR_NAMES[name]] = block.get(ERROR_NAMES[name], ["1"]) + list(terms)
    used_aux = sorted(set(spec.get("aux", [])) | {a for a in aux if any(a in t for t in terms)})
    if used_aux:
        spec["aux"] = used_aux
    return error_model_from_dict(spec, robot, "<diagnose>", aux)


def _linear_system(rnd: Round, data: Measurements, y: np.ndarray):
    """H over the kept columns and the residual, rows scaled by the robust fit's point weights, so
    a glitch neither passes for an effect nor hides one."""
    H, r = zip(*rows_H_and_residual(rnd.cm, data, y, rnd.fit.c, weights=rnd.fit.weights))
    return np.vstack(H)[:, list(rnd.fit.redundancy.kept)], np.concatenate(r)


def _rows_pose(data: Measurements) -> np.ndarray:
    order = np.argsort(data.pose, kind="stable")  # the row order rows_H_and_residual yields
    return np.repeat(data.pose[order], 3), order


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


def diagnose(robot: Robot, model: ErrorModel, data: Measurements, val: Measurements | None = None,
             registration_mode: str = "auto", seed: int = 0, progress=None, noise_mm: float | None = None) -> Diagnosis:
    """Run the loop; without `val`, a seeded fifth of the poses is held out for the report.
    `noise_mm`: the measurement noise per coordinate (mm), when known; otherwise it is estimated
    from repeated poses of `data`, if any. It decides whether what remains is only noise."""
    rng = np.random.default_rng(seed)
    noise = noise_floor(data, noise_mm)
    if val is None:
        held = rng.permutation(data.n_poses)
        n_val = max(1, data.n_poses // 5)
        val, data = data.subset(np.sort(held[:n_val])), data.subset(np.sort(held[n_val:]))
    fold = _folds(data.n_poses, rng)
    rnd = first = _fit(robot, model, data, registration_mode)
    if first.fit.failures:
        raise RuntimeError(f"the declared model's fit is not trustworthy: {first.fit.failures[0]}")
    effects: list[Effect] = []
    history, tested = [], 0
    for round_no in range(1, MAX_ROUNDS + 1):
        if progress:
            progress(round_no, rnd.fit.train["rms_mm"])
        y = rnd.fit.registration.to_world(data.xyz)
        H, r = _linear_system(rnd, data, y)
        rows_pose, order = _rows_pose(data)
        Q = np.linalg.qr(H / np.linalg.norm(H, axis=0))[0]
        m, k = len(r), H.shape[1]
        sigma2 = float(r @ r) / (m - k)
        cands = candidates(robot, rnd.model, data, rng)
        eps = rnd.cm.eps(data.q, data.w, data.aux_columns(rnd.model.aux), rnd.fit.c)
        _, Jall = rnd.cm.J_e(data.q, eps)
        J = Jall.reshape(data.n_poses, -1, 3, robot.n_errors)[data.pose[order], data.target[order]].reshape(-1, robot.n_errors)
        J *= np.repeat(np.sqrt(rnd.fit.weights[order]), 3)[:, None]  # weighted as H and r are
        errors = [e for e in range(robot.n_errors) if np.any(J[:, e])]
        base_cv = cv_rms(H, r, rows_pose, fold)
        present = [{t.text for t in ts} for ts in rnd.model.terms]
        chosen, results = None, []
        # a missing constant error first (few candidates, so a mild multiplicity correction), then the rest
        for tier in (lambda c: c.family == "geometric", lambda c: c.family != "geometric"):
            indices = [k for k, c in enumerate(cands) if tier(c)]
            found = screen(J, rows_pose, r, Q, sigma2, [cands[k] for k in indices], errors)
            # a term the error already has (kept or eliminated) is never new, however its column moved
            found = [(drop, indices[ci], e, fitted) for drop, ci, e, fitted in found
                     if not set(cands[indices[ci]].terms) & present[e]]
            results += found
            n_tests = max(1, len(indices) * len(errors))
            tested += n_tests
            chosen = _first_accepted(found, cands, J, H, r, rows_pose, fold, sigma2, n_tests, base_cv)
            if chosen:
                cv = selection_cv_rms(J, H, r, rows_pose, fold, cands, [(ci, e) for _, ci, e, _ in found[:SHORTLIST]])
                if cv < (1 - MIN_CV_GAIN) * base_cv:
                    chosen = (*chosen[:5], cv)  # the gain reported is that of the choice, not of the winner
                    break
                chosen = None
        results.sort(key=lambda t: -t[0])
        history.append({"round": round_no, "train_rms_mm": rnd.fit.train["rms_mm"], "cv_rms_mm": 1e3 * base_cv,
                        "candidates": len(cands) * len(errors), "accepted": None})
        if chosen is None:
            break
        drop, ci, e, fitted, p, cv = chosen
        c = cands[ci]
        if c.family == "fourier":
            def drop_of(cand, e=e):
                found = screen(J, rows_pose, r, Q, 0.0, [cand], [e])
                return found[0][0] if found else 0.0
            c = refine_period(c, data, drop_of)
        history[-1]["accepted"] = f"{robot.error_names()[e]}: {', '.join(c.terms)}"
        alternatives, seen = [], {(e, cands[ci].terms)}
        for d2, ci2, e2, f2 in results[:200]:
            if (e2, cands[ci2].terms) in seen or d2 < 0.5 * drop:
                continue
            seen.add((e2, cands[ci2].terms))
            cos = abs(f2 @ fitted) / (np.linalg.norm(f2) * np.linalg.norm(fitted))
            if cos > SAME_EFFECT:
                alternatives.append({"error": robot.error_names()[e2], "terms": list(cands[ci2].terms),
                                     "similarity": float(cos)})
        new_model = _with_terms(robot, rnd.model, e, c.terms, data.aux_names)
        refit = _fit(robot, new_model, data, registration_mode)
        if refit.fit.failures:
            # an effect whose fit cannot be trusted is not added, however much it promised
            history[-1]["refused"] = f"{history[-1]['accepted']}: {refit.fit.failures[0]}"
            history[-1]["accepted"] = None
            break
        rnd = refit
        coefs = _effect_coefficients(robot, rnd, e, len(c.terms))
        effects.append(Effect(robot.error_names()[e], list(c.variables), list(c.terms), c.family,
                              1e3 * (base_cv - cv), p, coefs, alternatives[:5]))
    before = _scores(first, data, val)
    after = _scores(rnd, data, val)
    # the last round's CV is the final model's unless that round added an effect (the round cap)
    final_cv = history[-1]["cv_rms_mm"] if history[-1]["accepted"] is None else None
    remaining = what_remains(rnd, data, final_cv, noise)
    return Diagnosis(robot, first, rnd, effects, len(history), tested, before, after, history, remaining)


def noise_floor(data: Measurements, noise_mm: float | None = None) -> dict | None:
    """The measurement noise per coordinate: {"noise_mm", "source", "dof"} from `noise_mm` when
    given (dof None: taken as exact), else pooled over repeated poses (poses with identical joints,
    wrench and aux, measuring the same target), else None (unknown)."""
    if noise_mm is not None:
        return {"noise_mm": float(noise_mm), "source": "given (--noise-mm)", "dof": None}
    state = np.column_stack([data.q, data.w, data.aux])
    _, group = np.unique(state, axis=0, return_inverse=True)
    key = group.ravel()[data.pose] * len(data.target) + data.target
    _, point_group, size = np.unique(key, return_inverse=True, return_counts=True)
    repeated = size[point_group] > 1
    if not repeated.any():
        return None
    mean = np.zeros((len(size), 3))
    np.add.at(mean, point_group, data.xyz)
    mean /= size[:, None]
    dev = data.xyz[repeated] - mean[point_group[repeated]]
    dof = 3 * int(np.sum(size[size > 1] - 1))
    return {"noise_mm": 1e3 * float(np.sqrt(np.sum(dev ** 2) / dof)), "source": "repeated poses", "dof": dof}


#: the residual is consistent with the noise when an F test of their variances passes at this level
NOISE_TEST_ALPHA = 0.01
#: largest residual points listed when structure remains
LARGEST = 5


def what_remains(rnd: Round, data: Measurements, cv_rms_mm: float | None, noise: dict | None) -> dict:
    """Whether the final residual is only noise, and what is left when it is not.

    `covered` is True when the fit's residual sigma passes an F test against the noise floor,
    False when it fails it, None when the noise is unknown (no repeated poses, no --noise-mm):
    then nobody can say that the model covers the data, only that nothing in the dictionary
    explains what remains."""
    fit = rnd.fit
    e = position_errors(rnd.cm, data, fit.registration.to_world(data.xyz), fit.c)
    inliers = np.nonzero(e <= fit.outlier_limit_m)[0]  # outliers are counted, not ranked with the rest
    top = inliers[np.argsort(-e[inliers])[:LARGEST]]
    out = {"train_rms_mm": fit.train_inliers["rms_mm"], "cv_rms_mm": cv_rms_mm, "sigma_mm": 1e3 * fit.sigma_m,
           "noise": noise, "covered": None, "outliers": len(fit.outliers),
           "largest": [{"row": int(data.file_rows[r]), "pose": int(data.pose_ids[data.pose[r]]),
                        "target": rnd.cm.robot.target_names[data.target[r]], "residual_mm": 1e3 * float(e[r])}
                       for r in top]}
    if noise is not None and noise["noise_mm"] > 0:
        ratio = (1e3 * fit.sigma_m / noise["noise_mm"]) ** 2
        dof_fit = max(3 * float(fit.weights.sum()) - fit.redundancy.n_identifiable, 1)
        p = float(stats.chi2.sf(ratio * dof_fit, dof_fit) if noise["dof"] is None
                  else stats.f.sf(ratio, dof_fit, noise["dof"]))
        out.update(covered=p > NOISE_TEST_ALPHA, noise_p_value=p, sigma_over_noise=float(np.sqrt(ratio)))
    return out


def verdict(remaining: dict) -> str:
    """One sentence for a person on what the final model leaves in the data."""
    r = remaining
    if r["covered"]:
        return (f"The residual ({r['sigma_mm']:.4f} mm per coordinate) is consistent with the measurement noise "
                f"({r['noise']['noise_mm']:.4f} mm, {r['noise']['source']}): the model covers the data.")
    largest = ", ".join(f"row {p['row']} ({p['residual_mm']:.3f} mm)" for p in r["largest"][:3])
    cv = f", cross-validated {r['cv_rms_mm']:.4f} mm" if r["cv_rms_mm"] is not None else ""
    outliers = f" without its {r['outliers']} outliers" if r["outliers"] else ""
    what = f"Structure remains: training RMS{outliers} {r['train_rms_mm']:.4f} mm{cv}; largest residuals {largest}"
    if r["covered"] is False:
        return (f"{what}. The residual is {r['sigma_over_noise']:.2f}x the noise floor ({r['noise']['noise_mm']:.4f} mm, "
                f"{r['noise']['source']}) and nothing in the candidate dictionary explains the rest.")
    return (f"{what}. The noise floor is unknown (no repeated poses; give --noise-mm), so whether the model covers "
            f"the data cannot be decided; nothing in the candidate dictionary explains the rest.")


def _effect_coefficients(robot: Robot, rnd: Round, error: int, n_new: int) -> list[dict]:
    """Fitted value and standard deviation of the n_new terms just added to `error`."""
    new = {t.text for t in rnd.model.terms[error][-n_new:]}
    names = rnd.model.coefficient_names(robot)
    # a term the refit eliminated (merged into others) has no std of its own: null, not NaN
    return [{"name": names[j], "value": float(rnd.fit.c[j]),
             "std": float(rnd.fit.std[j]) if np.isfinite(rnd.fit.std[j]) else None}
            for j, c in enumerate(rnd.model.coefficients) if c.error == error and c.term.text in new]


def _scores(rnd: Round, data: Measurements, val: Measurements) -> dict:
    yv = rnd.fit.registration.to_world(val.xyz)
    ev = position_errors(rnd.cm, val, yv, rnd.fit.c)
    s = summary(ev)
    return {"train_rms_mm": rnd.fit.train["rms_mm"], "val_rms_mm": s["rms_mm"], "val_max_mm": s["max_mm"]}


def write_error_model(robot: Robot, model: ErrorModel, effects: list[Effect], path: str | Path):
    """The model as an error-model file, with a header naming what diagnose added."""
    lines = [f"# Error model of {robot.name} written by gecgen diagnose."]
    lines += [f"# added: {e.error} <- {', '.join(e.terms)} (cross-validated gain {e.gain_mm:.4f} mm)" for e in effects]
    if not effects:
        lines.append("# diagnose found nothing in its candidate dictionary to add; the model is unchanged")
    spec = model.to_yaml_dict(robot)
    write_atomically(path, "\n".join(lines) + "\n" + yaml.safe_dump(spec, sort_keys=False, width=120))
