"""The `gecgen` command line (CONTRACTS.md section 4).

Every command takes --json (one JSON object on stdout, nothing else there) and exits non-zero
with a one-line reason on stderr when it cannot do its job.
"""
from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

from gecgen.files import check_output_dir, check_output_file
from gecgen.model import ModelError, load_error_model, load_robot
from gecgen.model.checks import check_terms_finite


def robot_and_model(robot_path: str, errors: str | None, aux_columns: tuple[str, ...] = ()):
    """The robot, and its error model: --errors, else robots/NAME.errors.yaml beside the robot file."""
    robot = load_robot(robot_path)
    if errors is None:
        default = Path(robot_path).with_name(f"{robot.name}.errors.yaml")
        errors = str(default) if default.is_file() else None
    return robot, load_error_model(errors, robot, aux_columns)


def cmd_generate(args) -> dict:
    from gecgen.emit import generate

    robot, model = robot_and_model(args.robot, args.errors)
    outdir = Path(args.output or Path("generated") / robot.name)
    files = generate(robot, model, outdir)
    return {"robot": robot.name, "output": str(outdir), "files": sorted(files),
            "n_params": len(model.coefficients), "n_errors": robot.n_errors}


def _progress(enabled: bool):
    """A rich status line for long steps on a terminal; silent under --json or when piped."""
    from contextlib import nullcontext

    if not enabled or not sys.stderr.isatty():
        return nullcontext(None)
    from rich.console import Console

    return Console(stderr=True).status("working")


def _identify_inputs(args):
    from gecgen.model.measurements import read_measurements
    from gecgen.runtime.compiled import CompiledModel

    robot = load_robot(args.robot)
    data = read_measurements(args.data, robot)
    robot, model = robot_and_model(args.robot, args.errors, data.aux_names)
    check_terms_finite(model, robot, data)
    return robot, model, data, CompiledModel(robot, model)


def _fit_options(args, cm, data) -> tuple[dict, list]:
    """--ridge and --rank-tol: each a number, or auto; the auto ones are chosen together by 5-fold
    cross-validation on the training data. Returns the options for identify and the CV table."""
    import numpy as np

    from gecgen.runtime.identify import RANK_TOL_GRID, RIDGE_GRID, choose

    fixed, grids = {"loss": args.loss}, {}
    # rank_tol is a share of a normalised column: at 1 or above nothing would be kept
    for name, option, grid, upper in (("ridge", args.ridge, RIDGE_GRID, np.inf),
                                      ("rank_tol", args.rank_tol, RANK_TOL_GRID, 1.0)):
        if option is None:
            continue  # identify's default
        if option == "auto":
            grids[name] = grid
            continue
        try:
            fixed[name] = float(option)
        except ValueError:
            fixed[name] = np.nan
        if not 0 <= fixed[name] < upper:
            bound = "a non-negative number" if upper == np.inf else f"a number from 0 to below {upper:g}"
            raise ModelError(f"--{name.replace('_', '-')} {option!r}: give {bound}, or auto")
    if not grids:
        return fixed, []
    chosen, table = choose(cm, data, grids, **fixed)
    return {**fixed, **chosen}, table


def cmd_identify(args) -> dict:
    from gecgen.runtime import calibration
    from gecgen.runtime.identify import identify

    robot, model, data, cm = _identify_inputs(args)
    with _progress(not args.json) as status:
        def progress(it, rms_mm):
            if status:
                status.update(f"Gauss-Newton iteration {it}: linearised residual {rms_mm:.4f} mm rms")

        options, cv_table = _fit_options(args, cm, data)
        fit = identify(cm, data, registration_mode=args.register, progress=progress, **options)
    if fit.failures:
        raise RuntimeError(f"the fit is not trustworthy, no calibration written: {fit.failures[0]}")
    calib = calibration.from_fit(robot, model, fit)
    calib.report.update({**options, "cv": cv_table})
    out = Path(args.output or f"{robot.name}.calib.json")
    calibration.save(calib, out)
    result = {"robot": robot.name, "data": str(args.data), "calibration": str(out), "n_poses": data.n_poses,
              "n_points": len(data.xyz), **calib.report, "registration": fit.registration.to_dict(),
              "registrations": {str(k): r.to_dict() for k, r in fit.registrations.items()}}
    return result


def cmd_evaluate(args) -> dict:
    from gecgen.model.measurements import read_measurements
    from gecgen.runtime import calibration
    from gecgen.runtime.compiled import CompiledModel
    from gecgen.runtime.identify import fit_frames, position_errors, summary, to_world

    calib = calibration.load(args.calibration)
    data = read_measurements(args.data, calib.robot)
    check_terms_finite(calib.model, calib.robot, data)
    cm = CompiledModel(calib.robot, calib.model)
    outside = _extrapolation(calib, data.q, data.w, data.aux_columns(calib.model.aux))
    result = {"robot": calib.robot.name, "data": str(args.data), "n_poses": data.n_poses, "n_points": len(data.xyz),
              "registered": args.register}
    if args.register:
        # a new stationing: each side is scored in the frame that fits it best, so that before and
        # after differ by the calibration alone
        frames = fit_frames(cm, data, calib.c)
        y_before, y = to_world(fit_frames(cm, data, None), data), to_world(frames, data)
        known = calib.frames
        moved = {k: {**r.to_dict(), **r.relative_to(known.get(k, calib.registration))} for k, r in frames.items()}
        first = moved[min(moved)]
        result.update(before_registration="the nominal model's, fitted on DATA", registration=first,
                      registrations={str(k): v for k, v in moved.items()},
                      tracker_frame=f"re-fitted on DATA with the calibration held: {first['angle_deg']:.3f} deg and "
                                    f"{first['distance_mm']:.1f} mm from the calibration's")
    else:
        y = y_before = to_world(calib.frames, data, "the tracker was re-stationed: use evaluate --register")
        result.update(before_registration="the calibration's", tracker_frame="the calibration's")
    return {**result, "before": summary(position_errors(cm, data, y_before, None)),
            "after": summary(position_errors(cm, data, y, calib.c)), "extrapolation": outside}


def _extrapolation(calib, q, w, aux) -> dict:
    """Poses outside the training ranges per input; a warning line says so when there are any."""
    from gecgen.runtime import calibration

    counts = calibration.extrapolation(calib, q, w, aux)
    note = calibration.extrapolation_note(counts, len(q), calib.robot)
    if note:
        warnings.warn(note)
    return counts


def cmd_compensate(args) -> dict:
    import numpy as np

    from gecgen.model.measurements import read_commands, write_commands
    from gecgen.runtime import calibration
    from gecgen.runtime.compiled import FAILED, NONFINITE, OUTSIDE_LIMITS, CompiledModel

    if args.max_iter < 0:
        raise ModelError(f"--max-iter {args.max_iter}: give a non-negative number of Newton steps")
    calib = calibration.load(args.calibration)  # refuses non-finite coefficients, naming the first
    cmds = read_commands(args.poses, calib.robot, calib.model.aux)
    check_terms_finite(calib.model, calib.robot, cmds)
    cm = CompiledModel(calib.robot, calib.model)
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
            "extrapolation": _extrapolation(calib, cmds.q, cmds.w, cmds.aux),
            "max_correction": {name: float(np.abs(dq[:, j]).max()) for j, name in enumerate(calib.robot.joint_names)}}


def cmd_redundancy(args) -> dict:
    from gecgen.runtime.compiled import CompiledModel
    from gecgen.runtime.identify import redundancy

    data = None
    if args.data:
        from gecgen.model.measurements import read_measurements

        data = read_measurements(args.data, load_robot(args.robot))
    robot, model = robot_and_model(args.robot, args.errors, data.aux_names if data else ())
    if data:
        check_terms_finite(model, robot, data)
    result = redundancy(CompiledModel(robot, model), data).to_dict()
    return {"robot": robot.name, "data": args.data, **result}


def cmd_diagnose(args) -> dict:
    from gecgen.emit import generate
    from gecgen.loop.diagnose import diagnose, verdict, write_error_model
    from gecgen.model.measurements import read_measurements

    register_val = args.register == "val"
    if register_val and not args.val:
        raise ModelError("diagnose --register re-fits the tracker frame of the validation file; give it with --val VAL")
    robot = load_robot(args.robot)
    data = read_measurements(args.data, robot)
    val = read_measurements(args.val, robot) if args.val else None
    robot, model = robot_and_model(args.robot, args.errors, data.aux_names)
    for d in filter(None, (data, val)):
        check_terms_finite(model, robot, d)
    with _progress(not args.json) as status:
        def progress(round_no, rms_mm):
            if status:
                status.update(f"diagnose round {round_no}: training RMS {rms_mm:.4f} mm; screening candidates")

        diag = diagnose(robot, model, data, val, registration_mode="auto" if register_val else args.register,
                        progress=progress, noise_mm=args.noise_mm, max_rounds=args.max_rounds,
                        register_val=register_val)
    out = Path(args.output or f"{robot.name}.diagnosed.errors.yaml")
    write_error_model(robot, diag.final.model, diag.effects, out)
    generated = Path(args.generated or out.with_suffix("").with_suffix("").as_posix() + "_generated")
    generate(robot, diag.final.model, generated)
    result = {"robot": robot.name, "before": diag.before, "after": diag.after,
              "effects": [e.to_dict() for e in diag.effects], "errors_out": str(out), "generated": str(generated),
              "rounds": diag.history, "candidates_tested": diag.candidates_tested, "remaining": diag.remaining,
              "verdict": verdict(diag.remaining),
              "validation": str(args.val) if args.val else "internal hold-out of 1/5 of the poses",
              "val_registered": register_val}
    if args.report:
        from gecgen.loop.report import write_report

        result["report"] = str(write_report(diag, data, args.report, str(out)))
    return result


def _scalar(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


#: list entries a person sees one per line before the rest is left to --json
MAX_LISTED = 20


def _print_human(result: dict):
    """A short summary for a person; the full record (every list entry) is what --json prints."""
    for key, value in result.items():
        if key in ("identifiable", "training_ranges"):
            continue
        if key == "outliers":
            print(f"outliers: {len(value)}" + (" (file row, pose, target, residual)" if value else ""))
            for o in value[:MAX_LISTED]:
                print(f"  row {o['row']}: pose {o['pose']} {o['target']} {o['residual_mm']:.3f} mm")
            if len(value) > MAX_LISTED:
                print(f"  ... {len(value) - MAX_LISTED} more (use --json for the list)")
        elif key == "effects":
            print(f"effects: {len(value)}")
            for e in value:
                print(f"  {e['error']}: {', '.join(e['terms'])} ({e['family']}; cross-validated gain "
                      f"{e['gain_mm']:.4f} mm)")
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            print(f"{key}: {len(value)} (use --json for the list)")
        elif isinstance(value, dict):
            scalars = {k: v for k, v in value.items() if not isinstance(v, (dict, list))}
            if not scalars:
                print(f"{key}: {len(value)} (use --json for them)")
                continue
            more = " (more with --json)" if len(scalars) < len(value) else ""
            print(f"{key}: " + ", ".join(f"{k} {_scalar(v)}" for k, v in scalars.items()) + more)
        else:
            print(f"{key}: {_scalar(value)}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gecgen", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    def command(name, fn, help_text):
        p = sub.add_parser(name, help=help_text)
        p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        p.set_defaults(fn=fn)
        return p

    p = command("generate", cmd_generate, "write C, CasADi and a manifest for a robot and error model")
    p.add_argument("robot")
    p.add_argument("--errors", help="error-model file (default: robots/NAME.errors.yaml)")
    p.add_argument("-o", "--output", help="output folder (default: generated/NAME)")

    p = command("identify", cmd_identify, "fit the error model to measured data and write a calibration")
    p.add_argument("robot")
    p.add_argument("data", help="measurement CSV (CONTRACTS.md section 3)")
    p.add_argument("--errors", help="error-model file (default: robots/NAME.errors.yaml)")
    p.add_argument("-o", "--output", help="calibration JSON (default: NAME.calib.json)")
    p.add_argument("--register", choices=["auto", "always", "never"], default="auto",
                   help="register the measurement frame onto the robot world first (auto: when far apart)")
    p.add_argument("--ridge", default="0", help="ridge prior on the column-scaled coefficients: a number, or auto "
                                               "(5-fold cross-validation on DATA); default 0, plain least squares")
    p.add_argument("--loss", choices=["cauchy", "huber", "l2"], default="cauchy",
                   help="robust loss on each point's residual (default cauchy): points beyond the outlier limit are "
                        "down-weighted and listed; l2 is plain least squares")
    p.add_argument("--rank-tol",
                   help="numerical rank tolerance on DATA: coefficients whose normalised column keeps less than this "
                        "outside the better-excited ones are held at zero; a number, or auto (5-fold cross-validation "
                        "on DATA); default: exact dependencies only (1e-7)")

    p = command("evaluate", cmd_evaluate, "position errors of new data before and after the calibration")
    p.add_argument("calibration")
    p.add_argument("data")
    p.add_argument("--register", action="store_true",
                   help="DATA was measured from a new tracker stationing: fit only the tracker frame on it (the "
                        "calibration's coefficients held), and score the uncalibrated model in its own fitted frame")

    p = command("compensate", cmd_compensate, "corrected joint commands for nominal commands")
    p.add_argument("calibration")
    p.add_argument("poses", help="CSV with q1..qn (and optionally fx..mz and aux columns)")
    p.add_argument("-o", "--output", required=True)
    p.add_argument("--max-iter", type=int, default=50)

    p = command("redundancy", cmd_redundancy, "which coefficients are eliminated and what they merge into")
    p.add_argument("robot")
    p.add_argument("data", nargs="?", help="measurement CSV: also report what it leaves unexcited")
    p.add_argument("--errors", help="error-model file (default: robots/NAME.errors.yaml)")

    from gecgen.simulate.cli import add_parser as add_simulate

    add_simulate(command)
    from gecgen.model.wide_cli import add_parser as add_import

    add_import(command)
    from gecgen.model.gravity_cli import add_parser as add_gravity

    add_gravity(command)
    from gecgen.runtime.design_cli import add_parser as add_design

    add_design(command)

    p = command("diagnose", cmd_diagnose, "trace the residual to missing effects, add them, refit, report")
    p.add_argument("robot")
    p.add_argument("data")
    p.add_argument("--errors", help="declared error-model file (default: robots/NAME.errors.yaml)")
    p.add_argument("--val", help="held-out measurement CSV, for reporting only (never used to choose terms)")
    p.add_argument("-o", "--output", help="new error-model file (default: NAME.diagnosed.errors.yaml)")
    p.add_argument("--generated", help="folder for the regenerated code (default: beside the new error model)")
    p.add_argument("--report", help="folder for report.md and its plots")
    p.add_argument("--register", nargs="?", const="val", choices=["auto", "always", "never", "val"], default="auto",
                   help="registration of DATA onto the nominal model: auto (when far apart), always or never; "
                        "--register alone (or val): auto, and each round's model also re-fits the tracker frame of "
                        "the --val file, measured from another stationing, before scoring it")
    p.add_argument("--max-rounds", type=int, default=50,
                   help="rounds at most (default 50); diagnose stops earlier when nothing passes the statistics")
    p.add_argument("--noise-mm", type=float, help="measurement noise per coordinate (mm), to say whether what "
                                                   "remains is only noise (default: from repeated poses, if any)")
    return parser


#: per command, the options naming what it writes: option -> (what, is a folder)
OUTPUTS = {
    "generate": {"output": ("generated code", True)},
    "identify": {"output": ("calibration", False)},
    "compensate": {"output": ("corrected commands", False)},
    "diagnose": {"output": ("error model", False), "generated": ("generated code", True), "report": ("report", True)},
    "simulate": {"output": ("measurements", False), "val_out": ("validation measurements", False),
                 "truth_out": ("truth file", False)},
    "import": {"output": ("measurements", False)},
    "gravity": {"output": ("table", False)},
    "design": {"output": ("poses", False)},
}


def check_outputs(args):
    """One-line refusal of an output that names a folder where a file is meant, a file where a
    folder is meant, or a place that cannot be written: before the work, not after it."""
    for option, (what, folder) in OUTPUTS.get(args.command, {}).items():
        path = getattr(args, option, None)
        if path is None:
            continue  # not written, or a default in the working folder
        if folder:
            check_output_dir(path, what)
        else:
            check_output_file(path, what)


def _os_reason(exc: OSError) -> str:
    """`path: reason` of an OSError, as one line."""
    reason = exc.strerror or str(exc)
    return (f"{exc.filename}: {reason}" if exc.filename else reason).splitlines()[0]


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # warnings become one line each after the result, and none when the command fails: the
    # failure's reason is then the one line on stderr
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code, result = _run(args)
    if code:
        return code
    for message in dict.fromkeys(str(w.message).splitlines()[0] for w in caught):
        print(f"gecgen {args.command}: warning: {message}", file=sys.stderr)
    if args.json:
        print(json.dumps(result, allow_nan=False))
    else:
        _print_human(result)
    return 0


def _run(args) -> tuple[int, dict | None]:
    """Run a parsed command: (0, its result), or (exit code, None) after one line on stderr."""
    try:
        check_outputs(args)
        return 0, args.fn(args)
    except ModelError as exc:
        print(f"gecgen {args.command}: {exc}", file=sys.stderr)
        return 2, None
    except OSError as exc:
        print(f"gecgen {args.command}: {_os_reason(exc)}", file=sys.stderr)
        return 2, None
    except RuntimeError as exc:
        print(f"gecgen {args.command}: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 1, None


if __name__ == "__main__":
    sys.exit(main())
