"""Holds a gecgen run at a chosen step until a signal ends it, for the interruption tests
(tests/test_interrupt.py): GECGEN_TEST_HOLD="STEP:FLAG" replaces the function of STEP by one
that writes FLAG.PID (so the test knows, without waiting a fixed time, that the run is there) and
then waits for good. Imported by `python tests/hold.py ARGS` (then runs `gecgen ARGS`), and as a
Dask preload in a fleet's worker processes.

STEP: `start` (calibrate about to read its inputs, its folder held), `folds` (calibrate's
cross-validation folds, in its worker processes), `report` (calibrate writing its report: the
calibration and code already written into the new folder), `fleet` (fleet about to start its
cluster, its folder held), `summary` (fleet writing its summary: fleet.json written, fleet.csv not).
"""
import os
import signal
import sys
from pathlib import Path

import gecgen.api
import gecgen.cli.fleet
import gecgen.loop.calibrate
import gecgen.report


def _hold(*args, **kwargs):
    Path(f"{FLAG}.{os.getpid()}").write_text("held\n")
    while True:
        signal.pause()


if __name__ == "__main__":
    # Ctrl-C as a terminal gives it: the test runner's process may have SIGINT ignored (a process
    # that calls C's system() from two threads at once can be left so), and a child inherits that
    signal.signal(signal.SIGINT, signal.default_int_handler)

STEP, _, FLAG = os.environ.get("GECGEN_TEST_HOLD", "").partition(":")
if STEP == "start":
    gecgen.api.calibrate = _hold
elif STEP == "folds":
    gecgen.loop.calibrate.fold_score = _hold
elif STEP == "report":
    gecgen.report.write = _hold
elif STEP == "fleet":
    gecgen.cli.fleet._run_tasks = _hold
elif STEP == "summary":
    gecgen.cli.fleet.write_csv = _hold
elif STEP:
    raise SystemExit(f"GECGEN_TEST_HOLD: unknown step {STEP!r}")

if __name__ == "__main__":
    from gecgen.cli import main

    sys.exit(main(sys.argv[1:]))
