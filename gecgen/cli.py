"""The `gecgen` command line (CONTRACTS.md section 4).

Every command takes --json (one JSON object on stdout, nothing else there) and exits non-zero
with a one-line reason on stderr when it cannot do its job.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from gecgen.model import ModelError, load_error_model, load_robot


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


def _print_human(result: dict):
    for key, value in result.items():
        print(f"{key}: {value}")


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
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        result = args.fn(args)
    except (ModelError, FileNotFoundError) as exc:
        print(f"gecgen {args.command}: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        print(f"gecgen {args.command}: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(result, allow_nan=False))
    else:
        _print_human(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
