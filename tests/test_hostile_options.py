"""Every option of every command with hostile values (empty, 0, -1, nan, inf, 1e308, a word): a result
or a one-line refusal naming the option, never a traceback (issue 20). The commands run in this process
on a few poses of the PUMA 560 (TALOS's tree for `gravity`, which needs a URDF), so an accepted value
runs the command for real."""
import argparse
import contextlib
import io

import pytest
from conftest import ROBOTS, ROOT

from gecgen.cli import OUTPUTS, build_parser, main

HOSTILE = ["", "0", "-1", "nan", "inf", "1e308", "word"]
PUMA = str(ROBOTS / "puma560.yaml")
TALOS = str(ROOT / "tests" / "data" / "talos" / "talos.yaml")


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    t = tmp_path_factory.mktemp("hostile")
    quiet = io.StringIO()
    with contextlib.redirect_stdout(quiet), contextlib.redirect_stderr(quiet):
        assert main(["simulate", PUMA, "--poses", "12", "--seed", "1", "-o", str(t / "d.csv")]) == 0
        assert main(["identify", PUMA, str(t / "d.csv"), "-o", str(t / "c.json")]) == 0
    (t / "v.yaml").write_text("angle_unit: deg\nsamples: 5\n")
    (t / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n0.1,0.2,-0.3,0.4,0.5,-0.6\n")
    (t / "p.script").write_text("def p():\n  movej([0.1, 0.2, -0.3, 0.4, 0.5, -0.6], a=1.2, v=0.5)\nend\n")
    (t / "q.csv").write_text("q1,q2,q3,q4,q5,q6,q7,q8,q9,q10,q11,q12,q13,q14,q15,q16\n" + ",".join(["0.1"] * 16) + "\n")
    (t / "wide.csv").write_text("a,b,c,d,e,f,x,y,z\n0.1,0.2,0.3,0.1,0.2,0.3,0.5,0.1,0.4\n")
    (t / "map.yaml").write_text("pose: row\njoints: {q1: a, q2: b, q3: c, q4: d, q5: e, q6: f}\n"
                                "targets: {t1: [x, y, z]}\n")
    return t


def invocations(t):
    """A working invocation of each command: its positionals and required options."""
    return {
        "generate": [PUMA, "-o", str(t / "gen")],
        "identify": [PUMA, str(t / "d.csv"), "-o", str(t / "c2.json")],
        "evaluate": [str(t / "c.json"), str(t / "d.csv")],
        "compensate": [str(t / "c.json"), str(t / "cmd.csv"), "-o", str(t / "fixed.csv")],
        "filter": [str(t / "c.json"), str(t / "p.script"), "-o", str(t / "fixed.script")],
        "export": [str(t / "c.json"), "--table"],
        "redundancy": [PUMA],
        "simulate": [PUMA, "--poses", "4", "-o", str(t / "s.csv")],
        "import": [PUMA, str(t / "wide.csv"), "--mapping", str(t / "map.yaml"), "-o", str(t / "imported.csv")],
        "gravity": [TALOS, str(t / "q.csv"), "-o", str(t / "g.csv")],
        "design": [PUMA, "--poses", "3", "--candidates", "200", "-o", str(t / "p.csv")],
        "diagnose": [PUMA, str(t / "d.csv"), "--max-rounds", "1", "-o", str(t / "diag.errors.yaml")],
        "calibrate": [PUMA, str(t / "d.csv"), "--models", "geometric", "-o", str(t / "cal")],
        # a manifest refused as it is read: the options are checked before it, and no cluster starts
        "fleet": [str(t / "wide.csv"), "-o", str(t / "fleet")],
        "iso9283": [PUMA, "-o", str(t / "plan.csv"), "--cycles", "2"],
        "check": [str(t / "c.json"), str(t / "d.csv")],
        "accuracy": [str(t / "c.json"), str(t / "v.yaml"), str(t / "d.csv"), "--draws", "100"],
    }


def value_options():
    """(command, option string) of every option that takes a value."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return [(name, action.option_strings[-1]) for name, parser in sub.choices.items() for action in parser._actions
            if action.option_strings and action.nargs != 0 and action.dest not in ("help",)]


@pytest.mark.parametrize("command, option", value_options())
def test_every_option_takes_hostile_values_without_a_traceback(files, command, option, monkeypatch):
    monkeypatch.chdir(files)  # an accepted name is written here, never into the checkout
    base = invocations(files)[command]
    written = {f"--{o.replace('_', '-')}" for o in OUTPUTS.get(command, {})} | {"-o"}
    # an output's other values are ordinary names, written like any other (a report takes seconds)
    for value in [""] if option in written else HOSTILE:
        args = [command, *base, option, value]
        if option in base:  # the base already gives it: replace its value
            args = [command, *base]
            args[args.index(option) + 1] = value
        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            try:
                code = main(args)
            except SystemExit as exc:  # argparse's refusal of the value
                code = exc.code
        text = err.getvalue()
        assert isinstance(code, int) and "Traceback" not in text, (args, text)
        if code:
            lines = text.splitlines()
            assert len(lines) == 1 and len(lines[0]) < 400, (args, text)
