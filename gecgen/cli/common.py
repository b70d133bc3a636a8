"""What several commands share: the robot and its error model, fit options, progress."""
from __future__ import annotations

import sys

from gecgen.model import load_robot


def robot_and_model(robot_path: str, errors: str | None, aux_columns: tuple[str, ...] = ()):
    """The robot, and its error model: --errors, else robots/NAME.errors.yaml beside the robot file."""
    from gecgen.api import error_model

    robot = load_robot(robot_path)
    return robot, error_model(errors, robot, aux_columns)


def progress_status(enabled: bool):
    """A rich status line for long steps on a terminal; silent under --json or when piped."""
    from contextlib import nullcontext

    if not enabled or not sys.stderr.isatty():
        return nullcontext(None)
    from rich.console import Console

    return Console(stderr=True).status("working")


def add_orientation_length(p, default: str = "0.1"):
    """The option that weighs measured orientations against positions (README "Pose measurements")."""
    p.add_argument("--orientation-length", type=float, metavar="L",
                   help=f"for data with orientation columns: an orientation error of 1 mrad counts as L * 1 mrad of "
                        f"position error (m; default {default}); set L = position noise / orientation noise")


def fit_options(args) -> dict:
    """--ridge and --rank-tol as the API takes them (a number, auto or None), refused in one line
    naming the option."""
    from gecgen.api import fit_option

    return {name: fit_option(getattr(args, name), name, "--" + name.replace("_", "-"))
            for name in ("ridge", "rank_tol")}
