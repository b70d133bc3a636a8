"""The background build of a new model's C: run as `python -m gecgen.runtime.background` by
`runtime.compiled.build_in_background`, the robot, error model and cache key pickled on stdin.

It builds the shared library into the cache (`$GECGEN_CACHE`, as the starting process saw it) at low
priority, under the cache's locks and atomic writes: a second build of the same entry waits for
this one, and no process reads a half-written entry. Its output goes nowhere: a build that fails
here fails again, with its message, in the next run that needs the C.
"""
from __future__ import annotations

import os
import pickle
import sys

from gecgen.runtime.compiled import shared_library


def main() -> int:
    robot, model, key = pickle.load(sys.stdin.buffer)
    if hasattr(os, "nice"):
        os.nice(10)  # the run that started it comes first
    shared_library(robot, model, key)
    return 0


if __name__ == "__main__":
    sys.exit(main())
