"""What a fit works on, shared by the Python API and the command line: the error model, the
targets the data places, pose data as points, and the compiled model checked against the data."""
from __future__ import annotations

import warnings
from pathlib import Path

from gecgen.model import ErrorModel, Robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.checks import check_terms_finite
from gecgen.model.measurements import Measurements
from gecgen.runtime.compiled import CompiledModel


def error_model(errors, robot: Robot, aux: tuple[str, ...] = (), constant: bool = True) -> ErrorModel | None:
    """The error model: an ErrorModel as given, a file's, or (None) robots/NAME.errors.yaml beside
    the robot file when there is one, else six constant errors per frame (`constant`) or None.
    `aux` are the data's auxiliary columns, usable as variables."""
    if isinstance(errors, ErrorModel):
        return errors
    if errors is None and robot.source:
        default = Path(robot.source).with_name(f"{robot.name}.errors.yaml")
        errors = default if default.is_file() else None
    return load_error_model(errors, robot, aux) if errors is not None or constant else None


def placed(robot: Robot, data: Measurements):
    """The robot with the targets the data must place placed (fit.placement), and the placement
    or None; a warning says which targets moved and how far, and which the data would move further
    than they support (held where the robot file puts them)."""
    from gecgen.fit.placement import FAR_M, FAR_RAD, place_targets

    robot, placement = place_targets(robot, data)
    if placement:
        moves = ", ".join([f"{n} estimated" if d is None else f"{n} {d:.0f} mm from the robot file's"
                           for n, d in placement.moved_mm.items()
                           if (d is None or d > 1e3 * FAR_M) and n not in placement.held]
                          + [f"{n}'s measured frame turned {a:.0f} mrad from the tool frame"
                             for n, a in placement.turned_mrad.items() if a > 1e3 * FAR_RAD])
        if moves:
            warnings.warn(f"targets placed from the data before the fit: {moves} (nominal model residual "
                          f"{placement.rms_mm:.2f} mm rms with them)")
        for name, why in placement.held.items():
            warnings.warn(f"target {name} held where the robot file puts it: {why}")
    return robot, placement


def on_points(robot: Robot, length_m: float | None, *datasets):
    """The robot and data a fit works on: when any data set measures orientations, the robot with
    the virtual targets of pose measurements (length scale L, default `pose_targets.LENGTH_M`) and
    every data set's oriented rows as their vertex points; otherwise all as given."""
    from gecgen.model.pose_targets import LENGTH_M, as_points, with_pose_targets

    if all(d is None or d.orientation is None for d in datasets):
        return (robot, *datasets)
    derived = with_pose_targets(robot, LENGTH_M if length_m is None else length_m)
    return (derived, *(None if d is None else as_points(derived, d) for d in datasets))


def measured_counts(data: Measurements) -> dict:
    """{n_poses, n_points} of data (a measured frame's vertices are one measured point),
    n_orientations, the rows that measure a frame, when there are any, and `relative`, what the
    rows of sockets and planes hold ({points, planes, distances, rows}), when there are any."""
    rows = data.rows
    oriented = int(rows.oriented.sum())
    return {"n_poses": data.n_poses, "n_points": len(rows.first), **({"n_orientations": oriented} if oriented else {}),
            **({"relative": data.relative.summary()} if data.relative is not None else {})}


def checked(model: ErrorModel, robot: Robot, *datas) -> CompiledModel:
    """The compiled model, after refusing (one line) a term that is not finite on any of `datas`
    (measurements or commands; None entries skipped)."""
    cm = CompiledModel(robot, model)
    for data in filter(None, datas):
        check_terms_finite(model, robot, data, cm)
    return cm
