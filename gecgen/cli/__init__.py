"""The `gecgen` command line (CONTRACTS.md section 4): one module per command in this package.

Every command takes --json (one JSON object on stdout, nothing else there) and exits non-zero
with a one-line reason on stderr when it cannot do its job.
"""
from __future__ import annotations

import argparse
import importlib
import json
import sys
import warnings

from gecgen import __version__
from gecgen.cli.human import print_human
from gecgen.files import check_output_dir, check_output_file
from gecgen.model import ModelError

#: the command modules, in the order `gecgen --help` lists them
COMMANDS = ("generate", "identify", "evaluate", "compensate", "export", "redundancy", "simulate", "import_", "gravity",
            "design", "diagnose", "calibrate")

#: per command, the options naming what it writes: option -> (what, is a folder)
OUTPUTS = {
    "generate": {"output": ("generated code", True)},
    "identify": {"output": ("calibration", False), "report": ("report", True)},
    "evaluate": {"report": ("report", True)},
    "compensate": {"output": ("corrected commands", False)},
    "export": {"c": ("generated code", True), "urdf": ("URDF", False)},
    "diagnose": {"output": ("error model", False), "generated": ("generated code", True), "report": ("report", True)},
    "simulate": {"output": ("measurements", False), "val_out": ("validation measurements", False),
                 "truth_out": ("truth file", False)},
    "import": {"output": ("measurements", False)},
    "gravity": {"output": ("table", False)},
    "design": {"output": ("poses", False)},
    "calibrate": {"output": ("calibration folder", True)},
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gecgen", description="Calibrate a robot from measurements of it (GEC method) and generate the C code "
                                   "that corrects its commands. `gecgen COMMAND --help` explains each command; the "
                                   "README has a walk-through and the file formats.")
    parser.add_argument("--version", action="version", version=f"gecgen {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    def command(name, fn, help_text):
        p = sub.add_parser(name, help=help_text)
        p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
        p.set_defaults(fn=fn)
        return p

    for module in COMMANDS:
        importlib.import_module(f"gecgen.cli.{module}").add_parser(command)
    return parser


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
        print_human(result)
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
