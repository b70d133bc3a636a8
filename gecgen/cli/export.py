"""`gecgen export CALIB [--c DIR] [--urdf OUT.urdf] [--table]`: a calibration into a controller."""
from __future__ import annotations

from gecgen.cli.common import CALIBRATION_HELP

import shlex
from pathlib import Path

from gecgen.model import ModelError


def add_parser(command):
    """Register `export` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("export", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("--c", metavar="DIR", help="write the generated C, NAME_calibration.h and NAME_example.c into DIR")
    p.add_argument("--urdf", metavar="OUT.urdf", help="write the robot's URDF with the constant errors in its joint "
                                                      "origins (URDF robots only)")
    p.add_argument("--table", action="store_true", help="joint zero offsets and constant errors per frame")


def run(args) -> dict:
    from gecgen.emit import robot_model_hash
    from gecgen.files import write_atomically
    from gecgen.runtime import calibration, export
    from gecgen.runtime.compiled import CompiledModel

    if not (args.c or args.urdf or args.table):
        raise ModelError("say what to export: --c DIR, --urdf OUT.urdf and/or --table")
    calib = calibration.load(args.calibration)
    where = args.calibration
    out: dict = {"calibration": where, "robot": calib.robot.name,
                 "model_hash": robot_model_hash(calib.robot, calib.model)}
    # everything is computed before anything is written: a refusal leaves no half export behind
    cm = CompiledModel(calib.robot, calib.model)
    urdf = export.urdf_copy(calib, cm, where) if args.urdf else None
    files, command = export.c_files(calib, cm, where) if args.c else (None, None)
    if args.table:
        out["table"] = export.table(calib, cm)
    if files is not None:
        for name, text in files.items():
            write_atomically(Path(args.c) / name, text)
        compile_args, run_args = export.compile_command(args.c, calib.robot.name)
        out["c"] = {"output": args.c, "files": sorted(files),
                    "compile": shlex.join(compile_args), "run": shlex.join(run_args),
                    "example_command": command}
    if urdf is not None:
        write_atomically(args.urdf, urdf[0])
        out["urdf"] = {"output": args.urdf, **urdf[1]}
    return out

