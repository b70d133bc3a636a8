"""`gecgen calibrate ROBOT TRAIN [--val VAL | --holdout F] -o DIR`: the whole pipeline in one command.

The model is chosen on the training data alone (gecgen/loop/calibrate.py says the rule); DIR gets
the calibration, the chosen error model, its generated code and a report.
"""
from __future__ import annotations

from pathlib import Path

from gecgen.cli.common import add_orientation_length, checked, measured_counts, on_points, placed, progress_status
from gecgen.loop.calibrate import NAMES
from gecgen.model import load_error_model, load_robot
from gecgen.model.validation import require


def add_parser(command):
    """Register `calibrate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("calibrate", run, "choose a model on the training data, fit it, write calibration, code and report")
    p.add_argument("robot", help="robot file (robots/NAME.yaml)")
    p.add_argument("train", help="training measurement CSV: the model is chosen and fitted on it alone")
    held = p.add_mutually_exclusive_group()
    held.add_argument("--val", help="validation measurement CSV, scored after the choice (never used to choose)")
    held.add_argument("--holdout", type=float, help="share of TRAIN's poses to hold out for validation instead "
                                                    "(split by pose, seeded by --seed), e.g. 0.2")
    p.add_argument("--errors", help="the robot's default error model among the candidates (default: "
                                    "robots/NAME.errors.yaml beside the robot file, if any)")
    p.add_argument("--models", default=",".join(NAMES),
                   help="comma-separated candidates to choose among (default: %(default)s; those that do not apply "
                        "to the robot and data are skipped)")
    p.add_argument("--seed", type=int, default=0, help="seed of the cross-validation folds and of --holdout "
                                                       "(default %(default)s)")
    p.add_argument("-o", "--output", required=True, help="folder for calibration.json, errors.yaml, report.md, "
                                                         "report.html and generated/ (the C and CasADi code, "
                                                         "NAME_calibration.h with the coefficients, NAME_example.c)")
    add_orientation_length(p)


def _default_model(args, robot, aux):
    if args.errors:
        return load_error_model(args.errors, robot, aux)
    path = Path(args.robot).with_name(f"{robot.name}.errors.yaml")
    return load_error_model(path, robot, aux) if path.is_file() else None


def run(args) -> dict:
    from gecgen import report
    from gecgen.files import write_atomically
    from gecgen.loop.calibrate import choose
    from gecgen.loop.diagnose import write_error_model
    from gecgen.model.measurements import hold_out, read_measurements
    from gecgen.runtime import calibration, export
    from gecgen.runtime.identify import row_errors, summary, to_world

    names = tuple(n.strip() for n in args.models.split(","))
    unknown = [n for n in names if n not in NAMES]
    require(not unknown, f"--models: '{unknown[0] if unknown else ''}' is not a candidate; choose from {', '.join(NAMES)}")
    robot = load_robot(args.robot)
    data = read_measurements(args.train, robot)
    val = read_measurements(args.val, robot) if args.val else None
    if args.holdout is not None:
        data, val = hold_out(data, args.holdout, args.seed)
    robot, placement = placed(robot, data)
    default = _default_model(args, robot, data.aux_names)
    fitted, data, val = on_points(robot, args.orientation_length, data, val)
    if default is not None:
        checked(default, fitted, data, val)
    with progress_status(not args.json) as status:
        def progress(name):
            if status:
                status.update(f"cross-validating the {name} model on the training poses")

        choice = choose(fitted, data, default, args.seed, progress=progress, names=names)
    out = Path(args.output)
    calib = calibration.from_fit(robot, choice.model, choice.fit)
    calib.report.update({"model": choice.chosen.name, "candidates": choice.table,
                         "placement": placement.to_dict() if placement else None})
    if fitted.vertex_of:
        calib.report["orientation_length_m"] = fitted.pose_length
    calibration.save(calib, out / "calibration.json")
    effects = choice.diagnosis.effects if choice.diagnosis else []
    write_error_model(robot, choice.model, effects, out / "errors.yaml")
    # the code, the coefficient header and an example program: what `gecgen export --c` writes
    code, _ = export.c_files(calib, choice.cm, str(out / "calibration.json"))
    for name, text in code.items():
        write_atomically(out / "generated" / name, text)
    result = {"robot": robot.name, "train_data": str(args.train), "output": str(out), **measured_counts(fitted, data),
              "model": choice.chosen.name,
              "candidates": choice.table, "n_params": len(choice.model.coefficients),
              "n_identifiable": choice.fit.redundancy.n_identifiable, "before": choice.fit.before,
              "train": choice.fit.train, "outliers": [o.to_dict() for o in choice.fit.outliers],
              "effects": [e.to_dict() for e in effects], "placement": calib.report["placement"]}
    if val is not None:
        checked(choice.model, fitted, val)
        y = to_world(calib.frames, val, "measure it from a station of TRAIN, or score it with gecgen evaluate --register")
        result["validation"] = str(args.val) if args.val else f"--holdout {args.holdout:g} of TRAIN (seed {args.seed})"
        result["val_before"] = summary(*row_errors(choice.cm, val, y, None)[:2])
        result["val"] = summary(*row_errors(choice.cm, val, y, choice.fit.c)[:2])
    files = {"calibration": out / "calibration.json", "errors": out / "errors.yaml", "generated": out / "generated",
             "coefficient_header": out / "generated" / f"{robot.name}_calibration.h"}
    files.update(report.write(report.content.calibrate(result, choice, calib, data, val), out))
    result["files"] = {k: str(v) for k, v in files.items()}
    return result

