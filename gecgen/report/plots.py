"""The report's figures as PNG (matplotlib, no display needed): error distributions, signed
residuals against each joint, and each diagnosed effect against its variable."""
from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import sympy as sp  # noqa: E402

from gecgen.model.robot import Robot  # noqa: E402
from gecgen.report.content import DataSet, Figure, Residuals, joint_label, joint_values, variable  # noqa: E402

#: one colour per stage, in order: uncalibrated, calibrated, diagnosed
COLOURS = ("tab:red", "tab:blue", "tab:green")
DPI = 100


def _png(fig) -> bytes:
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=DPI)
    plt.close(fig)
    return out.getvalue()


def _slug(text: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in text).strip("_")


def error_distribution(robot: Robot, ds: DataSet) -> Figure:
    """Histogram and cumulative distribution of the point errors (mm, log scale) of every stage."""
    errors = [np.linalg.norm(s.position_mm, axis=1) for s in ds.stages]
    positive = np.concatenate(errors)
    positive = positive[positive > 0]
    lo, hi = (positive.min(), positive.max()) if len(positive) else (1e-3, 1.0)
    bins = np.geomspace(lo / 1.05, hi * 1.05, 40)
    fig, (ax, cx) = plt.subplots(1, 2, figsize=(12, 3.6))
    for s, e, colour in zip(ds.stages, errors, COLOURS):
        e = np.maximum(e, lo)
        ax.hist(e, bins, color=colour, alpha=0.45, label=s.stage)
        cx.step(np.sort(e), np.arange(1, len(e) + 1) / len(e), where="post", color=colour, label=s.stage)
    for a in (ax, cx):
        a.set_xscale("log")
        a.set_xlabel("point error (mm)")
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=8)
    ax.set_ylabel("measured rows")
    cx.set_ylabel("share of rows at or below")
    ax.set_title(f"{robot.name}, {ds.name} data: histogram of point errors")
    cx.set_title(f"{robot.name}, {ds.name} data: cumulative distribution")
    fig.tight_layout()
    return Figure(f"errors_{ds.name}", f"Point errors on the {ds.name} data, each model", _png(fig))


def residuals_per_joint(robot: Robot, ds: DataSet, st: Residuals) -> Figure:
    """Signed residual per axis (rows: x, y, z in mm, then orientation about x, y, z in mrad when
    measured) against each joint (columns), names and units on every axis."""
    rows = [(f"{a} residual (mm)", st.position_mm[:, k]) for k, a in enumerate("xyz")]
    if st.rotation_mrad is not None:
        rows += [(f"rot. about {a} (mrad)", st.rotation_mrad[:, k]) for k, a in enumerate("xyz")]
    n = robot.n
    fig, axes = plt.subplots(len(rows), n, figsize=(12, 1.75 * len(rows) + 0.7), squeeze=False)
    colour = COLOURS[min(len(COLOURS) - 1, [s.stage for s in ds.stages].index(st.stage))]
    for r, (ylabel, values) in enumerate(rows):
        finite = values[np.isfinite(values)]
        limit = 1.08 * np.abs(finite).max() if len(finite) and np.abs(finite).max() > 0 else 1.0
        for k in range(n):
            ax = axes[r, k]
            ax.plot(joint_values(robot, ds.data, k)[st.pose], values, ".", ms=3, alpha=0.7, color=colour)
            ax.axhline(0, color="0.5", lw=0.6)
            ax.set_ylim(-limit, limit)
            ax.set_xlabel(joint_label(robot, k), fontsize=7, labelpad=1)
            ax.set_ylabel(ylabel, fontsize=7, labelpad=1)
            ax.tick_params(labelsize=6, pad=1)
            ax.grid(alpha=0.3)
    fig.suptitle(f"{robot.name}, {ds.name} data, {st.stage}: signed residuals against each joint", fontsize=10)
    fig.tight_layout(h_pad=0.4, w_pad=0.3)
    return Figure(f"residuals_{ds.name}_{_slug(st.stage)}",
                  f"Signed residuals, {st.stage} model, {ds.name} data", _png(fig))


def _rms_per_pose(st: Residuals, n_poses: int) -> np.ndarray:
    """RMS point error (mm) of the measured rows of each pose (P,)."""
    sq = np.bincount(st.pose, np.einsum("gi,gi->g", st.position_mm, st.position_mm), n_poses)
    return np.sqrt(sq / np.maximum(np.bincount(st.pose, minlength=n_poses), 1))


def effect(robot: Robot, eff, coefficients, c: np.ndarray, name: str, before: Residuals, after: Residuals,
           data) -> Figure:
    """Left: the generalized error the effect adds (sum of its coefficients times their terms, mm
    or mrad) at each training pose against `name`; right: the RMS residual per pose before and after."""
    values = {str(s): None for co in coefficients for s in co.term.expr.free_symbols}
    args = sorted(values)
    funcs = [sp.lambdify([sp.Symbol(a) for a in args], co.term.expr, "numpy") for co in coefficients]
    inputs = [variable(data, a) for a in args]
    size = 1e3 * sum(ck * np.broadcast_to(f(*inputs), (data.n_poses,)) for ck, f in zip(c, funcs))
    x = variable(data, name)
    k = int(name[1:]) - 1 if name.startswith("q") and name[1:].isdigit() else None
    if k is not None:
        x = joint_values(robot, data, k)
    label = joint_label(robot, k) if k is not None else name
    unit = "mm" if eff.error.split(".")[-1] in ("ex", "ey", "ez") else "mrad"
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 3.4))
    order = np.argsort(x)
    ax.plot(x[order], size[order], ".-", ms=3, lw=0.8, color=COLOURS[2])
    ax.set_xlabel(label)
    ax.set_ylabel(f"{eff.error} added ({unit})")
    ax.set_title(f"fitted {eff.error}: {' + '.join(eff.terms)}", fontsize=9)
    for st, colour in ((before, COLOURS[1]), (after, COLOURS[2])):
        bx.plot(x, _rms_per_pose(st, data.n_poses), ".", ms=4, alpha=0.7, color=colour, label=st.stage)
    bx.set_xlabel(label)
    bx.set_ylabel("residual per pose, RMS (mm)")
    bx.set_title("training residual before and after diagnose", fontsize=9)
    bx.legend(fontsize=8)
    for a in (ax, bx):
        a.grid(alpha=0.3)
    fig.tight_layout()
    return Figure(f"effect_{_slug(eff.error)}_{_slug(name)}", f"{eff.error} against {label}: what the effect removed",
                  _png(fig))
