"""One BLAS thread for gecgen's linear algebra.

numpy and scipy each bring their own OpenBLAS, each with a pool of threads that spin while they
wait for work. gecgen's matrices are small (a few hundred columns) and its calls many and short,
alternating between the two libraries; with another busy process on the machine the pools spend
their time waiting on each other. Measured on the 2-core machine with one other process busy:
diagnose of the Panda's 5,000 poses took 407 s with the default pools and 50 s with one thread
each (identical results). The heavy verbs (identify, diagnose, design_poses) therefore run with one
BLAS thread per library; `threadpoolctl` restores the caller's setting when they return.
"""
from __future__ import annotations

import functools

from threadpoolctl import threadpool_limits


def one_blas_thread(fn):
    """Run `fn` with every loaded BLAS limited to one thread."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)
    return wrapper
