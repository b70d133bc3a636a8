"""What several commands share: the robot and its error model, fit options, progress."""
from __future__ import annotations

import argparse
import math
import sys
import warnings
from contextlib import contextmanager


#: the positionals most commands share
ROBOT_HELP = "robot file (robots/NAME.yaml: DH rows or a URDF, targets; docs/reference.md, \"Files\")"
DATA_HELP = ("measurement CSV (pose, q1..qn, target, x y z[, wrench, station, orientation, aux]; docs/reference.md, "
             "\"Files\")")
CALIBRATION_HELP = "calibration JSON written by gecgen identify or calibrate"


def robot_and_model(robot_path: str, errors: str | None, aux_columns: tuple[str, ...] = ()):
    """The robot, and its error model: --errors, else robots/NAME.errors.yaml beside the robot file."""
    from gecgen.fit.inputs import error_model
    # here, not at the top: the robot file's reader loads numpy, which a command's --help does not need
    from gecgen.model import load_robot

    robot = load_robot(robot_path)
    return robot, error_model(errors, robot, aux_columns)


def not_from_pixels(report: dict, where: str, command: str):
    """Refuse, in one line, a calibration from image points (its report's `measurement`) given with tracker
    data to a command that also reads images (`--cameras`)."""
    from gecgen.model.validation import require

    require(report.get("measurement") != "pixels",
            f"{where}: a calibration from image points; {command} takes a calibration from tracker points with "
            f"tracker data, or this one with images: gecgen {command} {where} ... PIXELS.csv --cameras CAMERAS.yaml")


def progress_status(enabled: bool):
    """Where long steps say how far they are (`status.update(text)`): a rich status line on stderr
    when stderr is a terminal, which is cleared when the block ends; None (say nothing) when it is
    not (a file, a pipe, a CI log: stderr then holds only warnings and the one-line reason of a
    failure) and under --json."""
    from contextlib import nullcontext

    if not (enabled and sys.stderr.isatty()):
        return nullcontext(None)
    from rich.console import Console

    return Console(stderr=True).status("working")


def say(status, text: str):
    """`status.update(text)` when there is a status line (`progress_status`), shown at once: a new
    spinner makes rich redraw now, where the text alone waits for its next refresh, which a short
    step may never see."""
    if status is not None:
        status.update(text, spinner="dots")


#: the most poses a command draws or designs: far beyond any measurement campaign, far below memory
MAX_POSES = 10_000_000
#: numpy's generators take seeds up to 2**128; gecgen's files and reports print them as 64-bit integers
MAX_SEED = 2 ** 63 - 1


def whole(low: int, high: int):
    """An argparse type: an integer in low..high; anything else is the option's one-line refusal."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number; give one in {low}..{high}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{value} is outside {low}..{high}")
        return value
    return parse


def number(low: float = -math.inf, high: float = math.inf, above: bool = False):
    """An argparse type: a finite number in [low, high] (`above`: strictly above low)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        inside = (value > low if above else value >= low) and value <= high
        if not (math.isfinite(value) and inside):
            wanted = [f"{'above' if above else 'at least'} {low:g}"] if low > -math.inf else []
            wanted += [f"at most {high:g}"] if high < math.inf else []
            raise argparse.ArgumentTypeError(" ".join([f"{text!r}: give a finite number", " and ".join(wanted)]).strip())
        return value
    return parse


def numbers(low: float = -math.inf):
    """An argparse type: comma-separated finite numbers, each at least `low`."""
    one = number(low)

    def parse(text: str) -> list[float]:
        return [one(part.strip()) for part in str(text).split(",")]
    return parse


def add_orientation_length(p, calibration_first: bool = False):
    """The option that weighs measured orientations against positions (docs/reference.md, "Pose measurements");
    `calibration_first`: unset, it is the length the calibration was fitted with."""
    from gecgen.model.robot import LENGTH_M

    default = f"the calibration's, else {LENGTH_M:g}" if calibration_first else f"{LENGTH_M:g}"
    p.add_argument("--orientation-length", type=number(0, above=True), metavar="L",
                   help=f"for data with orientation columns: an orientation error of 1 mrad counts as L * 1 mrad of "
                        f"position error (m; default {default}); set L = position noise / orientation noise")


def add_noise(p):
    p.add_argument("--noise-mm", type=number(0, 1000, above=True),
                   help="the instrument's noise per coordinate, mm (1 sigma): the fit's residual is judged against it "
                        "(significance.overall in the JSON), with a warning when the model leaves more")


def add_keep_insignificant(p):
    p.add_argument("--keep-insignificant", action="store_true",
                   help="carry every identifiable coefficient into the calibration; by default those the data do not "
                        "determine (|value| / std < 2 after backward elimination) are held at zero and the rest "
                        "refitted")


def fit_options(args) -> dict:
    """--ridge and --rank-tol as the API takes them (a number, auto or None), refused in one line
    naming the option."""
    from gecgen.api import fit_option

    return {name: fit_option(getattr(args, name), name, "--" + name.replace("_", "-"))
            for name in ("ridge", "rank_tol")}


@contextmanager
def warned():
    """Record the block's warnings (the list it yields: `human.warning_lines(it)` is what the terminal will
    print) and pass them on when it ends, so a report carries the warnings the terminal shows."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def add_tolerance(p):
    p.add_argument("--tolerance-mm", type=number(0, 1000, above=True),
                   help="the accuracy the robot must reach, mm (point error): the report's verdict says whether the "
                        "held-out poses meet it, do not, or cannot tell")


def next_commands(robot: str, train: str, held: str, calibration: str, n_train: int | None, relative: bool,
                  noise: str):
    """The commands a report's next step names (`report.verdict.Commands`), with the run's own files:
    held the option that names held-out data (`--val V.csv`, `--holdout 0.2`, or empty), n_train the
    training poses (as many more are designed; None: not known, N), noise the option stating the
    instrument's noise as given (empty: the option to give)."""
    from shlex import quote

    from gecgen.report.verdict import Commands

    n_train = "N" if n_train is None else n_train

    more = (f"gecgen design {quote(robot)} --fixtures FIXTURES.csv --poses {n_train} -o more.csv" if relative else
            f"gecgen design {quote(robot)} --given {quote(train)} --poses {n_train} -o more.csv")
    return Commands(diagnose=" ".join(filter(None, ["gecgen diagnose", quote(robot), quote(train), held, noise])),
                    more_poses=more, score=f"gecgen evaluate {quote(calibration)} NEW.csv --report REPORT_DIR",
                    export=f"gecgen export {quote(calibration)} --c CONTROLLER_DIR", noise=noise or "--noise-mm S")
