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
    from gecgen.api import filter_program, load_calibration
    from gecgen.cli import Incomplete

    cal = load_calibration(args.calibration)
    done = filter_program(cal, args.program, args.output, frames=args.frames, format=args.format,
                          max_iter=args.max_iter)
    kept = done.kept
    result = {"robot": cal.robot_.name, "controller": cal.robot_.controller or None, "program": str(args.program),
              "written": [str(p) for p in done.written.values()], "log": str(done.log),
              "n_targets": len(done.targets), "corrected": done.corrected, "status_counts": done.counts,
              "kept": [{"target": t.name, "file": t.file.name, "line": t.line, "reason": t.reason} for t in kept],
              "max_correction_mm": max((t.position_mm for t in done.targets), default=0.0),
              "max_correction_deg": max((t.rotation_deg for t in done.targets), default=0.0)}
    if kept:
        first = kept[0]
        raise Incomplete(f"{first.file}:{first.line}: {first.name} kept as written ({first.reason}); "
                         f"{done.corrected} of {len(done.targets)} targets corrected, {len(kept)} kept as written "
                         f"(each with its reason in {result['log']}): the program is written, the kept targets "
                         f"carry the uncalibrated error", result)
    return result
