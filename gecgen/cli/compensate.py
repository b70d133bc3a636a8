"""`gecgen compensate CALIB POSES.csv -o OUT.csv`: corrected joint commands for nominal commands."""
from __future__ import annotations

from gecgen.cli.common import CALIBRATION_HELP, whole

import sys



def add_parser(command):
    """Register `compensate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("compensate", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("poses", help="CSV with q1..qn (and optionally fx..mz and aux columns)")
    p.add_argument("-o", "--output", required=True, help="CSV to write: the same rows and columns, q1..qn corrected")
    p.add_argument("--max-iter", type=whole(0, 1_000_000), default=50,
                   help="Newton steps at most per command (default %(default)s)")
    p.add_argument("--branch", help="on a robot with branches: the branch whose tool to place (its own joints are "
                                    "corrected, every other reading held)")


def run(args) -> dict:
    from gecgen.api import load_calibration
    from gecgen.model.measurements import read_commands, write_commands
    from gecgen.model.validation import nearest, require

    cal = load_calibration(args.calibration)  # refuses non-finite coefficients, naming the first
    names = [b.name for b in cal.robot_.branches]
    # said here in the option's words: the API's own refusal speaks of its keyword, branch=
    require(args.branch is None if not names else args.branch in names,
            f"--branch: robot {cal.robot_.name} is a serial chain with one tool; leave --branch out" if not names else
            f"--branch{' ' + args.branch if args.branch else ''}: robot {cal.robot_.name} has branches; name the one whose tool to place: "
            f"{nearest(args.branch, names)}")
    cmds = read_commands(args.poses, cal.robot_, cal.calibration_.model.aux)
    done = cal.compensate(cmds, max_iter=args.max_iter, branch=args.branch)
    write_commands(args.output, cal.robot_, cmds, done.q)
    outside = [k + 2 for k in done.outside_limits]
    if outside:
        print(f"gecgen compensate: warning: corrected commands leave the joint limits in rows {outside[:10]}"
              f"{' ...' if len(outside) > 10 else ''}", file=sys.stderr)
    return {"robot": cal.robot_.name, "error_model": cal.calibration_.model.source, "output": str(args.output),
            "n_poses": len(done.q), "outside_limits_rows": outside, "extrapolation": done.extrapolation,
            "max_correction": done.max_correction,
            "max_correction_units": {j.name: "rad" if j.kind == "R" else "m" for j in cal.robot_.joints}}
