"""One BLAS thread for gecgen's linear algebra.

numpy and scipy each bring their own OpenBLAS, each with a pool of threads that spin while they
wait for work. gecgen's matrices are small (a few hundred columns) and its calls many and short,
alternating between the two libraries; with another busy process on the machine the pools spend
their time waiting on each other. Measured on the 2-core machine with one other process busy:
diagnose of the Panda's 5,000 poses took 407 s with the default pools and 50 s with one thread
each (identical results). The heavy verbs (identify, diagnose, design_poses) therefore run with
GECGEN_BLAS_THREADS (environment, default 1) BLAS threads per library; `threadpoolctl` restores
the caller's setting when they return.
"""
from __future__ import annotations

import functools
import os

from threadpoolctl import threadpool_limits

from gecgen.model.validation import require

#: the environment variable that sets the BLAS threads of the heavy verbs
VARIABLE = "GECGEN_BLAS_THREADS"


def blas_threads() -> int:
    """The BLAS threads per library the heavy verbs use: GECGEN_BLAS_THREADS, default 1."""
    text = os.environ.get(VARIABLE, "1").strip()
    require(text.isdigit() and int(text) >= 1, f"{VARIABLE}={text!r}: give a whole number of threads, 1 or more "
                                               f"(default 1)")
    return int(text)


def one_blas_thread(fn):
    """Run `fn` with every loaded BLAS limited to `blas_threads()` threads."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=blas_threads(), user_api="blas"):
            return fn(*args, **kwargs)
    return wrapper
