"""`gecgen export CALIB [--c DIR] [--urdf OUT.urdf] [--table]`: a calibration into a controller."""
from __future__ import annotations

from gecgen.cli.common import CALIBRATION_HELP

import shlex
import warnings
from pathlib import Path

import numpy as np

from gecgen.model import ModelError


def add_parser(command):
    """Register `export` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("export", run)
    p.add_argument("calibration", help=CALIBRATION_HELP)
    p.add_argument("--c", metavar="DIR", help="write the generated C, NAME_calibration.h and NAME_example.c into DIR")
    p.add_argument("--urdf", metavar="OUT.urdf", help="write the robot's URDF with the constant errors in its joint "
                                                      "origins (URDF robots only)")
    p.add_argument("--table", action="store_true", help="joint zero offsets and constant errors per frame")
    p.add_argument("--data", metavar="TRAIN.csv", help="with --urdf: the calibration's training data; when the URDF "
                                                       "cannot carry some terms, the exported model is scored on it "
                                                       "against the full calibration (mm)")
    p.add_argument("--val", metavar="VAL.csv", help="with --urdf: held-out data (in the calibration's tracker frame), "
                                                    "scored as --data is")
    g = p.add_argument_group("with a camera (docs/reference.md, \"Cameras\"): --data and --val are pixel files")
    g.add_argument("--cameras", metavar="FILE", help="camera file of a pixel calibration's cameras: --data's and "
                                                     "--val's image points are scored with the poses it fitted (px)")
    g.add_argument("--board", metavar="FILE", help="board file of the chessboard a camera on the tool sees")


def run(args) -> dict:
    from gecgen.emit import robot_model_hash
    from gecgen.model.files import write_atomically
    from gecgen.fit import calibration
    from gecgen.deliver import export
    from gecgen.runtime.compiled import CompiledModel

    if not (args.c or args.urdf or args.table):
        raise ModelError("say what to export: --c DIR, --urdf OUT.urdf and/or --table")
    if (args.data or args.val) and not args.urdf:
        raise ModelError("--data and --val score the exported URDF's model: give --urdf OUT.urdf too")
    if (args.cameras or args.board) and not (args.data or args.val):
        raise ModelError("--cameras and --board read the image points of --data and --val: give those too")
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
        if urdf[1]["not_carried"]:
            out["urdf"]["cost"] = _cost(args)
            _warn_left_out(urdf[1]["not_carried"], out["urdf"]["cost"], calib.report.get("measurement") == "pixels")
    return out


def _cost(args) -> dict:
    """What the exported model (the constant errors only, `export.rigid_part`) scores on --data and
    --val against the full calibration: {data set: {data, calibration_rms_mm, exported_rms_mm,
    calibration_max_mm, exported_max_mm, gap_rms_mm, gap_max_mm}}, each scored in the calibration's
    tracker frame. gap: how far apart the two models put every target at the data's poses. Scores
    of relative data (sockets, lengths) do not see where the robot is, only its consistency, so
    they can understate what the URDF gets wrong; the gap does not depend on what was measured.
    With --cameras the data are image points, scored in px (`_pixel_scores`) where the others are mm."""
    from gecgen.api import load_calibration
    from gecgen.deliver import export

    full, exported = load_calibration(args.calibration), load_calibration(args.calibration)
    exported._set(export.rigid_part(exported.calibration_))
    aux_names = full.calibration_.model.aux
    cost = {}
    for name, path in (("training", args.data), ("held_out", args.val)):
        if path:
            if args.cameras:
                data, scores = _pixel_scores(args, path, full.calibration_, exported.calibration_)
            else:
                score = full.score(path)
                a, b = score.after, exported.score(path).after
                data = score.data
                scores = {"calibration_rms_mm": a.rms_mm, "exported_rms_mm": b.rms_mm,
                          "calibration_max_mm": a.max_mm, "exported_max_mm": b.max_mm}
            q, w, aux = data.q, data.w, data.aux_columns(aux_names)
            with warnings.catch_warnings():  # score said them for these poses already
                warnings.simplefilter("ignore")
                gap = 1e3 * np.linalg.norm(full.predict(q, w, aux) - exported.predict(q, w, aux), axis=2).ravel()
            cost[name] = {"data": path, **scores, "gap_rms_mm": float(np.sqrt(np.mean(gap ** 2))),
                          "gap_max_mm": float(gap.max())}
    return cost


def _pixel_scores(args, path: str, full, exported) -> tuple:
    """The image points of `path` (a pixel file of the calibration's set-up) and what the full and the
    exported calibration leave of them, through the cameras' (and board's) poses the calibration fitted
    (as evaluate --cameras scores them): (Pixels, {calibration_rms_px, exported_rms_px,
    calibration_max_px, exported_max_px})."""
    from gecgen.cli.pixels import recorded_rig
    from gecgen.fit.camera import recorded_problem, summary_of
    from gecgen.model.pixels import read_pixels

    _, cameras, board = recorded_rig(args)
    data = read_pixels(path, full.robot, cameras, board)
    problem, g = recorded_problem(full, args.calibration, data, cameras, board)
    a, b = summary_of(problem, g, full.c), summary_of(problem, g, exported.c)
    return data, {"calibration_rms_px": a["rms_px"], "exported_rms_px": b["rms_px"],
                  "calibration_max_px": a["max_px"], "exported_max_px": b["max_px"]}


def _warn_left_out(left: list[dict], cost: dict, pixels: bool):
    """The URDF's warning: what it leaves out and, with data, what that costs (pixels: from a pixel calibration)."""
    top = left[0]
    unit = "px" if pixels and any("calibration_rms_px" in c for c in cost.values()) else "mm"
    said = "; ".join(f"on the {name.replace('_', '-')} data the exported model leaves {c[f'exported_rms_{unit}']:.3g} "
                     f"{unit} RMS against the calibration's {c[f'calibration_rms_{unit}']:.3g} {unit} and puts the "
                     f"targets {c['gap_rms_mm']:.3g} mm RMS (up to {c['gap_max_mm']:.3g} mm) from where the "
                     f"calibration does" for name, c in cost.items())
    give = ("give the calibration's images (--data TRAIN_PIXELS.csv, --val VAL_PIXELS.csv, with --cameras FILE, and "
            "--board FILE for a camera on the tool)" if pixels else "give the calibration's data (--data TRAIN.csv, --val VAL.csv)")
    warnings.warn(f"the URDF carries the constant errors only: {len(left)} coefficients of other terms are left out "
                  f"(largest {top['coefficient']}, up to {top['max_effect']:.3g} {top['unit']} over the training "
                  f"ranges); " + (said + " (urdf.cost)" if said else f"{give} to learn what that costs in {'px' if pixels else 'mm'}")
                  + "; see not_carried")

