"""Which identified coefficients the data determine: t statistics and backward elimination.

Identifiable (`fit.redundancy`) says the data can separate a coefficient from the others;
it does not say they hold its value. A coefficient whose value is within two standard deviations
of zero (t = |c| / std below 2) is not determined: its value is what noise and misfit put there
(on figaroh's 23 real UR10 poses, 26 of the 30 identifiable coefficients, 22 of them with a std at
least as large as the value), and carried into the compensation it moves every corrected command
by an amount nobody measured.

Backward elimination: the least significant coefficient is held at zero and the others are
refitted, until every coefficient left has t >= T_MIN. The refit without coefficient a is, for
the linearised least squares at the fit, the others conditioned on x_a = 0:
x <- x - M[:, a] x_a / M_aa and M <- M - M[:, a] M[a, :] / M_aa, with M = (A^T A)^-1 = cov / sigma^2,
and the residual sum of squares grows by x_a^2 / M_aa (so sigma is re-estimated at each step).
Correlated coefficients that are insignificant one by one but determined together keep the
survivor of the group, which absorbs the rest. The nonlinear refit with the dropped coefficients
held at zero follows (`identify`'s hold).

The fit's residual against the instrument's noise: the noise stated, or pooled over the data's
repeated poses (`noise_floor`), and the test that says whether the residual is only that noise
(`noise_test`, `overall`); identify and diagnose judge a model with them alike.
"""
from __future__ import annotations

import warnings

import numpy as np
from scipy import special

from gecgen.fit.identify import identify
from gecgen.model.measurements import Measurements
from gecgen.model.robot import Robot

#: a coefficient is determined by the data when |value| / std is at least this (about 95 % two-sided)
T_MIN = 2.0


def t_values(c: np.ndarray, std: np.ndarray) -> np.ndarray:
    """|c| / std per coefficient (NaN where std is NaN: not fitted)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(c) / std


def backward_elimination(x: np.ndarray, cov: np.ndarray, sigma: float, dof: float) -> dict[int, float]:
    """The coefficients to hold at zero, {position in x: its t when it was dropped}, least
    significant first, for fitted values x (k,) with covariance cov (k, k), residual standard
    deviation sigma and dof = measured degrees of freedom - k. Empty when all are determined."""
    x = np.array(x, float)
    if sigma <= 0 or not np.isfinite(sigma):
        return {}
    M = np.array(cov, float) / sigma ** 2
    rss, dof = sigma ** 2 * dof, float(dof)
    active, dropped = list(range(len(x))), {}
    while len(active) > 0:
        s2 = rss / max(dof, 1.0)
        diag = np.diag(M)[active]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.abs(x[active]) / np.sqrt(s2 * diag)
        # a variance that is not a positive number (a singular system) determines nothing
        t = np.where(np.isfinite(diag) & (diag > 0), t, 0.0)
        j = int(np.argmin(t))
        if not t[j] < T_MIN:
            break
        a = active.pop(j)
        dropped[a] = float(t[j])
        if np.isfinite(M[a]).all() and M[a, a] > 0:  # the others, given it is zero
            rss += x[a] ** 2 / M[a, a]
            x -= M[:, a] * x[a] / M[a, a]
            M -= np.outer(M[:, a], M[a, :]) / M[a, a]
        dof += 1.0
    return dropped


def judge(names: list[str], c: np.ndarray, std: np.ndarray, kept, cov: np.ndarray, sigma: float,
          measured_dof: float) -> tuple[dict, dict[int, str]]:
    """The verdict on a fit's coefficients (names (nc,), values c and std (nc,), the kept indices,
    their covariance, sigma (m) and the measured degrees of freedom): a report ({t_min,
    n_determined, held: [{param, value, std, t}] (the fit's value and std, the t at which
    elimination dropped it), frames: {frame: {determined, held}}}) and the coefficients to hold at
    zero ({index: why}, for `identify`'s hold)."""
    kept = list(kept)
    dropped = backward_elimination(c[kept], cov, sigma, measured_dof - len(kept))
    hold = {kept[a]: f"t = {t:.3f} < {T_MIN:g}: the data do not determine it; held at zero and the rest refitted "
                     f"(keep_insignificant=True, or --keep-insignificant, carries it)" for a, t in dropped.items()}
    frames: dict[str, dict[str, int]] = {}
    for j in kept:
        count = frames.setdefault(names[j].split(".")[0], {"determined": 0, "held": 0})
        count["held" if j in hold else "determined"] += 1
    held = [{"param": names[kept[a]], "value": float(c[kept[a]]), "std": float(std[kept[a]]), "t": t}
            for a, t in dropped.items()]
    return {"t_min": T_MIN, "n_determined": len(kept) - len(hold), "held": held, "frames": frames}, hold


#: the residual is beyond the stated noise when noise alone leaves one as large with less than this probability
NOISE_ALPHA = 0.01


def overall(sigma_m: float, dof: float, noise_m: float) -> dict:
    """The fit's residual sigma (m per coordinate, over dof degrees of freedom) against the
    instrument noise a user states (m per coordinate): their ratio, the probability that noise alone
    leaves a residual as large (chi-square, dof), and the error the model leaves beyond the noise,
    sqrt(sigma^2 - noise^2) (mm)."""
    p = float(special.chdtrc(max(dof, 1.0), max(dof, 1.0) * sigma_m ** 2 / noise_m ** 2))
    return {"sigma_mm": 1e3 * sigma_m, "noise_mm": 1e3 * noise_m, "ratio": sigma_m / noise_m, "p_value": p,
            "beyond_noise": p < NOISE_ALPHA,
            "unexplained_mm": 1e3 * float(np.sqrt(max(sigma_m ** 2 - noise_m ** 2, 0.0)))}


def determined(cm, data, fit, keep: bool = False, noise_m: float | None = None, **options):
    """(the fit, the verdict on its coefficients `judge`): unless keep, refitted (`identify` with
    `options`, on compiled model cm and data) with the coefficients the data do not determine held
    at zero, and a warning naming them. Raises RuntimeError when that refit cannot be trusted. With
    the instrument noise noise_m (m per coordinate), the verdict's `overall` says whether the fit's
    residual is beyond it (`overall`), with a warning when it is; the refit holds the weakly
    determined directions against it (`identify`'s noise_m)."""
    verdict, hold = judge(cm.model.coefficient_names(cm.robot), fit.c, fit.std, fit.redundancy.kept, fit.cov,
                          fit.sigma_m, fit.measured_dof)
    verdict["insignificant_carried"] = bool(hold) and keep
    if hold and not keep:
        names = [h["param"] for h in verdict["held"]]
        warnings.warn(f"{len(hold)} of {len(fit.redundancy.kept)} coefficients are not determined by the data (|value| "
                      f"/ std < {T_MIN:g}: {', '.join(names[:6])}{', ...' if len(names) > 6 else ''}): "
                      f"held at zero and the rest refitted, so the compensation carries no value nobody measured "
                      f"(keep_insignificant=True, or --keep-insignificant, carries them)", stacklevel=3)
        # what the fit held as weakly determined stays held: the refit need not find it again
        fit = identify(cm, data, **options, hold={**{h.index: h for h in fit.held}, **hold}, analysis=fit.analysis,
                       noise_m=noise_m)
        if fit.failures:
            raise RuntimeError(f"the refit without the {len(hold)} insignificant coefficients is not trustworthy, no "
                               f"calibration made or written: {'; '.join(fit.failures)}")
    if noise_m is not None:
        verdict["overall"] = o = overall(fit.sigma_m, fit.measured_dof - len(fit.redundancy.kept), noise_m)
        if o["beyond_noise"]:
            warnings.warn(f"the fit leaves {o['sigma_mm']:.3g} mm per coordinate against the stated noise "
                          f"{o['noise_mm']:.3g} mm ({o['ratio']:.3g} times, p = {o['p_value']:.2g}): the model misses "
                          f"about {o['unexplained_mm']:.3g} mm; run gecgen diagnose to find what", stacklevel=3)
    return fit, verdict


#: bootstrap draws and seed of `rms_interval` (fixed: the same data always gets the same interval)
DRAWS, SEED = 2000, 0


def clustered_covariance(A: np.ndarray, r: np.ndarray, groups: np.ndarray, n_groups: int) -> np.ndarray:
    """The covariance (k, k) of least-squares coefficients from rows A (R, k) with residuals r (R,), when
    rows are independent only between groups (groups (R,), 0..n_groups-1: a pose's points share the
    robot's repeatability and any error the model lacks; an image's points likewise): the sandwich
    (A^T A)^-1 (sum_g a_g a_g^T) (A^T A)^-1, a_g = A_g^T r_g, scaled by G / (G - k) for G groups. Taking
    the rows as independent, as sigma^2 (A^T A)^-1 does, makes a bound built on it too tight."""
    a = np.zeros((n_groups, A.shape[1]))
    np.add.at(a, groups, A * r[:, None])
    A_inv = np.linalg.pinv(A.T @ A)
    return n_groups / max(n_groups - A.shape[1], 1) * A_inv @ (a.T @ a) @ A_inv


def rms_interval(errors: np.ndarray, pose: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """The `level` confidence interval of an RMS error over poses drawn like these: errors (G,) per
    measured row, pose (G,) the pose of each row. Poses, not rows, are resampled (the bootstrap
    percentile interval): the rows of one pose share its joint values and its errors, and a
    held-out set of 5 poses says little however many targets each carries."""
    ids, at = np.unique(pose, return_inverse=True)
    sq, n = np.bincount(at, errors ** 2, len(ids)), np.bincount(at, minlength=len(ids)).astype(float)
    draw = np.random.default_rng(SEED).integers(0, len(ids), (DRAWS, len(ids)))
    rms = np.sqrt(sq[draw].sum(1) / n[draw].sum(1))
    lo, hi = np.quantile(rms, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


#: joint angles taken 2 pi apart are compared to this many decimals (rad) once wrapped: the wrap's
#: rounding (1e-15) must not split a repeat, and nothing a robot repeats differs by 1e-9 rad
ANGLE_DECIMALS = 9


def noise_floor(data: Measurements, noise_mm: float | None = None, robot: Robot | None = None) -> dict | None:
    """The measurement noise per coordinate: {"noise_mm", "source", "dof"} from `noise_mm` when
    given (dof None: taken as exact), else pooled over repeated poses (poses with identical joints,
    wrench and aux, measuring the same target; with the robot, revolute joints 2 pi apart count as
    identical), else None (unknown). A measured frame's vertices count with their weight and degrees
    of freedom (`Measurements.rows`), so the noise is per degree of freedom as the fit's sigma is."""
    if noise_mm is not None:
        return {"noise_mm": float(noise_mm), "source": "given (--noise-mm)", "dof": None}
    if data.relative is not None:  # a socket's or plane's rows have no position to repeat
        data = data.rows_of(~data.relative.rows)
        if not len(data.target):
            return None
    q = data.q
    if robot is not None:  # a revolute joint read 2 pi apart is in the same place (a wrist at -360 and +360 deg)
        turns = np.array([j.kind == "R" for j in robot.joints])
        q = np.where(turns, np.round(np.mod(q + np.pi, 2 * np.pi) - np.pi, ANGLE_DECIMALS), q)
    state = np.column_stack([q, data.w, data.aux])
    _, group = np.unique(state, axis=0, return_inverse=True)
    key = group.ravel()[data.pose] * len(data.target) + data.target
    _, point_group, size = np.unique(key, return_inverse=True, return_counts=True)
    repeated = size[point_group] > 1
    if not repeated.any():
        return None
    weight, point_dof = data.rows.weight, data.rows.dof
    mean = np.zeros((len(size), 3))
    np.add.at(mean, point_group, data.xyz)
    mean /= size[:, None]
    dev = data.xyz[repeated] - mean[point_group[repeated]]
    # each repeated point leaves its degrees of freedom times (size - 1) / size of them
    dof = float(np.sum(point_dof[repeated] * (1 - 1 / size[point_group[repeated]])))
    sq = float(np.sum(weight[repeated] * np.einsum("ni,ni->n", dev, dev)))
    return {"noise_mm": 1e3 * float(np.sqrt(sq / dof)), "source": "repeated poses", "dof": dof}


#: the residual is consistent with the noise when an F test of their variances passes at this level
NOISE_TEST_ALPHA = 0.01


def noise_test(sigma_m: float, dof_fit: float, noise: dict) -> tuple[bool, float, float]:
    """Whether a fit's residual sigma (m per coordinate, over dof_fit degrees of freedom) is only the
    noise (`noise_floor`): a chi-square test against a noise taken as exact (dof None), an F test
    against one pooled over repeated poses; (passes at NOISE_TEST_ALPHA, p-value, sigma / noise)."""
    ratio = (1e3 * sigma_m / noise["noise_mm"]) ** 2
    p = float(special.chdtrc(dof_fit, ratio * dof_fit) if noise["dof"] is None
              else special.fdtrc(dof_fit, noise["dof"], ratio))  # scipy.stats's sf, without its import
    return p > NOISE_TEST_ALPHA, p, float(np.sqrt(ratio))
