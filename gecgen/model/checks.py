"""Checks where an error model meets data: every basis term must be finite on every pose."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import sympy as sp

from gecgen.model.errors import ErrorModel
from gecgen.model.measurements import Commands, Measurements
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.validation import ModelError, excerpt


def check_terms_finite(model: ErrorModel, robot: Robot, data: Measurements | Commands, load_signals=None):
    """Refuse a term that is NaN or infinite on the data (sqrt of a negative reading, 1/q2 at q2 = 0).

    Fitting, diagnosing or compensating with it would fail deep inside, on a NaN Jacobian, after
    minutes of work; here the message names the term and the first pose (for commands: the row).
    `load_signals(q, w) -> (names, values (N, L))` gives the load signals a term may use
    (`CompiledModel.load_signals`: the compiler derives them); needed only when a term uses one."""
    aux = data.aux_columns(model.aux) if isinstance(data, Measurements) else data.aux
    values = {f"q{i + 1}": data.q[:, i] for i in range(robot.n)}
    values |= {w: data.w[:, k] for k, w in enumerate(WRENCH)}
    values |= {a: aux[:, k] for k, a in enumerate(model.aux)}
    known = set(values)
    if any(s.name not in known for t in model.unique_terms() for s in t.expr.free_symbols):
        names, signals = load_signals(data.q, data.w)
        values |= dict(zip(names, signals.T))
    for term in model.unique_terms():
        symbols = sorted(term.expr.free_symbols, key=lambda s: s.name)
        if not symbols:
            continue
        args = [values[s.name] for s in symbols]
        with np.errstate(all="ignore"):
            v = np.broadcast_to(sp.lambdify(symbols, term.expr, modules="numpy")(*args), data.q.shape[:1])
        bad = np.nonzero(~np.isfinite(v))[0]
        if len(bad):
            p = bad[0]
            place = (f"pose {data.pose_ids[p]}" if isinstance(data, Measurements) else
                     f"row {p + 2}" if data.header else f"row {p} (0-based)")  # a file's line, or an array's row
            at = ", ".join(f"{s.name} = {values[s.name][p]:g}" for s in symbols[:3])
            raise ModelError(f"{data.source}: {place}: the term {excerpt(term.label)} of {Path(model.source).name} is "
                             f"{'NaN' if np.isnan(v[p]) else 'infinite'} at {at}; change the term or check the data")
