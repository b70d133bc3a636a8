"""`gecgen compensate CALIB POSES.csv -o OUT.csv`: corrected joint commands for nominal commands."""
from __future__ import annotations

import sys

from gecgen.cli.common import checked, extrapolation
from gecgen.model import ModelError


def add_parser(command):
    """Register `compensate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("compensate", run, "corrected joint commands for nominal commands")
    p.add_argument("calibration")
    p.add_argument("poses", help="CSV with q1..qn (and optionally fx..mz and aux columns)")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--max-iter", type=int, default=50)


def run(args) -> dict:
    import numpy as np

    from gecgen.model.measurements import read_commands, write_commands
    from gecgen.runtime import calibration
    from gecgen.runtime.compiled import FAILED, NONFINITE, OUTSIDE_LIMITS

    if args.max_iter < 0:
        raise ModelError(f"--max-iter {args.max_iter}: give a non-negative number of Newton steps")
    calib = calibration.load(args.calibration)  # refuses non-finite coefficients, naming the first
    cmds = read_commands(args.poses, calib.robot, calib.model.aux)
    cm = checked(calib.model, calib.robot, cmds)
    q, status = cm.compensate(cmds.q, cmds.w, cmds.aux, calib.c, max_iter=args.max_iter)
    failed = np.nonzero(np.isin(status, FAILED))[0]
    if len(failed):
        k = failed[0]
        why = ("the correction is not finite (the command, wrench or aux values overflow the model)"
               if status[k] == NONFINITE else "the correction did not converge; the command may be near a singularity")
        raise RuntimeError(f"{args.poses}: row {k + 2}: {why} ({len(failed)} rows failed)")
    write_commands(args.output, calib.robot, cmds, q)
    outside = [int(k) + 2 for k in np.nonzero(status == OUTSIDE_LIMITS)[0]]
    if outside:
        print(f"gecgen compensate: warning: corrected commands leave the joint limits in rows {outside[:10]}"
              f"{' ...' if len(outside) > 10 else ''}", file=sys.stderr)
    dq = q - cmds.q
    return {"robot": calib.robot.name, "output": str(args.output), "n_poses": len(q), "outside_limits_rows": outside,
            "extrapolation": extrapolation(calib, cmds.q, cmds.w, cmds.aux),
            "max_correction": {name: float(np.abs(dq[:, j]).max()) for j, name in enumerate(calib.robot.joint_names)}}
