"""What several commands share: the robot and its error model, fit options, progress, extrapolation."""
from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

from gecgen.model import ModelError, load_error_model, load_robot
from gecgen.model.checks import check_terms_finite


def robot_and_model(robot_path: str, errors: str | None, aux_columns: tuple[str, ...] = ()):
    """The robot, and its error model: --errors, else robots/NAME.errors.yaml beside the robot file."""
    robot = load_robot(robot_path)
    if errors is None:
        default = Path(robot_path).with_name(f"{robot.name}.errors.yaml")
        errors = str(default) if default.is_file() else None
    return robot, load_error_model(errors, robot, aux_columns)


def progress_status(enabled: bool):
    """Where long steps say how far they are (`status.update(text)`): a rich status line on a
    terminal; log lines on stderr when stderr is a file or a pipe (a CI log, `2> log`), at most one
    every LOG_EVERY_S seconds; nothing under --json, whose stderr holds only warnings and the
    one-line reason of a failure."""
    from contextlib import nullcontext

    if not enabled:
        return nullcontext(None)
    if not sys.stderr.isatty():
        return nullcontext(_LogLines())
    from rich.console import Console

    return Console(stderr=True).status("working")


#: seconds between two progress log lines when stderr is not a terminal
LOG_EVERY_S = 2.0


class _LogLines:
    """status.update(text) as time-stamped lines on stderr, rate-limited."""

    def __init__(self):
        self.last = -math.inf

    def update(self, text: str):
        now = time.monotonic()
        if now - self.last >= LOG_EVERY_S:
            self.last = now
            print(f"{time.strftime('%H:%M:%S')} gecgen: {text}", file=sys.stderr, flush=True)


def add_orientation_length(p, default: str = "0.1"):
    """The option that weighs measured orientations against positions (README "Pose measurements")."""
    p.add_argument("--orientation-length", type=float, metavar="L",
                   help=f"for data with orientation columns: an orientation error of 1 mrad counts as L * 1 mrad of "
                        f"position error (m; default {default}); set L = position noise / orientation noise")


def on_points(robot, length_m: float | None, *datasets):
    """The robot and data a fit works on: when any data set measures orientations, the robot with
    the virtual targets of pose measurements (length scale L, default `pose_targets.LENGTH_M`) and
    every data set's oriented rows as their vertex points; otherwise all as given."""
    from gecgen.model.pose_targets import LENGTH_M, as_points, with_pose_targets

    if all(d is None or d.orientation is None for d in datasets):
        return (robot, *datasets)
    derived = with_pose_targets(robot, LENGTH_M if length_m is None else length_m)
    return (derived, *(None if d is None else as_points(derived, d) for d in datasets))


def measured_counts(robot, data) -> dict:
    """{n_poses, n_points} of data on `robot` (a frame's vertices are one measured point), and
    n_orientations, the rows that measure a frame, when there are any."""
    from gecgen.model.pose_targets import measured_rows

    rows = measured_rows(robot, data)
    oriented = int(rows.oriented.sum())
    return {"n_poses": data.n_poses, "n_points": len(rows.first), **({"n_orientations": oriented} if oriented else {})}


def identify_inputs(args):
    """(robot with its targets placed, error model, data, compiled model, placement or None). When
    the data measures orientations, the data is its vertex points and the compiled model that of
    the derived robot (`on_points`); the robot stays the file's, placed."""
    from gecgen.model.measurements import read_measurements

    robot = load_robot(args.robot)
    data = read_measurements(args.data, robot)
    robot, model = robot_and_model(args.robot, args.errors, data.aux_names)
    robot, placement = placed(robot, data)
    fitted, data = on_points(robot, args.orientation_length, data)
    return robot, model, data, checked(model, fitted, data), placement


def checked(model, robot, *datas):
    """The compiled model, after refusing (one line) a term that is not finite on any of `datas`
    (measurements or commands; None entries skipped)."""
    from gecgen.runtime.compiled import CompiledModel

    cm = CompiledModel(robot, model)
    for data in filter(None, datas):
        check_terms_finite(model, robot, data, cm.load_signals)
    return cm


def placed(robot, data):
    """The robot with the targets the data must place placed (runtime.placement), and the placement
    or None; a warning says which targets moved and how far."""
    from gecgen.runtime.placement import FAR_M, place_targets

    robot, placement = place_targets(robot, data)
    if placement:
        moves = ", ".join(f"{n} estimated" if d is None else f"{n} {d:.0f} mm from the robot file's"
                          for n, d in placement.moved_mm.items() if d is None or d > 1e3 * FAR_M)
        warnings.warn(f"targets placed from the data before the fit: {moves} (nominal model residual "
                      f"{placement.rms_mm:.2f} mm rms with them)")
    return robot, placement


def fit_options(args, cm, data) -> tuple[dict, list]:
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


def extrapolation(calib, q, w, aux) -> dict:
    """Poses outside the training ranges per input; a warning line says so when there are any."""
    from gecgen.runtime import calibration

    counts = calibration.extrapolation(calib, q, w, aux)
    note = calibration.extrapolation_note(counts, len(q), calib.robot)
    if note:
        warnings.warn(note)
    return counts
