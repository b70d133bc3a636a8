"""The report's figures as PNG (matplotlib, no display needed): error distributions, signed
residuals against each joint, and each diagnosed effect against its variable."""
from __future__ import annotations

import io
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.patches  # noqa: E402
import matplotlib.ticker  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from gecgen.model.robot import Robot  # noqa: E402
from gecgen.report.blocks import (DataSet, Figure, Residuals, joint_label, joint_scale, joint_values,  # noqa: E402
                                  variable, variable_label)

#: one colour per stage, in order: uncalibrated, calibrated, diagnosed
COLOURS = ("tab:red", "tab:blue", "tab:green")
DPI = 100
#: at most this many poses get a bar each per model in the per-pose figure (more: a point each)
MAX_BARS = 40
#: the share of the per-pose figure's width a labelled pose keeps clear of another's label (7 pt "pose 1234")
LABEL_CLEAR = 0.05
#: panels per row of the accuracy map: legible at a page's width
MAP_COLUMNS = 4
#: fixed margins of the one-row figures (a share of the figure): tight_layout would draw each figure twice
MARGINS = {"left": 0.065, "right": 0.99, "bottom": 0.16, "top": 0.9}


def _figure(fig, name: str, caption: str, named: tuple[str, ...] = ()) -> Figure:
    """The figure as PNG, with the labels of its axes and what else `named` names on them (the page's
    alt text names them)."""
    labels = tuple(dict.fromkeys([*(t for ax in fig.axes for t in (ax.get_xlabel(), ax.get_ylabel()) if t), *named]))
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=DPI)
    plt.close(fig)
    return Figure(name, caption, out.getvalue(), labels)


#: the height (inches) of the row above a figure's axes that holds its legend, and of the axes' titles
LEGEND_ROW, TITLE_ROW = 0.3, 0.3


def _legend_above(fig, ax) -> None:
    """One legend for the figure, in a row of its own above the axes and their titles, so that it
    hides no data (a legend inside an axes covers the points or bars in its corner); the axes' top
    is moved down to make the row."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 1.0), ncol=len(labels), fontsize=8,
               frameon=False, markerscale=2.5)
    fig.subplots_adjust(top=1 - (LEGEND_ROW + TITLE_ROW) / fig.get_figheight())


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")


def error_distribution(robot: Robot, ds: DataSet, orientation: bool = False) -> Figure:
    """Histogram and cumulative distribution of the point errors (mm, log scale) of every stage, or
    (`orientation`) of the orientation errors (mrad) of the rows that measure a frame."""
    if orientation:
        errors = [np.linalg.norm(s.rotation_mrad, axis=1) for s in ds.stages]
        errors = [e[np.isfinite(e)] for e in errors]
        what, unit, name = "orientation error", "mrad", f"rotation_errors_{ds.name}"
    else:
        errors = [np.linalg.norm(s.position_mm, axis=1) for s in ds.stages]
        what, unit, name = "point error", "mm", f"errors_{ds.name}"
    positive = np.concatenate(errors)
    positive = positive[positive > 0]
    lo, hi = (positive.min(), positive.max()) if len(positive) else (1e-3, 1.0)
    bins = np.geomspace(lo / 1.05, hi * 1.05, 40)
    fig, (ax, cx) = plt.subplots(1, 2, figsize=(12, 3.6 + LEGEND_ROW))
    for s, e, colour in zip(ds.stages, errors, COLOURS):
        e = np.maximum(e, lo)
        ax.hist(e, bins, color=colour, alpha=0.45, label=s.stage)
        cx.step(np.sort(e), np.arange(1, len(e) + 1) / len(e), where="post", color=colour, label=s.stage)
    ticks = log_ticks(bins[0], bins[-1])
    for a in (ax, cx):
        a.set_xscale("log")
        a.set_xlim(bins[0], bins[-1])
        # numbers at ticks chosen for the span: a log axis within one decade has no major tick to label
        a.xaxis.set_major_locator(matplotlib.ticker.FixedLocator(ticks))
        a.xaxis.set_major_formatter(matplotlib.ticker.FixedFormatter([f"{v:g}" for v in ticks]))
        a.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        a.set_xlabel(f"{what} ({unit})")
        a.grid(alpha=0.3, which="both")
    ax.yaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))  # counts
    ax.set_ylabel("measured frames" if orientation else "measured rows")
    cx.set_ylabel("share of them at or below" if orientation else "share of rows at or below")
    ax.set_title(f"{robot.name}, {ds.name} data: histogram of {what}s")
    cx.set_title(f"{robot.name}, {ds.name} data: cumulative distribution")
    fig.subplots_adjust(**MARGINS, wspace=0.18)
    _legend_above(fig, ax)
    return _figure(fig, name, f"{what.capitalize()}s on the {ds.name} data, each model")


def log_ticks(lo: float, hi: float, most: int = 12) -> np.ndarray:
    """Tick values for a log axis from lo to hi (> 0), each with two significant digits at most: 1, 2
    and 5 times the powers of ten in it, or every digit times them when that gives fewer than three,
    or three values spread evenly on the log scale when even those do not (a span under a factor
    of two); never more than `most` (then the powers of ten, or every other one)."""
    decades = np.arange(np.floor(np.log10(lo)), np.ceil(np.log10(hi)) + 1)
    for subs in ((1.0,), (1.0, 2.0, 5.0), tuple(range(1, 10))):
        values = np.array([s * 10 ** d for d in decades for s in subs])
        values = values[(values >= lo) & (values <= hi)]
        if len(values) >= 3 or subs[-1] == 9:
            break
    if len(values) < 2:
        values = np.array([float(f"{v:.2g}") for v in np.geomspace(lo, hi, 4)[1:-1]] + [float(f"{lo:.2g}")])
        values = np.unique(values[(values >= lo) & (values <= hi)])
    while len(values) > most:
        values = values[::2]
    return values


def per_pose(robot: Robot, ds: DataSet) -> Figure:
    """Each pose's RMS point error (mm) of every stage against the pose's order in the file, the
    five largest of the last stage labelled with their pose ids (a pose within LABEL_CLEAR of the
    width of a larger one is not, its label would cover the other's): a bad pose stands out."""
    fig, ax = plt.subplots(figsize=(12, 3.0 + LEGEND_ROW))
    P = ds.data.n_poses
    x = np.arange(P)
    width = 0.8 / len(ds.stages)
    for k, (s, colour) in enumerate(zip(ds.stages, COLOURS)):
        sq = np.bincount(s.pose, np.sum(s.position_mm ** 2, axis=1), P)
        rms = np.sqrt(sq / np.maximum(np.bincount(s.pose, minlength=P), 1))
        # poses are not a sequence: bars side by side for a few, points for many, never a line joining them
        if P <= MAX_BARS:
            ax.bar(x + (k - (len(ds.stages) - 1) / 2) * width, rms, width, color=colour, label=s.stage)
        else:
            ax.plot(x, rms, "o", ms=2.5, color=colour, label=s.stage)
    labelled: list[int] = []  # the largest first, each far enough from the others for its label to stand clear
    for p in np.argsort(-rms):
        if len(labelled) == 5:
            break
        if all(abs(p - o) > LABEL_CLEAR * P for o in labelled):
            labelled.append(p)
            ax.annotate(f"pose {ds.data.pose_ids[p]}", (p, rms[p]), fontsize=7, xytext=(2, 2),
                        textcoords="offset points")
    ids = ds.data.pose_ids
    ax.xaxis.set_major_locator(matplotlib.ticker.FixedLocator(x) if P <= MAX_BARS // 2 else
                               matplotlib.ticker.MaxNLocator(nbins=MAX_BARS // 2, integer=True))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(
        lambda v, _: str(ids[int(v)]) if float(v).is_integer() and 0 <= v < P else ""))
    ax.set_xlim(-0.6, P - 0.4)
    ax.set_xlabel("pose id, in the order of the file")
    ax.set_ylabel("RMS point error (mm)")
    ax.set_title(f"{robot.name}, {ds.name} data: error per pose")
    ax.grid(alpha=0.3)
    fig.subplots_adjust(**MARGINS)
    _legend_above(fig, ax)
    return _figure(fig, f"poses_{ds.name}", f"RMS point error of each pose, {ds.name} data, each model")


def _binned_mean(ax, x: np.ndarray, y: np.ndarray, bins: int = 12):
    """The mean of y in equal bins of x, as a line: a periodic or sloped pattern stands out of the scatter."""
    ok = np.isfinite(y)
    edges = np.linspace(x.min(), x.max(), bins + 1)
    at = np.clip(np.searchsorted(edges, x[ok], side="right") - 1, 0, bins - 1)
    count = np.bincount(at, minlength=bins)
    mean = np.bincount(at, y[ok], minlength=bins) / np.maximum(count, 1)
    centre = (edges[:-1] + edges[1:]) / 2
    ax.plot(centre[count >= 3], mean[count >= 3], "-", color="black", lw=1.0)


def _ticks(lo: float, hi: float) -> np.ndarray:
    """The tick values a panel from lo to hi gets (matplotlib's default locator, at most 4 intervals)."""
    values = matplotlib.ticker.MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi)
    span = hi - lo
    return values[(values >= lo - 1e-10 * span) & (values <= hi + 1e-10 * span)]


def _tick_labels(values: np.ndarray) -> list[str]:
    """Tick labels as an axis of its own would print them, in full (no offset)."""
    formatter = matplotlib.ticker.ScalarFormatter(useOffset=False)
    formatter.create_dummy_axis()
    return formatter.format_ticks(values)


def _span(x: np.ndarray) -> tuple[float, float]:
    """The span of a panel showing x: its range with matplotlib's margins of 5 %; one unit either
    side of a value held still (every joint still: the panels show them all)."""
    lo, hi = float(x.min()), float(x.max())
    return (lo - 0.05 * (hi - lo), hi + 0.05 * (hi - lo)) if hi > lo else (lo - 1.0, hi + 1.0)


#: the gap between the panels of a residual grid's row, a share of a panel's width
GAP = 0.08  # as subplots_adjust(wspace=0.08) spaced them when each was an Axes


def residuals_per_joint(robot: Robot, ds: DataSet, st: Residuals) -> Figure:
    """Signed residual per axis (rows: x, y, z in mm, then orientation about x, y, z in mrad when
    measured) against each joint the data moves (columns; one held still shows nothing): a grid of
    small multiples, each row on one residual scale and each column on one joint's, named with
    units on the outer panels. A row is one Axes whose x holds its panels side by side, panel j
    from j (1 + GAP) to that plus 1, its joint's span (with matplotlib's margins of 5 %) mapped onto
    it: 36 Axes of their own took most of a report's time on small data."""
    rows = [(f"{a} residual (mm)", st.position_mm[:, k]) for k, a in enumerate("xyz")]
    if st.rotation_mrad is not None:
        rows += [(f"rot. about {a} (mrad)", st.rotation_mrad[:, k]) for k, a in enumerate("xyz")]
    moving = [k for k in range(robot.n) if np.ptp(ds.data.q[:, k]) > 0] or list(range(robot.n))
    colour = COLOURS[min(len(COLOURS) - 1, [s.stage for s in ds.stages].index(st.stage))]
    xs = [joint_values(robot, ds.data, k)[st.pose] for k in moving]
    spans = [_span(x) for x in xs]
    starts = np.arange(len(moving)) * (1 + GAP)

    def placed(col: int, values):
        lo, hi = spans[col]
        return starts[col] + (np.asarray(values, float) - lo) / (hi - lo)

    x_ticks = [_ticks(*span) for span in spans]
    grid = {"colors": matplotlib.rcParams["grid.color"], "linewidths": matplotlib.rcParams["grid.linewidth"],
            "alpha": 0.3, "zorder": 1.5}  # under the data, as axes.axisbelow "line" puts an axes' grid
    frame = {"fill": False, "linewidth": matplotlib.rcParams["axes.linewidth"],
             "edgecolor": matplotlib.rcParams["axes.edgecolor"], "zorder": 2.5, "clip_on": False}  # as spines are
    fig, axes = plt.subplots(len(rows), 1, figsize=(12, 1.75 * len(rows) + 0.7), squeeze=False)
    for r, (ylabel, values) in enumerate(rows):
        ax = axes[r, 0]
        finite = values[np.isfinite(values)]
        limit = 1.08 * np.abs(finite).max() if len(finite) and np.abs(finite).max() > 0 else 1.0
        y_ticks = _ticks(-limit, limit)
        lines = []  # the row's grid lines, drawn as one artist
        for col, x in enumerate(xs):
            u, a = placed(col, x), starts[col]
            ax.plot(u, values, ".", ms=3, alpha=0.7, color=colour)
            _binned_mean(ax, u, values)
            ax.add_patch(matplotlib.patches.Rectangle((a, -limit), 1.0, 2 * limit, **frame))
            lines += [[(v, -limit), (v, limit)] for v in placed(col, x_ticks[col])]
            lines += [[(a, v), (a + 1.0, v)] for v in y_ticks]
        ax.add_collection(LineCollection(lines, **grid))
        ax.hlines(np.zeros(len(xs)), starts, starts + 1.0, color="0.5", lw=0.6)
        ax.set_xlim(0.0, starts[-1] + 1.0)
        ax.set_ylim(-limit, limit)
        ax.set_yticks(y_ticks)
        ax.set_ylabel(ylabel, fontsize=7, labelpad=1)
        ax.tick_params(labelsize=6, pad=1)
        ax.set_frame_on(False)
        ax.set_xticks([])
    bottom = axes[-1, 0]
    bottom.set_xticks(np.concatenate([placed(col, t) for col, t in enumerate(x_ticks)]),
                      [label for t in x_ticks for label in _tick_labels(t)])
    joints = [joint_label(robot, k) for k in moving]
    bottom.set_xticks(starts + 0.5, joints, minor=True)  # minor ticks: a joint's name, below its values
    bottom.xaxis.remove_overlapping_locs = False  # a panel's centre may also be one of its ticks
    bottom.tick_params(axis="x", which="minor", length=0, pad=12, labelsize=7)
    fig.suptitle(f"{robot.name}, {ds.name} data, {st.stage}: signed residuals against each joint", fontsize=10)
    # fixed margins: tight_layout costs a second per figure
    height = fig.get_figheight()
    fig.subplots_adjust(left=0.06, right=0.995, bottom=0.45 / height, top=1 - 0.45 / height, hspace=0.1)
    still = [joint_label(robot, k) for k in range(robot.n) if k not in moving]
    return _figure(fig, f"residuals_{ds.name}_{_slug(st.stage)}",
                   f"Signed residuals, {st.stage} model, {ds.name} data"
                   + (f" (not shown: {', '.join(still)}, constant over the data)" if still else ""), tuple(joints))


def effect(robot: Robot, eff, size: np.ndarray, name: str, without: Residuals, after: Residuals, data) -> Figure:
    """Left: the generalized error the effect adds (its coefficients times their terms, mm or mrad)
    at each training pose (P,) against variable `name`; right, per axis x, y, z (mm): the residual
    without the effect (its coefficients zeroed, all else held) and that of the diagnosed model."""
    k = int(name[1:]) - 1 if name.startswith("q") and name[1:].isdigit() else None
    x = joint_values(robot, data, k) if k is not None else variable(data, name)
    label = joint_label(robot, k) if k is not None else variable_label(name)
    unit = "mm" if eff.error.split(".")[-1] in ("ex", "ey", "ez") else "mrad"
    fig, axes = plt.subplots(1, 4, figsize=(12, 3.0 + LEGEND_ROW))
    axes[0].plot(x, size, ".", ms=3, color=COLOURS[2])
    axes[0].set_ylabel(f"{eff.error} added ({unit})", fontsize=8)
    axes[0].set_title(f"fitted {eff.error}", fontsize=9)
    for a, ax in enumerate(axes[1:]):
        ax.plot(x[without.pose], without.position_mm[:, a], ".", ms=3, alpha=0.7, color=COLOURS[1],
                label="without this effect")
        ax.plot(x[after.pose], after.position_mm[:, a], ".", ms=3, alpha=0.7, color=COLOURS[2], label=after.stage)
        ax.axhline(0, color="0.5", lw=0.6)
        ax.set_ylabel(f"{'xyz'[a]} residual (mm)", fontsize=8)
        ax.set_title(f"{'xyz'[a]} residual", fontsize=9)
    for ax in axes:
        ax.set_xlabel(label, fontsize=8)
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(nbins=5))  # a quarter page: the default crowds
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    fig.subplots_adjust(**MARGINS, wspace=0.38)
    _legend_above(fig, axes[1])
    return _figure(fig, f"effect_{_slug(eff.error)}_{_slug(eff.terms[0])}_{_slug(name)}",
                   f"{eff.error} ({', '.join(eff.terms)}) against {label}: the fitted effect, and the residual "
                   "without it and with it")


def volume_map(robot: Robot, volume, samples, statement) -> Figure:
    """Each sample's own bound (the confidence quantile of its error, `verify.volume.Statement`)
    against every input the volume varies: the tool point's coordinates or the world position, each
    ranged joint, the payload; the bound on the worst in red, circling the sample where it is reached;
    the tolerance dashed."""
    where = samples.point if volume.tool_box is not None else samples.world
    frame = "tool point" if volume.tool_box is not None else "world"
    axes = [(f"{frame} {a} (m)", where[:, i]) for i, a in enumerate("xyz")]
    axes += [(joint_label(robot, k), joint_scale(robot, k) * samples.q[:, k]) for k in range(robot.n)]
    axes += [("payload (kg)", samples.payload_kg)]
    axes = [(label, x) for label, x in axes if np.ptp(x) > 1e-9]
    columns = min(MAP_COLUMNS, len(axes))
    rows = -(-len(axes) // columns)
    fig, panels = plt.subplots(rows, columns, figsize=(12, 2.8 * rows + 0.6), sharey=True, squeeze=False)
    for ax, (label, x) in zip(panels.flat, axes):
        ax.plot(x, statement.per_point_mm, ".", ms=2, alpha=0.5)
        ax.plot(x[statement.worst], statement.per_point_mm[statement.worst], "o", mfc="none", color="C3", ms=7)
        if statement.tolerance_mm is not None:
            ax.axhline(statement.tolerance_mm, color="k", ls="--", lw=1)
        ax.axhline(statement.bound_mm, color="C3", lw=1)
        ax.set_xlabel(label, fontsize=8)
        ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(nbins=6))  # a quarter page: the default crowds
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in panels.flat[len(axes):]:
        ax.set_visible(False)
    for row in panels:
        row[0].set_ylabel(f"{statement.confidence:.0%} bound of the point's error (mm)", fontsize=8)
    fig.suptitle(f"Compensated error over the volume: worst {statement.bound_mm:.3g} mm (red), "
                 f"{statement.verdict}", fontsize=9)
    fig.tight_layout()
    return _figure(fig, "volume-map", "Each sample's own bound against every input the volume varies; the bound "
                                      "on the worst over the volume in red, the sample where it is reached circled, "
                                      "the tolerance dashed.")
