"""`gecgen filter CALIB PROGRAM -o OUT`: a robot program with its targets corrected through the calibration."""
from __future__ import annotations

from gecgen.cli.common import CALIBRATION_HELP, whole


def add_parser(command):
    p = command("filter", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("program", help="the robot program: KUKA .src (its .dat beside it), ABB RAPID .mod/.modx/.prg, "
                                      "FANUC TP .ls or UR .script")
    p.add_argument("-o", "--output", required=True,
                   help="the corrected program to write (KRL: under the same name in another folder, its .dat "
                        "beside it); the change log goes beside it as OUTPUT.log.csv")
    p.add_argument("--frames", help="YAML with the tools, bases and flange the program names but does not "
                                    "declare, in the controller's own units and angles")
    p.add_argument("--format", choices=["krl", "rapid", "tp", "ur"],
                   help="the program's format (default: from its suffix)")
    p.add_argument("--max-iter", type=whole(0, 1_000_000), default=50, help="Newton steps at most per compensation "
                                                                            "(default %(default)s)")


def run(args) -> dict:
    from gecgen.api import load_calibration
    from gecgen.cli import Incomplete
    from gecgen.deliver.programs import filter_program

    cal = load_calibration(args.calibration)
    outcome, written, log = filter_program(cal, args.program, args.output, args.frames, args.format, args.max_iter)
    kept = outcome.kept
    result = {"robot": cal.robot_.name, "program": str(args.program),
              "written": [str(p) for p in written.values()], "log": str(log),
              "n_targets": len(outcome.changes), "corrected": outcome.corrected, "status_counts": outcome.counts(),
              "kept": [{"target": c.target.name, "file": c.target.file.name, "line": c.target.line,
                        "reason": c.reason} for c in kept],
              "max_correction_mm": max((c.position_mm for c in outcome.changes), default=0.0),
              "max_correction_deg": max((c.rotation_deg for c in outcome.changes), default=0.0)}
    if kept:
        first = kept[0]
        raise Incomplete(f"{first.target.file}:{first.target.line}: {first.target.name} kept as written "
                         f"({first.reason}); {outcome.corrected} of {len(outcome.changes)} targets corrected, "
                         f"{len(kept)} kept as written (each with its reason in {result['log']}): the program is "
                         f"written, the kept targets carry the uncalibrated error", result)
    return result
