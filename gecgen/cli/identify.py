"""`gecgen identify ROBOT DATA [-o CALIB.json]`: fit the error model to measured data, write a calibration."""
from __future__ import annotations


from gecgen.cli.common import (ROBOT_HELP, add_keep_insignificant, add_noise, add_orientation_length, add_tolerance,
                               fit_options, next_commands, progress_status, warned)
from gecgen.cli import pixels
from gecgen.cli.human import warning_lines
from gecgen.cli.register import add_register


def add_parser(command):
    """Register `identify` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("identify", run)
    p.add_argument("robot", help=ROBOT_HELP)
    p.add_argument("data", help="measurement CSV: pose, q1..qn, target, x, y, z (m) and optional columns "
                                "(docs/reference.md, \"Files\")")
    p.add_argument("--errors", help="error-model file (default: robots/NAME.errors.yaml)")
    p.add_argument("-o", "--output", help="calibration JSON (default: NAME.calib.json)")
    add_register(p, ("auto", "always", "never"), bare="always", default="auto",
                 lead="registration of DATA's measurement frame onto the robot world first: auto (when over 1 "
                      "degree or 20 mm apart), always, or never (DATA is in the robot's world frame)")
    p.add_argument("--ridge", default="0", help="ridge prior on the column-scaled coefficients: a number, or auto "
                                               "(5-fold cross-validation on DATA); default 0, plain least squares")
    p.add_argument("--loss", choices=["cauchy", "huber", "l2"], default="cauchy",
                   help="robust loss on each point's residual (default cauchy): points beyond the outlier limit are "
                        "down-weighted and listed; l2 is plain least squares")
    p.add_argument("--rank-tol",
                   help="numerical rank tolerance on DATA: coefficients whose normalised column keeps less than this "
                        "outside the better-excited ones are held at zero; a number, or auto (5-fold cross-validation "
                        "on DATA); default: exact dependencies only (1e-7)")
    add_orientation_length(p)
    add_keep_insignificant(p)
    add_noise(p)
    add_tolerance(p)
    p.add_argument("--report", metavar="DIR",
                   help="folder for report.md (PNG plots beside it) and report.html (self-contained)")
    pixels.add_options(p)


def run(args) -> dict:
    if args.cameras or args.board or args.refine_intrinsics:
        return pixels.identified(args)
    with warned() as caught:
        return _identified(args, caught)


def _identified(args, caught: list) -> dict:
    """The calibration, its result and report; caught: the warnings said on the way (`warned`)."""
    from gecgen.api import Calibrator
    from gecgen.report.verdict import Noise, assess

    cal = Calibrator(args.errors, loss=args.loss, register=args.register, orientation_length=args.orientation_length,
                     keep_insignificant=args.keep_insignificant, noise_mm=args.noise_mm, **fit_options(args))
    with progress_status(not args.json) as status:
        def progress(it, rms_mm):
            if status:
                status.update(f"Gauss-Newton iteration {it}: linearised residual {rms_mm:.4f} mm rms")

        cal.fit(args.robot, args.data, progress=progress)  # an untrustworthy fit raises: nothing is written
    out = cal.save(args.output or f"{cal.robot_.name}.calib.json")
    fit = cal.fit_
    result = {"robot": cal.robot_.name, "data": str(args.data), "calibration": str(out),
              "error_model": cal.calibration_.model.source, **cal.counts_, **cal.report_,
              "registration": fit.registration.to_dict(),
              "registrations": {str(k): r.to_dict() for k, r in fit.registrations.items()}}
    sig, relative = cal.report_["significance"], cal.data_.relative is not None
    assessment = assess(after=cal.report_["train"], before=cal.report_["before"], held_out=False,
                        n_poses=cal.counts_["n_poses"], tolerance_mm=args.tolerance_mm,
                        noise=Noise.of_significance(sig) or _repeated_noise(cal),
                        n_train_poses=cal.counts_["n_poses"],
                        held=None if sig.get("insignificant_carried") else
                        (len(sig["held"]), cal.report_["n_identifiable"]),
                        extrapolation={}, inside=None, relative=relative, weak=cal.report_.get("held"),
                        commands=next_commands(args.robot, args.data, "", str(out), cal.counts_["n_poses"], relative,
                                               f"--noise-mm {args.noise_mm:g}" if args.noise_mm else ""))
    result["assessment"], result["warnings"] = assessment.to_dict(), warning_lines(caught)
    if args.report:
        from gecgen import report

        result.update(report.write(report.content.identify(cal.robot_, cal.cm_, cal.data_, fit, cal.calibration_,
                                                           str(out), args.register, assessment, result["warnings"]),
                                   args.report))
    result["next"] = (f"gecgen evaluate {out} VAL.csv (new poses), gecgen diagnose {args.robot} {args.data} "
                      f"(what the model lacks), gecgen export {out} --c DIR (the controller's code)")
    return result


def _repeated_noise(cal):
    """Without a stated noise, the fit's residual against the noise pooled over the data's repeated
    poses (`fit.significance.noise_floor`, as diagnose judges it), or None when nothing repeats."""
    from gecgen.fit.significance import noise_floor, noise_test
    from gecgen.report.verdict import Noise

    floor = noise_floor(cal.data_, robot=cal.robot_)
    if floor is None:
        return None
    fit = cal.fit_
    covered, _, _ = noise_test(fit.sigma_m, max(fit.measured_dof - len(fit.redundancy.kept), 1), floor)
    return Noise(1e3 * fit.sigma_m, floor["noise_mm"], not covered, floor["source"])
