"""`gecgen compensate CALIB POSES.csv -o OUT.csv`: corrected joint commands for nominal commands."""
from __future__ import annotations

import sys

from gecgen.cli.common import CALIBRATION_HELP, progress_status, say, whole


def add_parser(command):
    """Register `compensate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("compensate", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("poses", help="CSV with q1..qn (and optionally fx..mz and aux columns)")
    p.add_argument("-o", "--output", required=True,
                   help="CSV to write: the same rows and columns, q1..qn corrected, and each row's status and "
                        "residual_mm")
    p.add_argument("--max-iter", type=whole(0, 1_000_000), default=50,
                   help="Newton steps at most per solve (default %(default)s; near a singular posture one solve per damping tried)")
    p.add_argument("--bound", metavar="B[,B...]",
                   help="largest correction per joint, in the joint's unit (rad or m): one value for every joint "
                        "or one per joint, comma-separated (inf leaves a joint free); a joint that reaches it is "
                        "held there and its row's status is bounded (5)")
    p.add_argument("--branch", help="on a robot with branches: the branch whose tool to place (its own joints are "
                                    "corrected, every other reading held)")


def parse_bound(text: str | None, n: int) -> list[float] | None:
    """--bound as n values, or a one-line refusal naming the option and the fix."""
    from gecgen.model import ModelError

    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ModelError(f"--bound {text}: not numbers; give one correction bound (rad or m) or {n} comma-separated"
                         ) from None
    if len(values) not in (1, n):
        raise ModelError(f"--bound {text}: {len(values)} values; give one for every joint or {n}, comma-separated")
    if not all(v >= 0 for v in values):
        raise ModelError(f"--bound {text}: a bound is negative or nan; give corrections >= 0 (inf leaves a joint free)")
    return values * n if len(values) == 1 else values


def run(args) -> dict:
    import numpy as np

    from gecgen.api import load_calibration
    from gecgen.cli import Incomplete
    from gecgen.model.measurements import read_commands, write_commands
    from gecgen.model.validation import nearest, require
    from gecgen.runtime.compiled import NONFINITE, STATUS_NAMES

    with progress_status(not args.json) as status:
        say(status, f"loading the calibration {args.calibration} and its compiled code")
        cal = load_calibration(args.calibration)  # refuses non-finite coefficients, naming the first
        robot = cal.robot_
        names = [b.name for b in robot.branches]
        # said here in the option's words: the API's own refusal speaks of its keyword, branch=
        require(args.branch is None if not names else args.branch in names,
                f"--branch: robot {robot.name} is a serial chain with one tool; leave --branch out" if not names else
                f"--branch{' ' + args.branch if args.branch else ''}: robot {robot.name} has branches; name the one "
                f"whose tool to place: {nearest(args.branch, names)}")
        bound = parse_bound(args.bound, robot.n)
        cmds = read_commands(args.poses, robot, cal.calibration_.model.aux)
        say(status, f"correcting {len(cmds.q)} commands")
        done = cal.compensate(cmds, max_iter=args.max_iter, branch=args.branch, bound=bound)
        say(status, f"writing {args.output}")
        # every row written, its status beside it: a controller reads which commands it may send
        residual = ["" if s == NONFINITE else repr(float(1e3 * r)) for s, r in zip(done.status, done.residual)]
        write_commands(args.output, robot, cmds, done.q,
                       {"status": [str(int(s)) for s in done.status], "residual_mm": residual})
    outside = [k + 2 for k in done.outside_limits]
    if outside:
        print(f"gecgen compensate: warning: corrected commands leave the joint limits in rows {outside[:10]}"
              f"{' ...' if len(outside) > 10 else ''}", file=sys.stderr)
    result = {"robot": robot.name, "error_model": cal.calibration_.model.source, "output": str(args.output),
              "n_poses": len(done.q), "outside_limits_rows": outside, "extrapolation": done.extrapolation,
              "max_correction": done.max_correction,
              "max_correction_units": {j.name: "rad" if j.kind == "R" else "m" for j in robot.joints},
              "status_counts": done.counts(), "failed_rows": [k + 2 for k in done.failed],
              "max_residual_mm": float(1e3 * np.max(done.residual, initial=0.0, where=done.status != NONFINITE))}
    if done.failed:
        rows, k = [k + 2 for k in done.failed], done.failed[0]
        kinds = ", ".join(f"{n} {name}" for name, n in done.counts().items()
                          if STATUS_NAMES.index(name) in {int(done.status[i]) for i in done.failed})
        moved = robot.moved_joints(robot.branch_index(args.branch))
        raise Incomplete(f"{cmds.source}: row {rows[0]}: {_why(int(done.status[k]), done.residual[k], moved)}; "
                         f"{len(rows)} of "
                         f"{len(done.q)} rows not placed ({kinds}: rows {', '.join(map(str, rows[:10]))}"
                         f"{' ...' if len(rows) > 10 else ''}); every row is in {args.output} with its status and "
                         f"residual_mm", result)
    return result


def _why(status: int, residual: float, moved: list[str]) -> str:
    """What a failed row's status means, in a few words; moved: the joints the correction moves (with
    fewer than 6 it places the tool's position where the whole pose is out of reach, and fewer than 3
    cannot place even that, whatever the posture)."""
    from gecgen.runtime.compiled import BOUNDED, NONFINITE, SINGULAR

    left = f"the tool is off by {1e3 * residual:.3g} mm"
    if status != NONFINITE and status != BOUNDED and len(moved) < 3:
        return (f"the correction did not converge: the {len(moved)} joints it moves ({', '.join(moved)}) cannot "
                f"place the tool's position ({left})")
    return {NONFINITE: "the correction is not finite (the command, wrench or aux values overflow the model)",
            SINGULAR: f"near a singular posture, corrected only as far as the model's error justifies ({left})",
            BOUNDED: f"a joint's correction reached --bound ({left})"}.get(
        status, f"the correction did not converge ({left})")
