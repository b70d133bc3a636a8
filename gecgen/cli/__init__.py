"""The `gecgen` command line (CONTRACTS.md section 4): one module per command in this package.

Every command takes --json (one JSON object on stdout, nothing else there) and exits non-zero
with a one-line reason on stderr when it cannot do its job.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import re
import signal
import sys
import threading
import warnings
from pathlib import Path

from gecgen.version import __version__
from gecgen.cli.register import bare_register
from gecgen.cli.human import print_human, warning_lines
from gecgen.model.files import check_output_dir, check_output_file, reading, same_file
from gecgen.model import ModelError
from gecgen.model.validation import nearest, read_yaml
from gecgen.runtime.threads import command_threads

#: command -> (its module in this package, its line in `gecgen --help`), in the order of the work, as
#: listed there: plan the measurement, bring it in, fit, verify, deliver to the controller
COMMANDS = {
    "design": ("design", "choose the poses to measure (optimal experiment design)"),
    "simulate": ("simulate", "simulated measurements of a robot with physical error sources"),
    "redundancy": ("redundancy", "which coefficients are eliminated and what they merge into"),
    "import": ("import_", "convert a wide table (points side by side), or socket files, into a measurement CSV"),
    "gravity": ("gravity", "append the static gravity torques of joints (URDF masses) as aux columns"),
    "calibrate": ("calibrate", "choose a model on the training data, fit it, write calibration, code and report"),
    "identify": ("identify", "fit the error model to measured data and write a calibration"),
    "diagnose": ("diagnose", "trace the residual to missing effects, add them, refit, report"),
    "fleet": ("fleet", "calibrate many robots at once (a manifest of robot and data files) on Dask"),
    "evaluate": ("evaluate", "position errors of new data before and after the calibration"),
    "iso9283": ("iso9283", "plan the ISO 9283 pose test, or its accuracy and repeatability from a measured run"),
    "check": ("check", "a QA check: a short measurement against the calibration, pass or fail, and what changed"),
    "accuracy": ("accuracy", "the worst compensated error over a declared volume, with a confidence, against a "
                             "tolerance"),
    "export": ("export", "a calibration as C with its coefficients, as a URDF, or as a table"),
    "compensate": ("compensate", "corrected joint commands for nominal commands"),
    "filter": ("filter", "a robot program (KUKA, ABB, FANUC, UR) with its targets corrected"),
    "generate": ("generate", "write C, CasADi and a manifest for a robot and error model"),
}

#: per command, the options naming what it writes: option -> (what, is a folder)
OUTPUTS = {
    "generate": {"output": ("generated code", True)},
    "identify": {"output": ("calibration", False), "report": ("report", True)},
    "evaluate": {"report": ("report", True)},
    "compensate": {"output": ("corrected commands", False)},
    "filter": {"output": ("corrected program", False)},
    "export": {"c": ("generated code", True), "urdf": ("URDF", False)},
    "diagnose": {"output": ("error model", False), "generated": ("generated code", True), "report": ("report", True)},
    "simulate": {"output": ("measurements", False), "val_out": ("validation measurements", False),
                 "truth_out": ("truth file", False), "rig_out": ("rig file", False), "images": ("images", True)},
    "import": {"output": ("measurements", False)},
    "gravity": {"output": ("table", False)},
    "design": {"output": ("poses", False)},
    "calibrate": {"output": ("calibration folder", True)},
    "fleet": {"output": ("fleet folder", True)},
    "iso9283": {"output": ("plan", False), "report": ("report", True)},
    "check": {"history": ("history of checks", False)},
    "accuracy": {"plot": ("map", False), "report": ("report", True)},
}


class _Parser(argparse.ArgumentParser):
    """A bad option is one line naming it and the fix, not the usage block argparse prints."""

    def error(self, message):
        line = message.splitlines()[0]
        wrong = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)$", line)
        if wrong:  # argparse lists the choices; a near miss gets named
            choices = re.findall(r"'([^']*)'", wrong.group(2))
            line = line[:wrong.start()] + f"invalid choice {wrong.group(1)!r}; {nearest(wrong.group(1), choices)}"
        # an unknown option of a command is found by the top parser: its help is the command's
        command = getattr(self, "command", None)
        self.exit(2, f"{self.prog}: {line}; see {self.prog}{f' {command}' if command else ''} --help\n")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every command (argv None), or of the command argv names only: a command's
    module imports what it computes with (numpy, sympy, scipy), and `gecgen --version`, `--help` or
    one command need not pay for the others."""
    parser = _Parser(
        prog="gecgen", description="Calibrate a robot from measurements of it (GEC method) and generate the C code "
                                   "that corrects its commands. The commands are listed in the order of the work: plan "
                                   "the measurement (design, simulate, redundancy), bring it in (import, gravity), "
                                   "fit (calibrate, identify, diagnose, fleet), verify (evaluate, iso9283, check, "
                                   "accuracy), deliver (export, compensate, filter, generate). `gecgen COMMAND --help` "
                                   "explains each command; the "
                                   "README has a walk-through, docs/guide.md the user guide and docs/reference.md the "
                                   "file formats.")
    parser.add_argument("--version", action="version", version=f"gecgen {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    subparsers = {name: sub.add_parser(name, help=text) for name, (_, text) in COMMANDS.items()}

    def command(name, fn):
        p = subparsers[name]
        p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        p.set_defaults(fn=fn)
        return p

    wanted = next((a for a in argv if not a.startswith("-")), None) if argv is not None else None
    parser.command = wanted if wanted in COMMANDS else None
    for name, (module, _) in COMMANDS.items():
        if argv is None or name == wanted:
            importlib.import_module(f"gecgen.cli.{module}").add_parser(command)
    return parser


def check_outputs(args) -> list[str]:
    """One-line refusal of an output that names a folder where a file is meant, a file where a
    folder is meant, a place that cannot be written, one of the command's inputs (any other argument
    naming an existing file, and the files those name: `read_through`) or another of its outputs:
    before the work, not after it. Returns the inputs, for `files.reading`."""
    outputs = OUTPUTS.get(args.command, {})
    # an option naming several files (import's socket files) names each in its refusal
    given = [(f"the {name.replace('_', ' ')}" + (f" {v}" if isinstance(value, list) else ""), v)
             for name, value in vars(args).items() if name not in outputs
             for v in (value if isinstance(value, list) else [value])]
    inputs = {name: value for name, value in given if isinstance(value, str) and os.path.isfile(value)}
    for source in list(inputs.values()):
        inputs.update({f"the file {source} names": path for path in read_through(source)})
    written = {}
    for option, (what, folder) in outputs.items():
        path = getattr(args, option, None)
        if path is None:
            continue  # not written, or a default in the working folder
        if not str(path).strip():
            raise ModelError(f"--{option.replace('_', '-')}: an empty name; give the {what}'s "
                             f"{'folder' if folder else 'file name'}")
        if folder:
            check_output_dir(path, what)
            continue
        check_output_file(path, what)
        for name, value in inputs.items():
            if same_file(path, value):
                raise ModelError(f"{path}: is {name}, which this command reads; writing the {what} "
                                 f"there would destroy it: give another file name")
        for other, value in written.items():
            if os.path.abspath(path) == os.path.abspath(value) or same_file(path, value):
                raise ModelError(f"{path}: --{option.replace('_', '-')} names the same file as "
                                 f"--{other.replace('_', '-')}; give each output its own file")
        written[option] = path
    return list(inputs.values())


def read_through(path: str) -> list[str]:
    """The files a command also reads through the input file `path`: the URDF a robot file names;
    the robot file a calibration file names, and that file's URDF. Only those that exist: a broken
    input is reported by the command's own reading of it, with its fix."""
    found = []
    try:
        if path.endswith((".yaml", ".yml")):
            spec = read_yaml(Path(path), "robot")
            if isinstance(spec, dict) and isinstance(spec.get("urdf"), str):
                found.append(str(Path(path).parent / spec["urdf"]))
        elif path.endswith(".json"):
            spec = json.loads(Path(path).read_text())
            if isinstance(spec, dict):
                named = [spec.get("robot_file"), spec.get("robot_file_relative")]
                robots = [str(Path(path).parent / r) for r in named if isinstance(r, str)]
                found += [r for r in robots if os.path.isfile(r)]
                found += [u for r in found[:] for u in read_through(r)]
    except (ModelError, OSError, ValueError):
        return []
    return [f for f in dict.fromkeys(found) if os.path.isfile(f)]


def _os_reason(exc: OSError) -> str:
    """`path: reason` of an OSError, as one line."""
    reason = exc.strerror or str(exc)
    return (f"{exc.filename}: {reason}" if exc.filename else reason).splitlines()[0]


class Incomplete(Exception):
    """A command that did its job and wrote its output, with some of it failed: the CLI prints the
    message (one line) on stderr, the result as usual, and exits 1."""

    def __init__(self, message: str, result: dict):
        super().__init__(message)
        self.result = result


class Terminated(KeyboardInterrupt):
    """SIGTERM (a service manager, `kill`, a CI timeout), raised where the command is, so that it
    ends as on Ctrl-C: its half-written output removed, its worker processes ended."""


def _terminated(signum, frame):
    raise Terminated()


@contextlib.contextmanager
def _sigterm_interrupts():
    """While the command runs, SIGTERM raises `Terminated` (only the main thread may set handlers:
    a command run from another thread, as fleet's robots are, keeps its process's handling)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = signal.signal(signal.SIGTERM, _terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


def main(argv: list[str] | None = None) -> int:
    command_threads()
    argv = bare_register(sys.argv[1:] if argv is None else list(argv))
    args = build_parser(argv).parse_args(argv)
    # warnings become one line each after the result, and none when the command fails: the
    # failure's reason is then the one line on stderr
    with warnings.catch_warnings(record=True) as caught, _sigterm_interrupts():
        warnings.simplefilter("always")
        # as Python does by default: a library's socket or file closed late (Dask's) is not the user's business
        warnings.simplefilter("ignore", ResourceWarning)
        try:
            code, result = _run(args)
        except KeyboardInterrupt as exc:  # what was being written is cleaned up (files.write_atomically,
            # files.output_folder), unless the command says what it leaves (the exception's text)
            how, code = ("terminated", 143) if isinstance(exc, Terminated) else ("interrupted", 130)
            print(f"gecgen {args.command}: {how}; {str(exc) or 'nothing was written for its unfinished step'}",
                  file=sys.stderr)
            return code
    if code and result is None:
        return code
    for message in warning_lines(caught):
        print(f"gecgen {args.command}: warning: {message}", file=sys.stderr)
    if args.json:
        print(json.dumps(result, allow_nan=False))
    else:  # a command may print its own summary (`human`, set by its parser)
        getattr(args, "human", print_human)(result)
    return code


def _run(args) -> tuple[int, dict | None]:
    """Run a parsed command: (0, its result), or (exit code, None) after one line on stderr."""
    try:
        with reading(check_outputs(args)):
            return 0, args.fn(args)
    except Incomplete as exc:  # the job is done and written, but some of it failed: the result says what
        print(f"gecgen {args.command}: {exc}", file=sys.stderr)
        return 1, exc.result
    except ModelError as exc:
        print(f"gecgen {args.command}: {exc}", file=sys.stderr)
        return 2, None
    except OSError as exc:
        print(f"gecgen {args.command}: {_os_reason(exc)}", file=sys.stderr)
        return 2, None
    except RuntimeError as exc:
        print(f"gecgen {args.command}: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 1, None
