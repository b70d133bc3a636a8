"""`gecgen generate ROBOT [--errors FILE] [-o DIR]`: C, CasADi and a manifest for a robot and error model."""
from __future__ import annotations

from pathlib import Path

from gecgen.cli.common import ROBOT_HELP, robot_and_model


def add_parser(command):
    """Register `generate` through the CLI's `command(name, fn, help)` helper (it adds --json)."""
    p = command("generate", run)
    p.add_argument("robot", help=ROBOT_HELP)
    p.add_argument("--errors", help="error-model file (default: robots/NAME.errors.yaml)")
    p.add_argument("-o", "--output", help="output folder (default: generated/NAME)")


def run(args) -> dict:
    from gecgen.emit import generate

    robot, model = robot_and_model(args.robot, args.errors)
    outdir = Path(args.output or Path("generated") / robot.name)
    files = generate(robot, model, outdir)
    return {"robot": robot.name, "error_model": model.source, "output": str(outdir), "files": sorted(files),
            "n_params": len(model.coefficients), "n_errors": robot.n_errors}
