"""Independent tasks in worker processes: calibrate's folds, a report's figures.

Python runs one thread of Python at a time, and most of a fold's fit or a figure's drawing is
Python, so the cores are used by processes. They are forked (on Linux): each starts with what the
parent has loaded (compiled models, matplotlib, the imports), so a task pays only for pickling its
arguments and result. Each task computes exactly what it would in the parent, its warnings are
issued again in the parent, and results come back in task order, so nothing a task returns or says
depends on how many processes ran it. GECGEN_WORKERS (environment) sets how many (default: the cores
this process may run on; 1 runs every task here, in order; so does a daemon process, such as a Dask
worker of a fleet, which already runs robots side by side and may not fork).

A forked worker inherits the parent's locks as they were at the fork: a terminal's progress spinner
writing to stderr at that moment would leave the worker's stderr locked for good. Workers therefore
write to fresh streams of their own (`_own_streams`), never to the inherited ones.

Workers live and die with the parent: Ctrl-C (which a terminal sends to every process of the
command) is the parent's to handle, and the parent ending for any reason (an error, Ctrl-C,
SIGTERM, SIGKILL) ends them, where they would otherwise wait for good on the pipe to a parent that
is gone, each holding the memory it inherited (`_worker_start`, `_stop`).
"""
from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import warnings
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
    GECGEN_WORKERS=1, in a daemon process, or off Linux (where forking a process that has loaded the
    system's BLAS is not safe)."""
    if n_calls <= 1 or multiprocessing.current_process().daemon or not sys.platform.startswith("linux"):
        return 1
    return min(workers(), n_calls)


@contextmanager
def mapped(calls: list[tuple[Callable, tuple]]) -> Iterator[Iterable]:
    """fn(*args) of every (fn, args) of calls (fn module-level, args picklable), in their order, as an
    iterator valid inside the `with`; in `side_by_side(len(calls))` forked processes, whose tasks are
    all handed out on entry (this process is free meanwhile). Leaving the `with` early (an error, an
    interrupt) cancels the tasks not yet started."""
    n = side_by_side(len(calls))
    if n <= 1:
        yield (fn(*args) for fn, args in calls)
        return
    pool = ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("fork"), initializer=_worker_start,
                               initargs=(os.getpid(),))
    # submitted one by one rather than through pool.map, whose results iterator cancels the pending
    # futures as an interrupt passes through it; with the workers then killed, Python 3.11's executor
    # fails those cancelled futures from its own thread with InvalidStateError, a traceback on stderr
    futures = [pool.submit(_call, fn, args) for fn, args in calls]
    try:
        yield (_reissued(*future.result()) for future in futures)
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown(wait=True, cancel_futures=True)  # the workers are alive: cancelling is safe


def _stop(pool: ProcessPoolExecutor):
    """End the pool now: its workers killed, not left to finish their tasks (a fold can take
    minutes), whose results nobody will read."""
    kill = getattr(pool, "kill_workers", None)  # Python 3.14
    if kill is not None:
        kill()
    else:  # before 3.14 the executor keeps its processes in `_processes` and offers no public way
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.kill()
    # the futures are not cancelled here: with its workers gone the executor fails every pending one
    # itself, and before Python 3.12 it raised InvalidStateError from its own thread (a traceback on
    # stderr) on any that had been cancelled meanwhile
    pool.shutdown(wait=False)


#: prctl's option that sends the calling process a signal when its parent ends (linux/prctl.h)
PR_SET_PDEATHSIG = 1


def _worker_start(parent: int):
    """A worker's set-up (see the module docstring): killed by the system when the parent ends,
    Ctrl-C left to the parent, the parent's SIGTERM handler (the CLI's) not inherited, and stdout and
    stderr of its own."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (AttributeError, OSError):  # no prctl here: the parent's `_stop` is all there is
        pass
    if os.getppid() != parent:  # the parent ended before the request above was made
        os._exit(1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _own_streams()


def _own_streams():
    """A worker's stdout and stderr: new file objects on the same descriptors (see the module docstring)."""
    sys.stdout = open(os.dup(1), "w", buffering=1)  # noqa: SIM115 - the worker's for its whole life
    sys.stderr = open(os.dup(2), "w", buffering=1)  # noqa: SIM115


def _call(fn: Callable, args: tuple):
    """fn(*args) in a worker, with the warnings it issued."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args)
    return out, [(w.message, w.category, w.filename, w.lineno) for w in caught]


def _reissued(out, caught: list):
    """A worker's result, its warnings issued again here, under this process's filters."""
    for message, category, filename, lineno in caught:
        warnings.warn_explicit(message, category, filename, lineno)
    return out
