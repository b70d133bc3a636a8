"""One BLAS thread for gecgen's linear algebra.

numpy and scipy each bring their own OpenBLAS, each with a pool of threads that spin while they
wait for work. gecgen's matrices are small (a few hundred columns) and its calls many and short,
alternating between the two libraries; with another busy process on the machine the pools spend
their time waiting on each other. Measured on the 2-core machine with one other process busy:
diagnose of the Panda's 5,000 poses took 407 s with the default pools and 50 s with one thread
each (identical results). The heavy verbs (identify, diagnose, design_poses) therefore run with
GECGEN_BLAS_THREADS (environment, default 1) BLAS threads per library; `threadpoolctl` restores
the caller's setting when they return. A `gecgen` command uses that many from its start
(`command_threads`): the rest of its algebra is as small (a command's placement of its targets, its
significance test, its report), and a pool of threads that is never started costs nothing to wait
on (`gecgen identify` of 450 PPS poses with the machine loaded: 1.3 s of CPU against 2.1 to 3.3 s).
"""
from __future__ import annotations

import functools
import os
import sys

from gecgen.model.validation import require

#: the environment variable that sets the BLAS threads of the heavy verbs
VARIABLE = "GECGEN_BLAS_THREADS"


def blas_threads() -> int:
    """The BLAS threads per library the heavy verbs use: GECGEN_BLAS_THREADS, default 1."""
    text = os.environ.get(VARIABLE, "1").strip()
    require(text.isdigit() and int(text) >= 1, f"{VARIABLE}={text!r}: give a whole number of threads, 1 or more "
                                               f"(default 1)")
    return int(text)


#: the variable OpenBLAS (numpy's and scipy's) reads for the size of its pool when it loads
OPENBLAS = "OPENBLAS_NUM_THREADS"


def command_threads() -> None:
    """A command's BLAS pools sized to `blas_threads()` from the start: OPENBLAS_NUM_THREADS set, unless
    the user set it, before numpy loads its BLAS (afterwards it would change nothing: then nothing is
    set). A GECGEN_BLAS_THREADS that is not a number is left to the verbs that use it to refuse."""
    if "numpy" not in sys.modules and OPENBLAS not in os.environ:
        text = os.environ.get(VARIABLE, "1").strip()
        if text.isdigit() and int(text) >= 1:
            os.environ[OPENBLAS] = text


def one_blas_thread(fn):
    """Run `fn` with every loaded BLAS limited to `blas_threads()` threads."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=blas_threads(), user_api="blas"):
            return fn(*args, **kwargs)
    return wrapper
