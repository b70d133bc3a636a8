"""Checks where an error model meets data: every basis term must be finite on every pose."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gecgen.model.errors import ErrorModel
from gecgen.model.measurements import Commands, Measurements
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.validation import ModelError, excerpt


def check_terms_finite(model: ErrorModel, robot: Robot, data: Measurements | Commands, compiled):
    """Refuse a term that is NaN or infinite on the data (sqrt of a negative reading, 1/q2 at q2 = 0).

    Fitting, diagnosing or compensating with it would fail deep inside, on a NaN Jacobian, after
    minutes of work; here the message names the term and the first pose (for commands: the row).
    `compiled` evaluates the terms as the fit does (`CompiledModel`: its `basis(q, w, aux)`, (N,
    terms) in `model.unique_terms()` order, and `load_signals(q, w)` for the message)."""
    aux = data.aux_columns(model.aux) if isinstance(data, Measurements) else data.aux
    with np.errstate(all="ignore"):
        f = np.asarray(compiled.basis(data.q, data.w, aux))
    bad_rows, bad_terms = np.nonzero(~np.isfinite(f))
    if not len(bad_rows):
        return
    k = bad_terms.min()  # the first term, at its first pose
    p = bad_rows[bad_terms == k].min()
    term = model.unique_terms()[k]
    values = {f"q{i + 1}": data.q[:, i] for i in range(robot.n)}
    values |= {w: data.w[:, j] for j, w in enumerate(WRENCH)}
    values |= {a: aux[:, j] for j, a in enumerate(model.aux)}
    if any(v not in values for v in term.variables):
        names, signals = compiled.load_signals(data.q, data.w)
        values |= dict(zip(names, signals.T))
    place = (f"pose {data.pose_ids[p]}" if isinstance(data, Measurements) else
             f"row {p + 2}" if data.header else f"row {p} (0-based)")  # a file's line, or an array's row
    at = ", ".join(f"{v} = {values[v][p]:g}" for v in term.variables[:3])
    raise ModelError(f"{data.source}: {place}: the term {excerpt(term.label)} of {Path(model.source).name} is "
                     f"{'NaN' if np.isnan(f[p, k]) else 'infinite'} at {at}; change the term or check the data")
