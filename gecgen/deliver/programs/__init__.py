"""Robot programs corrected through a calibration, for controllers that take neither generated C nor a
URDF: KUKA KRL, ABB RAPID, FANUC TP (ASCII .ls) and UR script, one module each over a shared core."""
from __future__ import annotations

import importlib
import warnings
from pathlib import Path

from gecgen.deliver.programs.core import Format, Outcome, correct, read_frames, require_six_axis_arm, \
    write_program
from gecgen.model.validation import ModelError

#: format name -> (its module, the file suffixes it reads)
FORMATS = {"krl": ("kuka", (".src",)), "rapid": ("abb", (".mod", ".modx", ".prg")), "tp": ("fanuc", (".ls",)),
           "ur": ("ur", (".script", ".urscript"))}


def program_format(path: str | Path, name: str | None = None) -> Format:
    """The format named, or the one the program's suffix says; a one-line refusal otherwise."""
    if name is None:
        suffix = Path(path).suffix.lower()
        name = next((k for k, (_, suffixes) in FORMATS.items() if suffix in suffixes), None)
        if name is None:
            known = ", ".join(f"{s} ({k})" for k, (_, suffixes) in FORMATS.items() for s in suffixes)
            raise ModelError(f"{path}: no program format reads {suffix or 'a file without suffix'}; give one of "
                             f"{known}, or name the format with --format")
    if name not in FORMATS:
        raise ModelError(f"--format {name}: unknown; give one of {', '.join(FORMATS)}")
    return importlib.import_module(f"gecgen.deliver.programs.{FORMATS[name][0]}").FORMAT


def require_controller(robot, fmt: Format, program: str | Path) -> None:
    """A one-line refusal of a program written for another controller than the one the robot file
    names; a warning when it names none (the program's format is then all gecgen knows)."""
    source = Path(robot.source).name if robot.source else "its robot file"
    if not robot.controller:
        warnings.warn(f"robot {robot.name}: {source} names no controller, so nothing checks that this "
                      f"{fmt.label} program was written for it; add 'controller: {fmt.controller}' to {source} if it "
                      f"runs on it (then identify again: a calibration holds to its robot file as it was)",
                      stacklevel=4)
    elif robot.controller != fmt.controller:
        raise ModelError(f"{program}: a {fmt.label} program, and the calibration is of robot {robot.name}, whose "
                         f"{source} names controller {robot.controller}; filter it with a calibration of the robot "
                         f"that runs it")


def filter_program(cal, program: str | Path, output: str | Path | None, frames: str | Path | None = None,
                   format: str | None = None, max_iter: int = 50) -> tuple[Outcome, dict[Path, Path], Path | None]:
    """Read `program`, correct its targets through the fitted Calibrator `cal`, and write the corrected
    program to `output` (KRL: its .dat beside it) with the change log beside it (OUTPUT.log.csv): the
    outcome of every target, where each file went, and the log's path ({} and None when `output` is
    None: nothing is written)."""
    require_six_axis_arm(cal.robot_)
    fmt = program_format(program, format)
    require_controller(cal.robot_, fmt, program)
    parsed = fmt.parse(Path(program))
    outcome = correct(fmt, parsed, cal, read_frames(frames, fmt), max_iter=max_iter)
    if output is None:
        return outcome, {}, None
    return (outcome, *write_program(fmt, parsed, outcome, Path(output)))
