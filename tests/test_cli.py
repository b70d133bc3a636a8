"""The command line contract: --json prints one JSON object and nothing else on stdout; failures
exit non-zero with one line on stderr."""
import json
import subprocess
import sys

import pytest
from conftest import ROBOTS


def gecgen(*args, cwd=None, env=None):
    return subprocess.run([sys.executable, "-m", "gecgen.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env)


def test_json_output_is_exactly_one_object(tmp_path):
    run = gecgen("redundancy", ROBOTS / "puma560.yaml", "--json")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)  # raises if anything else is on stdout
    assert out["n_params"] == 42 and out["n_identifiable"] == 30 and len(out["eliminated"]) == 12
    assert all({"param", "reason", "merged_into"} <= set(e) for e in out["eliminated"])


@pytest.mark.parametrize("args, expect", [
    (["identify", ROBOTS / "pps.yaml", "missing.csv"], "missing.csv: no such measurement file"),
    (["generate", "nope.yaml"], "nope.yaml: no such robot file"),
    (["evaluate", "none.json", "x.csv"], "none.json: no such calibration file"),
    (["generate", ROBOTS / "pps.yaml", "--errors", ROBOTS / "puma560.yaml"], "unknown key"),
])
def test_failures_exit_non_zero_with_one_line(args, expect, tmp_path):
    run = gecgen(*args, "--json", cwd=tmp_path)
    assert run.returncode != 0 and run.stdout == ""
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and expect in lines[0], run.stderr


def test_human_output_is_one_short_line_per_key():
    """Without --json a person gets a summary: lists are counted, nested records flattened to their
    scalars, so even the 12 eliminated coefficients and their merges take one line."""
    run = gecgen("redundancy", ROBOTS / "puma560.yaml")
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert "n_identifiable: 30" in lines and "eliminated: 12 (use --json for the list)" in lines
    assert all(len(line) < 200 for line in lines) and not any(line.startswith("identifiable:") for line in lines)


def test_every_argument_is_explained_with_its_default():
    """`gecgen CMD --help` explains every positional and option, and states each default."""
    import argparse

    from gecgen.cli import build_parser

    parser = build_parser()
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    unexplained = [f"{name} {'/'.join(a.option_strings) or a.dest}"
                   for name, sub in commands.items() for a in sub._actions
                   if not isinstance(a, argparse._HelpAction)
                   and (not a.help or (a.option_strings and a.default not in (None, False) and "default" not in a.help))]
    assert unexplained == []
    assert len(commands) == 17


@pytest.mark.parametrize("args", [["--version"], ["--help"], ["simulat"]])
def test_help_version_and_a_typo_load_no_numerical_library(args):
    """The parser imports a command's module only for that command: `gecgen --version` and
    `--help` load neither numpy nor sympy nor scipy (they took 1.2 s to import; speed itself is
    measured in benchmarks/)."""
    import subprocess
    import sys

    code = ("import sys\nfrom gecgen.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in ('numpy', 'sympy', 'scipy', 'pandas') if m in sys.modules))")
    run = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)
    assert run.stdout.strip().splitlines()[-1] == "[]", run.stdout + run.stderr


def test_the_summary_prints_three_digits_and_the_units_given_beside_a_dict(capsys):
    """A person reads three significant digits, and a dict with `<key>_units` beside it carries
    them, the units themselves not printed as a line of their own."""
    from gecgen.cli.human import print_human

    print_human({"rms_mm": 0.123456, "max_correction": {"slide": 1.23456e-4, "turn": 0.0123456},
                 "max_correction_units": {"slide": "m", "turn": "rad"}})
    assert capsys.readouterr().out.splitlines() == ["rms_mm: 0.123", "max_correction: slide 0.000123 m, turn 0.0123 rad"]
    print_human({"seconds": 1234.56, "log_det": 312.44})
    assert capsys.readouterr().out.splitlines() == ["seconds: 1235", "log_det: 312"]
    # what JSON spells null and [] a person reads as not known and none, not as Python prints them
    # (a result's `warnings` are not printed here: each is a line on stderr already)
    print_human({"suspect_poses": [], "placement": None, "val": {"rms_mm": 0.2, "cv_rms_mm": None}, "warnings": ["x"]})
    assert capsys.readouterr().out.splitlines() == ["suspect_poses: none", "placement: -",
                                                    "val: rms_mm 0.2, cv_rms_mm -"]
    print_human({"val_registered": False, "significance": {"t_min": 2, "insignificant_carried": True}})
    assert capsys.readouterr().out.splitlines() == ["val_registered: no", "significance: t_min 2, "
                                                    "insignificant_carried yes"]
    # one next step, the verdict's (identify --cameras also lists the commands after it as JSON `next`)
    # records by name are named, not counted (one board printed as "board: 2", its rotation and translation)
    print_human({"board": {"rotation": [1, 0, 0], "translation": [0, 0, 1]}, "cameras": {"cam1": {"fx": 1}}})
    assert capsys.readouterr().out.splitlines() == ["board: rotation, translation (use --json for them)",
                                                    "cameras: cam1 (use --json for them)"]
    print_human({"next": "gecgen compensate C.json POSES.csv -o OUT.csv", "next_step": "Score the calibration first"})
    assert capsys.readouterr().out.splitlines() == ["next_step: Score the calibration first"]


def test_a_librarys_resource_warning_is_not_shown_but_gecgens_own_warnings_are(monkeypatch, capsys):
    """Python hides ResourceWarning (a socket closed late, as Dask's are) unless asked; the CLI,
    which turns every other warning into a line, hides it too."""
    import warnings

    import gecgen.cli.redundancy as command
    from gecgen.cli import main

    def warn_both(args):
        warnings.warn("unclosed <socket.socket fd=6>", ResourceWarning)
        warnings.warn("a warning of gecgen's own")
        return {"done": True}

    monkeypatch.setattr(command, "run", warn_both)
    assert main(["redundancy", str(ROBOTS / "puma560.yaml"), "--json"]) == 0
    assert capsys.readouterr().err == "gecgen redundancy: warning: a warning of gecgen's own\n"
