"""`gecgen calibrate ROBOT TRAIN [--val VAL | --holdout F] -o DIR`: the whole pipeline in one command.

The model is chosen on the training data alone (gecgen/loop/calibrate.py says the rule); DIR gets
the calibration, the chosen error model, its generated code and a report. With `--cameras FILE
[--board FILE]` TRAIN (and VAL) are pixel files (`cli.pixels.calibrated`).
"""
from __future__ import annotations

from pathlib import Path

from gecgen.cli import pixels
from gecgen.cli.common import (MAX_SEED, add_keep_insignificant, add_noise, add_orientation_length, add_tolerance,
                               next_commands, progress_status, say, warned, whole)
from gecgen.cli.human import warning_lines
from gecgen.cli.register import REGISTER, add_register
from gecgen.loop import NAMES


def add_parser(command):
    """Register `calibrate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("calibrate", run)
    p.add_argument("robot", help="robot file (robots/NAME.yaml)")
    p.add_argument("train", help="training measurement CSV: the model is chosen and fitted on it alone")
    held = p.add_mutually_exclusive_group()
    held.add_argument("--val", help="validation measurement CSV, scored after the choice (never used to choose)")
    held.add_argument("--holdout", type=float, help="share of TRAIN's poses to hold out for validation instead "
                                                    "(split by pose, seeded by --seed), e.g. 0.2")
    add_register(p, REGISTER, bare="val", default="auto",
                 lead="registration of TRAIN onto the nominal model: auto (when far apart), always or never; val: "
                      "auto, and --val, measured from another tracker stationing, gets its frame fitted (the "
                      "coefficients held) before it is scored, as evaluate --register does")
    p.add_argument("--errors", help="the robot's default error model among the candidates (default: "
                                    "robots/NAME.errors.yaml beside the robot file, if any)")
    p.add_argument("--models", default=",".join(NAMES),
                   help="comma-separated candidates to choose among (default: %(default)s; those that do not apply "
                        "to the robot and data are skipped)")
    p.add_argument("--seed", type=whole(0, MAX_SEED), default=0,
                   help="seed of the cross-validation folds and of --holdout (default %(default)s)")
    p.add_argument("-o", "--output", required=True, help="folder for calibration.json, errors.yaml, report.md, "
                                                         "report.html and generated/ (the C and CasADi code, "
                                                         "NAME_calibration.h with the coefficients, NAME_example.c)")
    add_orientation_length(p)
    add_keep_insignificant(p)
    add_noise(p)
    add_tolerance(p)
    pixels.add_options(p)


def run(args) -> dict:
    from gecgen.model.files import output_folder

    out = Path(args.output)
    try:
        # the folder is held from the start (a second run into it is refused at once) and written
        # aside, replacing the old one whole at the end (files.output_folder)
        with output_folder(out, "calibration folder") as build, progress_status(not args.json) as status, \
                warned() as caught:
            if args.cameras or args.board or args.refine_intrinsics:
                return pixels.calibrated(args, out, build, status)
            return _calibrate(args, out, build, status, caught)
    except KeyboardInterrupt as exc:
        raise type(exc)(f"{out} is as it was before this run") from None


def _calibrate(args, out: Path, build: Path, status, caught: list) -> dict:
    """The command's work, its files written into `build`, which becomes `out`: the paths the result
    names are those under `out`. Says how far it is on `status` (`common.progress_status`); caught:
    the warnings said on the way (`warned`), which the result and the report carry."""
    from gecgen import report
    from gecgen.api import calibrate, model_names
    from gecgen.model.files import write_atomically
    from gecgen.loop.diagnose import write_error_model
    from gecgen.deliver import export
    from gecgen.runtime.compiled import CompiledModel, build_in_background

    names = model_names(tuple(n.strip() for n in args.models.split(",")), "--models")
    register_val = args.register == "val"
    say(status, "reading the robot and the data, compiling the candidate models")
    sel = calibrate(args.robot, args.train, args.val, holdout=args.holdout, errors=args.errors, models=names,
                    seed=args.seed, orientation_length=args.orientation_length, register_val=register_val,
                    register="auto" if register_val else args.register,
                    progress=lambda name: say(status, f"cross-validating the {name} model on the training poses"),
                    stage=lambda text: say(status, text),
                    keep_insignificant=args.keep_insignificant, noise_mm=args.noise_mm)
    say(status, f"writing the calibration, its code and the report into {out}")
    cal, choice = sel.calibrator, sel.choice
    # the same depth beside `out`: the robot file's path relative to the calibration is the same
    cal.save(build / "calibration.json")
    write_error_model(cal.robot_, choice.model, sel.effects, build / "errors.yaml")
    # the code, the coefficient header and an example program: what `gecgen export --c` writes, its
    # example command chosen on the calibration's own targets (the fit's model of pose data has the
    # measured frames' vertices as targets, which the emitted code does not)
    calib = cal.calibration_
    # its C, when not built, is built after the files are written: a background build started now would
    # hold the printed code's lock while it imports and prints, and the C source below would wait for it
    cm = CompiledModel(calib.robot, calib.model, build=False)
    code, _ = export.c_files(calib, cm, str(out / "calibration.json"))
    for name, text in code.items():
        write_atomically(build / "generated" / name, text)
    result = {"robot": cal.robot_.name, "train_data": str(args.train), "output": str(out), **sel.counts,
              "model": sel.model, "error_model": str(out / "errors.yaml"), "candidates": sel.table,
              "n_params": len(choice.model.coefficients),
              "n_identifiable": choice.fit.redundancy.n_identifiable, "n_carried": len(choice.fit.redundancy.kept),
              "significance": cal.report_["significance"], "before": choice.fit.before,
              "train": choice.fit.train, "outliers": [o.to_dict() for o in choice.fit.outliers],
              "effects": [e.to_dict() for e in sel.effects], "placement": cal.report_["placement"]}
    if sel.val is not None:
        result["validation"] = str(args.val) if args.val else f"--holdout {args.holdout:g} of {args.train} (seed {args.seed})"
        result["val_extrapolation"] = sel.val_extrapolation
        result["val_before"], result["val"] = sel.val_before.to_dict(), sel.val.to_dict()
        if sel.val_inside:  # the held-out poses inside every training range: where the model is validated
            result["val_inside"] = sel.val_inside.to_dict()
        result["val_registered"] = register_val
        if sel.val_branches:
            result["val_branches"] = sel.val_branches
    files = {"calibration": out / "calibration.json", "errors": out / "errors.yaml", "generated": out / "generated",
             "coefficient_header": out / "generated" / f"{cal.robot_.name}_calibration.h"}
    result["files"] = {k: str(v) for k, v in files.items()}
    result["assessment"] = (assessment := _assessment(args, sel, result)).to_dict()
    result["warnings"] = warning_lines(caught)
    written = report.write(report.content.calibrate(result, choice, calib, sel.data, sel.val_data, register_val,
                                                    assessment), build)
    result["files"].update({k: str(out / Path(v).relative_to(build)) for k, v in written.items()})
    if cm.c_pending:  # the delivered model's C, for the next command that compensates, beside any other build
        build_in_background(cm.robot, cm.model, cm.key, alongside=True)
    return result


def _assessment(args, sel, result):
    """The verdict and next step (`report.verdict.assess`) from the result, with this run's files."""
    from shlex import quote

    from gecgen.report.verdict import Noise, assess

    sig = result["significance"]
    held = f"--val {quote(args.val)}" if args.val else f"--holdout {args.holdout:g}" if args.holdout is not None else ""
    commands = next_commands(args.robot, args.train, held, result["files"]["calibration"], sel.data.n_poses,
                             sel.data.relative is not None, f"--noise-mm {args.noise_mm:g}" if args.noise_mm else "")
    val = sel.val is not None
    return assess(after=result["val"] if val else result["train"], before=result["val_before" if val else "before"],
                  held_out=val, n_poses=sel.val_data.n_poses if val else sel.data.n_poses,
                  tolerance_mm=args.tolerance_mm, noise=Noise.of_significance(sig),
                  held=None if sig.get("insignificant_carried") else (len(sig["held"]), result["n_identifiable"]),
                  n_train_poses=sel.data.n_poses, extrapolation=sel.val_extrapolation if val else {},
                  inside=result.get("val_inside"), relative=sel.data.relative is not None, commands=commands)
