"""`gecgen diagnose ROBOT DATA [--val VAL]`: trace the residual to missing effects, add them, refit, report;
`--cameras FILE [--board FILE]`: DATA is a pixel file (`cli.pixels.diagnosed`)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from gecgen.cli.common import (MAX_SEED, DATA_HELP, ROBOT_HELP, add_orientation_length, add_tolerance, next_commands,
                               number, progress_status, warned, whole)
from gecgen.cli import pixels
from gecgen.cli.human import warning_lines
from gecgen.cli.register import REGISTER, add_register
from gecgen.model import ModelError


def add_parser(command):
    """Register `diagnose` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("diagnose", run)
    p.add_argument("robot", help=ROBOT_HELP)
    p.add_argument("data", help=DATA_HELP)
    p.add_argument("--errors", help="declared error-model file (default: robots/NAME.errors.yaml)")
    held = p.add_mutually_exclusive_group()
    held.add_argument("--val", help="held-out measurement CSV, for reporting only (never used to choose terms)")
    held.add_argument("--holdout", type=float, help="share of DATA's poses to hold out for the report instead, split "
                                                    "by pose (seeded by --seed); default without --val: 0.2")
    p.add_argument("--seed", type=whole(0, MAX_SEED), default=0,
                   help="seed of the hold-out split and of the cross-validation folds (default %(default)s)")
    p.add_argument("-o", "--output", help="new error-model file (default: NAME.diagnosed.errors.yaml)")
    p.add_argument("--generated", help="folder for the regenerated code (default: beside the new error model)")
    p.add_argument("--report", metavar="DIR",
                   help="folder for report.md (PNG plots beside it) and report.html (self-contained)")
    add_register(p, REGISTER, bare="val", default="auto",
                 lead="registration of DATA onto the nominal model: auto (when far apart), always or never; val: "
                      "auto, and each round's model also re-fits the tracker frame of --val, measured from another "
                      "stationing, before scoring it")
    p.add_argument("--max-rounds", type=whole(1, 10_000), default=50,
                   help="rounds at most (default 50); diagnose stops earlier when nothing passes the statistics")
    p.add_argument("--noise-mm", type=number(0, above=True),
                   help="measurement noise per coordinate (mm), to say whether what remains is only noise (default: "
                        "from repeated poses, if any)")
    add_orientation_length(p)
    add_tolerance(p)
    pixels.add_options(p)


#: the report's stages -> their keys in the JSON's per-branch figures: before and after as diagnose's own
STAGES = {"uncalibrated": "uncalibrated", "calibrated (declared model)": "before", "diagnosed": "after"}


def run(args) -> dict:
    if args.cameras or args.board or args.refine_intrinsics:
        return pixels.diagnosed(args)
    with warned() as caught:
        return _diagnosed(args, caught)


def _diagnosed(args, caught: list) -> dict:
    """The diagnosis, its files, result and report; caught: the warnings said on the way (`warned`)."""
    from shlex import quote

    from gecgen.api import Diagnoser
    from gecgen.report.verdict import Noise, assess
    from gecgen.emit import generate
    from gecgen.runtime.compiled import printed_code

    register_val = args.register == "val"
    if register_val and not args.val:
        raise ModelError("diagnose --register re-fits the tracker frame of the validation file; give it with --val VAL")
    diagnoser = Diagnoser(args.errors, register="auto" if register_val else args.register, register_val=register_val,
                          max_rounds=args.max_rounds, noise_mm=args.noise_mm, seed=args.seed, holdout=args.holdout,
                          orientation_length=args.orientation_length)
    with progress_status(not args.json) as status:
        def progress(round_no, rms_mm):
            if status:
                status.update(f"diagnose round {round_no}: training RMS {rms_mm:.4f} mm; screening candidates")

        diagnoser.fit(args.robot, args.data, args.val, progress=progress)
    diag, robot, placement = diagnoser.diagnosis_, diagnoser.robot_, diagnoser.placement_
    out = diagnoser.save(args.output or f"{robot.name}.diagnosed.errors.yaml")
    generated = Path(args.generated or out.with_suffix("").with_suffix("").as_posix() + "_generated")
    generate(robot, diag.final.model, generated, printed_code(robot, diag.final.model, diag.final.cm.key))
    result = {"robot": robot.name, "error_model": diag.initial.model.source, "before": diag.before, "after": diag.after,
              "effects": [e.to_dict() for e in diag.effects], "errors_out": str(out), "generated": str(generated),
              "rounds": diag.history, "candidates_tested": diag.candidates_tested, "remaining": diag.remaining,
              "verdict": diagnoser.verdict_,
              "validation": str(args.val) if args.val else f"--holdout {args.holdout:g} of DATA (seed {args.seed})"
              if args.holdout is not None else "internal hold-out of 1/5 of the poses",
              "val_registered": register_val, "placement": placement.to_dict() if placement else None}
    if robot.branches:  # a tree: each hand's figures, as the report's table and calibrate's val_branches
        from gecgen.report.content import branch_figures, diagnosed_sets

        figures = branch_figures(robot, diagnosed_sets(diag, diagnoser.data_, diagnoser.val_, register_val,
                                                       "auto" if register_val else args.register))
        for key, name in (("train_branches", "training"), ("val_branches", "validation")):
            if figures and name in figures:
                result[key] = {b: {STAGES[stage]: v for stage, v in by.items()} for b, by in figures[name].items()}
    # what to run with the new model: fit it on all the data (diagnose's own fit held part out)
    calib = Path(out).with_name(f"{robot.name}.calib.json")  # beside the error model, not in the working folder
    # with the stated noise: identify holds against it what the data determine too weakly, as diagnose's fits did
    noise = f"--noise-mm {args.noise_mm:g}" if args.noise_mm else ""
    result["next"] = f"gecgen identify {args.robot} {args.data} --errors {out} -o {calib}" + (f" {noise}" if noise else "")
    val, relative = diagnoser.val_, diagnoser.data_.relative is not None
    held = f"--val {quote(args.val)}" if args.val else f"--holdout {args.holdout:g}" if args.holdout is not None else ""
    commands = next_commands(args.robot, args.data, held, str(calib), diagnoser.data_.n_poses, relative, noise)
    # diagnose has looked for what the model misses: the new model's fit on all the data shows the rest;
    # that fit writes the calibration the other commands read, so they come after it
    fit = result["next"]
    commands = replace(commands, diagnose=f"{fit} --report REPORT_DIR", export=f"{fit} && {commands.export}",
                       score=f"{fit} && {commands.score}")
    assessment = assess(after={"rms_mm": diag.after["val_rms_mm"], "max_mm": diag.after["val_max_mm"]},
                        before={"rms_mm": diag.before["val_rms_mm"]}, before_name="the declared model",
                        held_out=True, n_poses=None if val is None else val.n_poses, tolerance_mm=args.tolerance_mm,
                        noise=Noise.of_remaining(diag.remaining), held=None, n_train_poses=diagnoser.data_.n_poses,
                        extrapolation={}, inside=None, relative=relative, commands=commands)
    result["assessment"], result["warnings"] = assessment.to_dict(), warning_lines(caught)
    if args.report:
        from gecgen import report

        content = report.content.diagnose(diag, diagnoser.data_, diagnoser.val_, str(out), register_val,
                                          "auto" if register_val else args.register, assessment, result["warnings"])
        result.update(report.write(content, args.report))
    return result
