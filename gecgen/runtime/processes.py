"""Independent tasks in worker processes: calibrate's folds, a report's figures.

Python runs one thread of Python at a time, and most of a fold's fit or a figure's drawing is
Python, so the cores are used by processes. They are forked: each starts with what the parent has
loaded (compiled models, matplotlib, the imports), so a task pays only for pickling its arguments
and result. Each task computes exactly what it would in the parent, and results come back in task
order, so nothing a task returns depends on how many processes ran it. GECGEN_WORKERS (environment)
sets how many (default: the cores this process may run on; 1 runs every task here, in order; a
daemon process, such as a Dask worker, runs them here too).
"""
from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Callable, Iterable, Iterator

from gecgen.model.validation import require

#: the environment variable that sets how many processes run independent tasks
VARIABLE = "GECGEN_WORKERS"


def workers() -> int:
    """GECGEN_WORKERS, default the cores this process may run on."""
    text = os.environ.get(VARIABLE, "").strip()
    if not text:
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    require(text.isdigit() and int(text) >= 1, f"{VARIABLE}={text!r}: give a whole number of processes, 1 or more")
    return int(text)


def side_by_side(n_calls: int) -> int:
    """How many processes `mapped` runs n_calls in: 1 (this one) for a single call, with
    GECGEN_WORKERS=1, in a daemon process (a Dask worker of a fleet, which already runs robots side by
    side, may not fork) or where processes cannot be forked."""
    n = min(workers(), n_calls)
    if multiprocessing.current_process().daemon or "fork" not in multiprocessing.get_all_start_methods():
        return 1
    return max(n, 1)


@contextmanager
def mapped(calls: list[tuple[Callable, tuple]]) -> Iterator[Iterable]:
    """fn(*args) of every (fn, args) of calls (fn module-level, args picklable), in their order, as an
    iterator valid inside the `with`; in `side_by_side(len(calls))` forked processes, whose tasks are
    all handed out on entry (this process is free meanwhile)."""
    n = side_by_side(len(calls))
    if n <= 1:
        yield (_call(fn, args) for fn, args in calls)
        return
    with ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("fork")) as pool:
        yield pool.map(_call, *zip(*calls))


def _call(fn: Callable, args: tuple):
    return fn(*args)
