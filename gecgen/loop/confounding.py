"""Coupling ratios that stand in for loads.

A declared coupling's multipliers are calibration parameters (`Robot.ratio_terms`): a ratio error d
turns the coupled joint by d q_k, the term q_k on its zero-offset error. Over a robot's working
range that column can look much like the load the same joint carries: a torso joint whose gravity
moment grows as the trunk leans forward is turned by its compliance in step with the lean, and a
ratio error of the right size does the same. Fitted without the load, the ratio coefficient then
absorbs the compliance; a person reading it as a gear-ratio error would correct the wrong thing.

The check asks, for each kept ratio coefficient, how far its value moves between the fit with the
loads that physically act on its error (the matched component of the wrench the joint's frame
carries, `model.robot.MATCHING`; or the load terms the model already gives that error) and the
fit without them. Both are the same linear least squares at the fitted point, one with the load
columns L and one without, so the move is exact:

    c_ratio(without) - c_ratio(with) = -Sigma_rL Sigma_LL^-1 c_L(with)

(the constrained least-squares solution, Sigma the with-load covariance). It is significant when it
exceeds `SHIFT` standard deviations of the ratio coefficient in the with-load fit; on a robot
without the effect the move is noise (Delta / sigma_r = rho z with z standard normal, |rho| <= 1),
so the check false-alarms at most as often as |z| > 3 (0.3 %).
"""
from __future__ import annotations

import numpy as np

from gecgen.loop.dictionary import FRAME_SIGNAL
from gecgen.loop.linear import Round, linear_system, pose_rows, weighted_J
from gecgen.model.loads import catalog
from gecgen.model.measurements import Measurements
from gecgen.model.robot import MATCHING, WRENCH
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import Fit

#: a ratio coefficient whose value moves by this many of its standard deviations when the loads
#: acting on its error are modelled (or not) absorbs load
SHIFT = 3.0


def _matched_loads(signals: tuple[list[str], np.ndarray], error: int) -> tuple[list[str], np.ndarray]:
    """The load signals (names, values (P, l)) that act on `error` about or along its own axis: the
    matched component of the frame's wrench, from the URDF's masses when the robot has them, else the
    gravity regressor's columns, with the measured wrench's when the data has one. Signals that do
    not vary over the data are left out. signals: `CompiledModel.load_signals` at the data."""
    frame, k = divmod(error, 6)
    names, values = signals
    found: dict[str, list[int]] = {}
    for j, name in enumerate(names):
        m = FRAME_SIGNAL.match(name)
        if m and int(m.group(2)) == frame and m.group(3) == MATCHING[k] and np.ptp(values[:, j]) > 1e-12:
            found.setdefault(m.group(1), []).append(j)
    cols = (found.get("gravity_load") or found.get("gravity", [])) + found.get("wrench_load", [])
    return [names[j] for j in cols], values[:, cols]


def ratio_load_confounding(cm: CompiledModel, fit: Fit, data: Measurements) -> list[dict]:
    """For each kept coupling-ratio coefficient whose value depends on whether the loads acting on
    its error are modelled: {"coefficient", "loads" (term names), "in_model" (the loads are the
    model's own terms), "with_loads", "without_loads" (its value either way, rad per unit of the
    reading: a ratio error), "std" (its standard deviation with the loads), "shift_std" (the move
    in those standard deviations)}. Empty for a robot without declared couplings, and for socket
    or plane data (their rows are projected; the check needs plain points)."""
    robot = cm.robot
    ratios = robot.ratio_terms()
    kept = list(fit.redundancy.kept)
    coefs = cm.model.coefficients
    wanted = [j for j in kept if coefs[j].term.text in ratios.get(coefs[j].error, ())]
    if not wanted or data.relative is not None or not len(kept):
        return []
    rnd = Round(cm.model, cm, fit)
    H, r = linear_system(rnd, data, fit.to_world(data))
    rows_pose, _, order = pose_rows(data)
    J = weighted_J(rnd, data, order)
    loads = set(catalog(robot).names) | set(WRENCH)
    out, signals = [], None
    for error in sorted({coefs[j].error for j in wanted}):
        own = [i for i, j in enumerate(kept) if coefs[j].error == error
               and set(coefs[j].term.variables) & loads]
        if own:  # the model carries loads on this error: compare with the fit that drops them
            X, L, names = H, own, [coefs[kept[i]].term.label for i in own]
        else:
            signals = signals or cm.load_signals(data.q, data.w)  # once, for every error that needs them
            names, values = _matched_loads(signals, error)
            if not names:
                continue
            X = np.hstack([H, J[:, error:error + 1] * values[rows_pose]])
            L = list(range(H.shape[1], X.shape[1]))
        scale = np.linalg.norm(X, axis=0)
        scale[scale == 0] = 1.0
        Xs = X / scale
        # the linear least squares at the fitted point: the step to the with-load solution (zero when
        # the loads are the model's own) and its covariance, sigma^2 (X^T X)^-1, in the scaled columns
        step, *_ = np.linalg.lstsq(Xs, r, rcond=None)
        dof = max(len(r) - X.shape[1], 1)
        sigma2 = float(np.sum((r - Xs @ step) ** 2)) / dof
        cov = sigma2 * np.linalg.pinv(Xs.T @ Xs)
        with_c = np.concatenate([fit.c[kept], np.zeros(X.shape[1] - len(kept))]) + step / scale
        cov /= np.outer(scale, scale)
        cLL = cov[np.ix_(L, L)]
        for j in (j for j in wanted if coefs[j].error == error):
            i = kept.index(j)
            shift = float(cov[i, L] @ np.linalg.solve(cLL, with_c[L]))
            std = float(np.sqrt(cov[i, i]))
            if abs(shift) >= SHIFT * std:
                out.append({"coefficient": coefs[j].name(robot), "loads": names, "in_model": bool(own),
                            "with_loads": float(with_c[i]), "without_loads": float(with_c[i] - shift),
                            "std": std, "shift_std": abs(shift) / std})
    return out


def describe(item: dict) -> str:
    """One line a person reads: what the ratio coefficient's value depends on, and what to do."""
    frame, error = item["coefficient"].split(":")[0].split(".")
    moves = (f"{item['coefficient']}, a coupling ratio, is {item['with_loads']:+.4g} with the loads on frame {frame}'s "
             f"{error} ({', '.join(item['loads'])}) and {item['without_loads']:+.4g} without them "
             f"({item['shift_std']:.1f} standard deviations apart)")
    if item["in_model"]:
        return moves + ": as a gear-ratio error it is only as good as the load terms beside it"
    return (moves + ": fitted without them, it absorbs load and is not a gear-ratio error; model the load (calibrate's "
            "elastic model, or diagnose)")
