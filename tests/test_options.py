"""An option means the same, and is spelled the same, in every command that takes it."""
from __future__ import annotations

import pytest
from conftest import ROBOTS

from gecgen.cli import build_parser
from gecgen.cli.register import bare_register


def _parsed(*argv: str):
    argv = bare_register(list(argv))
    return build_parser(argv).parse_args(argv)


@pytest.mark.parametrize("argv, register", [
    # every spelling that worked keeps its meaning
    (["evaluate", "c.json", "d.csv"], "never"),
    (["evaluate", "c.json", "d.csv", "--register"], "always"),
    (["evaluate", "--register", "c.json", "d.csv"], "always"),
    (["calibrate", "r.yaml", "t.csv", "--val", "v.csv", "--register", "-o", "out"], "val"),
    (["calibrate", "--register", "r.yaml", "t.csv", "-o", "out"], "val"),
    (["identify", "r.yaml", "d.csv", "--register", "never"], "never"),
    (["diagnose", "r.yaml", "d.csv", "--register"], "val"),
    (["diagnose", "r.yaml", "d.csv", "--register", "always"], "always"),
    # and each takes the one form: --register MODE, --register=MODE, --register alone
    (["evaluate", "c.json", "d.csv", "--register", "always"], "always"),
    (["evaluate", "c.json", "d.csv", "--register=never"], "never"),
    (["evaluate", "c.json", "d.csv", "--register", "auto"], "auto"),
    (["calibrate", "r.yaml", "t.csv", "--register", "always", "-o", "out"], "always"),
    (["calibrate", "r.yaml", "t.csv", "--register=val", "-o", "out"], "val"),
    (["identify", "r.yaml", "d.csv", "--register"], "always"),
    (["identify", "--register", "r.yaml", "d.csv"], "always"),
    (["diagnose", "r.yaml", "d.csv", "--register=val"], "val"),
])
def test_register_takes_one_form_everywhere_and_every_old_spelling(argv, register):
    args = _parsed(*argv)
    assert args.register == register
    first = next(a for a in argv[1:] if a.endswith((".yaml", ".json")))  # not taken for the mode
    assert first in (getattr(args, "robot", None), getattr(args, "calibration", None))


@pytest.mark.parametrize("argv, allowed", [
    (["evaluate", "c.json", "d.csv", "--register=val"], "auto, always, never"),
    (["identify", "r.yaml", "d.csv", "--register=val"], "auto, always, never"),
])
def test_a_registration_a_command_does_not_do_is_one_line(capsys, argv, allowed):
    with pytest.raises(SystemExit) as exc:
        _parsed(*argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.splitlines()) == 1
    assert f"is not a registration this command does; give one of {allowed}, or --register alone" in err


def test_the_python_calibrate_refuses_an_unknown_registration():
    from gecgen.api import calibrate
    from gecgen.model import ModelError

    with pytest.raises(ModelError, match="register"):
        calibrate("r.yaml", "t.csv", register="sometimes")


def test_gravity_is_one_constant_wherever_a_default_is_taken():
    """Standard gravity, 9.80665 m/s^2, in the simulator's truth, the URDF gravity torques and the
    robot file's default alike; design takes the robot file's own (a Y-up PPS's payload weighs along
    -y)."""
    import numpy as np

    from gecgen.model import gravity as urdf_gravity
    from gecgen.model import load_robot
    from gecgen.model.kinematics import sensor_wrench
    from gecgen.model.robot import GRAVITY
    from gecgen.plan import design
    from gecgen.simulate import load_truth

    assert np.linalg.norm(np.array(GRAVITY, float)) == 9.80665
    puma = load_robot(ROBOTS / "puma560.yaml")
    given = [list(load_truth({}, puma).gravity), list(urdf_gravity.UPRIGHT), [float(v) for v in puma.gravity]]
    assert all(g == [float(v) for v in GRAVITY] for g in given), given
    assert _parsed("design", "r.yaml", "--poses", "3", "-o", "p.csv").gravity is None  # the robot file's
    pps = load_robot(ROBOTS / "pps.yaml")
    assert [float(v) for v in pps.gravity] == [0.0, -9.80665, 0.0]
    cands = design.uniform_candidates(pps, 5, np.random.default_rng(0), [70.0])
    expected = sensor_wrench(pps, cands.q, cands.payload_kg, np.zeros(3), np.array([0.0, -9.80665, 0.0]))
    np.testing.assert_array_equal(cands.w, expected)


def test_help_lists_the_commands_in_the_order_of_the_work(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--help"])
    listed = capsys.readouterr().out.split("positional arguments:")[1].split("{", 1)[1].split("}", 1)[0].split(",")
    plan, bring, fit, verify, deliver = (["design", "simulate", "redundancy"], ["import", "gravity"],
                                         ["calibrate", "identify", "diagnose", "fleet"],
                                         ["evaluate", "iso9283", "check", "accuracy"],
                                         ["export", "compensate", "filter", "generate"])
    assert listed == plan + bring + fit + verify + deliver
