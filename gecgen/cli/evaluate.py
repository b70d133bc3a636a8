"""`gecgen evaluate CALIB DATA [--register]`: position errors of new data before and after the calibration."""
from __future__ import annotations

from gecgen.cli.common import add_orientation_length, checked, extrapolation, measured_counts, on_points


def add_parser(command):
    """Register `evaluate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("evaluate", run, "position errors of new data before and after the calibration")
    p.add_argument("calibration")
    p.add_argument("data")
    p.add_argument("--register", action="store_true",
                   help="DATA was measured from a new tracker stationing: fit only the tracker frame on it (the "
                        "calibration's coefficients held), and score the uncalibrated model in its own fitted frame")
    p.add_argument("--report", metavar="DIR",
                   help="folder for report.md (PNG plots beside it) and report.html (self-contained)")
    add_orientation_length(p, "the calibration's, else 0.1")


def run(args) -> dict:
    from gecgen.model.measurements import read_measurements
    from gecgen.runtime import calibration
    from gecgen.runtime.identify import fit_frames, row_errors, summary, to_world

    calib = calibration.load(args.calibration)
    data = read_measurements(args.data, calib.robot)
    length = args.orientation_length
    if length is None:  # the length scale the calibration was fitted with, if it measured frames
        length = calib.report.get("orientation_length_m")
    robot, data = on_points(calib.robot, length, data)
    cm = checked(calib.model, robot, data)
    outside = extrapolation(calib, data.q, data.w, data.aux_columns(calib.model.aux))
    result = {"robot": calib.robot.name, "data": str(args.data), **measured_counts(robot, data),
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
    result = {**result, "before": summary(*row_errors(cm, data, y_before, None)[:2]),
              "after": summary(*row_errors(cm, data, y, calib.c)[:2]), "extrapolation": outside}
    if args.report:
        from gecgen import report

        result.update(report.write(report.content.evaluate(calib, cm, data, y_before, y, outside, args.calibration),
                                   args.report))
    return result
