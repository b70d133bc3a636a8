"""Robust losses on measured points: how much each point counts in a fit, and which are outliers.

A tracker glitch (a lost beam, a reflector in the wrong nest, a row pasted into the wrong pose)
gives one point a residual far outside the others. Least squares lets that one point pull every
coefficient; here a point's weight falls once its residual passes a threshold, so it cannot.

The unit is the measured point: its residual e is the length of its 3-D error (m), since a glitch
spoils all three coordinates of a point at once. A measured frame (position and orientation, see
`model.pose_targets`) is one unit too: its residual sqrt(|e|^2 + L^2 theta^2) has six degrees of
freedom, and scaled by sqrt(1/2) to three it follows nearly the law of a point's (median 1.63 sigma
against 1.54), so points and frames share one scale and one limit; it then counts twice in the
objective (`objective`'s count), as its six coordinates do in least squares. With Gaussian noise of sigma per coordinate,
(e / sigma)^2 follows a chi-square law with 3 degrees of freedom, so

* the robust scale is sigma = median(e) / sqrt(chi2.ppf(0.5, 3)) (the MAD idea for 3-D norms):
  a few gross points do not move a median;
* a point is an outlier when its residual exceeds a = THRESHOLD sigma, 10 robust sigmas. Gaussian
  noise alone would allow a lower limit (the largest of 10^6 clean points is about 6 sigma), but
  the residual of a model that lacks an effect is heavier-tailed than noise, and those points are
  the effect, not glitches: measured on simulations, the largest misfit residual reaches 9.6 robust
  sigmas (PPS paper design, constant model) and 7.6 (industrial6r, default model), while a tracker
  glitch of a few mm is 30 sigmas and more. Down-weighting misfit would hide from diagnose the very
  effect it must find. sigma never goes below SCALE_FLOOR_M: a noiseless simulation's residual is
  rounding, and nothing in it is an outlier;
* the losses are quadratic up to a and grow slower beyond it:
  `huber`  rho = 2 a e - a^2        (weight a / e: a gross point keeps a bounded pull),
  `cauchy` rho = a^2 (1 + 2 ln(e/a)) (weight (a / e)^2: its pull fades to zero; the default),
  `l2`     rho = e^2 everywhere     (plain least squares).
The weights are those of iteratively reweighted least squares, w = rho'(e) / (2 e).
"""
from __future__ import annotations

import math

import numpy as np

LOSSES = ("cauchy", "huber", "l2")
#: outlier limit in robust sigmas (see the module docstring for why 10)
THRESHOLD = 10.0
#: the robust sigma is at least this (m): far below any instrument's noise
SCALE_FLOOR_M = 1e-7


def _median_chi3() -> float:
    """The median of a chi variable with 3 degrees of freedom (sqrt of chi2.ppf(0.5, 3)): the root of
    its distribution function erf(r / sqrt 2) - sqrt(2 / pi) r exp(-r^2 / 2) = 1/2 by Newton's method
    (its density is sqrt(2 / pi) r^2 exp(-r^2 / 2)); closed forms, so that no command pays for
    importing a special-function library to know one number."""
    r, c = 1.5, math.sqrt(2 / math.pi)
    for _ in range(8):
        r -= (math.erf(r / math.sqrt(2)) - c * r * math.exp(-r * r / 2) - 0.5) / (c * r * r * math.exp(-r * r / 2))
    return r


#: median of a chi variable with 3 degrees of freedom: median(e) = MEDIAN_CHI3 * sigma
MEDIAN_CHI3 = _median_chi3()


def scale(e: np.ndarray) -> float:
    """Robust per-coordinate sigma (m) of points whose residual lengths are e (R,)."""
    return max(float(np.median(e)) / MEDIAN_CHI3, SCALE_FLOOR_M)


def check_loss(loss: str):
    if loss not in LOSSES:
        raise ValueError(f"loss {loss!r}: use one of {', '.join(LOSSES)}")


def outlier_limit(e: np.ndarray, loss: str) -> float:
    """a (m): residual length beyond which a point is down-weighted and reported; inf for l2."""
    check_loss(loss)
    if loss == "l2" or len(e) == 0:
        return np.inf
    return THRESHOLD * scale(e)


def weights(e: np.ndarray, a: float, loss: str) -> np.ndarray:
    """IRLS weight per point (R,) for residual lengths e (R,) at outlier limit a."""
    w = np.ones_like(e)
    beyond = e > a
    if loss == "huber":
        w[beyond] = a / e[beyond]
    elif loss == "cauchy":
        w[beyond] = (a / e[beyond]) ** 2
    return w


def objective(e: np.ndarray, a: float, loss: str, count: np.ndarray | None = None) -> float:
    """sum of count * rho(e) (m^2): what the robust fit minimises at a fixed outlier limit a. count
    (default 1) is what each residual stands for: a measured frame's residual, its length scaled
    to three degrees of freedom, stands for two points."""
    count = np.ones_like(e) if count is None else count
    beyond = e > a
    inner = float(np.sum(count[~beyond] * e[~beyond] ** 2))
    if not np.any(beyond):
        return inner
    if loss == "huber":
        return inner + float(np.sum(count[beyond] * (2 * a * e[beyond] - a * a)))
    return inner + float(np.sum(count[beyond] * a * a * (1 + 2 * np.log(e[beyond] / a))))
