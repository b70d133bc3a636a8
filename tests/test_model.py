"""Robot and error-model files: contract values, pinned kinematics, and refusal of bad input."""
import functools

import numpy as np
import pytest
from conftest import ROBOTS

from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import error_model_from_dict, load_error_model
from gecgen.model.kinematics import tool_pose


def test_pps_home_pose_and_prismatic_axes():
    robot = load_robot(ROBOTS / "pps.yaml")
    T = tool_pose(robot, np.zeros(6))[0]
    np.testing.assert_allclose(T[:3, :3], np.eye(3), atol=1e-12)  # tool axes parallel to world axes
    np.testing.assert_allclose(T[:3, 3], [0, 0.60, 0.80], atol=1e-12)
    for k in range(3):  # joints 1-3 move the tool along world +X, +Y, +Z
        q = np.zeros(6)
        q[k] = 0.123
        np.testing.assert_allclose(tool_pose(robot, q)[0][:3, 3] - T[:3, 3], 0.123 * np.eye(3)[k], atol=1e-12)
    assert robot.points["isocenter"] == (0.0, 0.80, 0.40)


def test_industrial6r_stretched_pose():
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    T = tool_pose(robot, np.radians([0, -90, -90, 0, 0, 0]))[0]
    np.testing.assert_allclose(T[:3, 3], [2.715, 0, 0.634], atol=1e-12)
    np.testing.assert_allclose(T[:3, 2], [1, 0, 0], atol=1e-12)


def test_puma560_matches_robotics_toolbox_dh():
    robot = load_robot(ROBOTS / "puma560.yaml")
    T = tool_pose(robot, np.zeros(6))[0]  # toolbox: p560.fkine(qz) has t = [0.4521, -0.1500, 0.4318]
    np.testing.assert_allclose(T[:3, 3], [0.4521, -0.15005, 0.4318], atol=1e-12)
    assert [round(np.degrees(j.upper)) for j in robot.joints] == [160, 225, 45, 170, 100, 266]


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = """name: r2
angle_unit: deg
joints:
  - {type: R, theta: 0, d: 0.1, a: 0.5, alpha: 0, limits: [-90, 90]}
  - {type: P, theta: 0, d: 0, a: 0.2, alpha: 90, limits: [0, 0.3]}
targets: {t: [0, 0, 0.1]}
"""


@pytest.mark.parametrize("text, expect", [
    (GOOD.replace("targets: {t: [0, 0, 0.1]}\n", ""), "missing key 'targets'"),
    (GOOD.replace("type: P", "type: Q"), "unknown joint type 'Q'"),
    (GOOD.replace("a: 0.5", "a: long"), "joints[0].a: expected a number"),
    (GOOD.replace("limits: [0, 0.3]", "limits: [0.3, 0]"), "lower limit"),
    (GOOD.replace("angle_unit: deg", "angle_unit: grad"), "angle_unit"),
    (GOOD + "colour: red\n", "unknown key 'colour'"),
    (GOOD.replace("{t: [0, 0, 0.1]}", "{t: [0, 0]}"), "targets.t"),
])
def test_malformed_robot_files_are_refused_with_one_line(tmp_path, text, expect):
    path = write(tmp_path, "r2.yaml", text)
    with pytest.raises(ModelError) as err:
        load_robot(path)
    message = str(err.value)
    assert expect in message and str(path) in message and "\n" not in message


@pytest.mark.parametrize("terms, expect", [
    ('["__import__(\'os\').system(\'true\')"]', "is not allowed"),
    ('["q3"]', "unknown variable 'q3'"),
    ('["temp_c"]', "unknown variable 'temp_c'"),
    ('["q1 +"]', "not a valid expression"),
    ('["q1**400"]', "exponent"),
    ('["q1", "q1"]', "repeats"),
    ('["2"]', "constant"),
    ('["q1.real"]', "is not allowed"),
    ('["poly(q1)"]', "poly takes"),
    ('["sin(poly(q1, 2))"]', "must stand alone"),
])
def test_bad_terms_are_refused(tmp_path, terms, expect):
    robot = load_robot(write(tmp_path, "r2.yaml", GOOD))
    path = write(tmp_path, "r2.errors.yaml", f"frames:\n  1:\n    ey: {terms}\n")
    with pytest.raises(ModelError) as err:
        load_error_model(path, robot)
    message = str(err.value)
    assert expect in message and "frames.1.ey" in message and str(path) in message and "\n" not in message


def test_term_language(tmp_path):
    robot = load_robot(write(tmp_path, "r2.yaml", GOOD))
    path = write(tmp_path, "e.yaml", 'aux: [temp_c]\ndefault: ["1"]\nframes:\n  1: ["1", "poly(q1, 3)"]\n'
                                     '  2:\n    ey: ["1", "fy", "fy*q2**3", "fourier(q2, 0.45, 2)", "temp_c", "cos(q1 + q2)"]\n')
    model = load_error_model(path, robot)
    texts = [t.text for t in model.terms[6 * 2 + 1]]
    assert texts[:3] == ["1", "fy", "fy*q2**3"] and len(texts) == 3 + 4 + 2
    assert [t.text for t in model.terms[6]] == ["1", "q1", "q1**2", "q1**3"]
    assert model.aux == ("temp_c",)
    assert len(model.coefficients) == 6 + 6 * 4 + 5 + 9
    # names spell the terms as the file does (shorthands expanded readably), not sympy's canonical form
    names = model.coefficient_names(robot)
    assert "2.ey:sin(4*pi*q2/0.45)" in names and "2.ey:cos(2*pi*q2/0.45)" in names and "1.ex:q1**3" in names
    assert "2.ey:sin(40*pi*q2/9)" not in names
    # the model written back (as diagnose and calibrations do) reads back to the same terms and names
    again = error_model_from_dict(model.to_yaml_dict(robot), robot, "<round trip>")
    assert [[t.text for t in ts] for ts in again.terms] == [[t.text for t in ts] for ts in model.terms]
    assert again.coefficient_names(robot) == names


def test_shipped_default_models(shipped):
    robot, model = shipped
    first = [t.text for t in model.terms[6]]
    if robot.name == "puma560":
        assert all([t.text for t in ts] == ["1"] for ts in model.terms)
    else:
        assert first == ["1", "q1", "q1**2", "fx", "fy", "fz", "mx", "my", "mz"]
        assert all([t.text for t in ts] == ["1"] for ts in model.terms[:6])


def test_exact_numbers_are_sympys_to_the_last_bit():
    """A robot's numbers are read without sympy (model.exact) and become sympy's in the symbolic
    layer: every float the numeric chain, the limits and the generated C use is the one sympy gives,
    last bit included (sympy does not always round pi/180 multiples to the nearest double)."""
    from fractions import Fraction

    import sympy as sp

    from gecgen.model.exact import PiMultiple, exact_norm
    from gecgen.symbolic.exact import sympy_number

    rng = np.random.default_rng(7)
    factors = [Fraction(k, 180) for k in range(-720, 721) if k] + \
              [Fraction(int(n), int(d)) for n, d in zip(rng.integers(-10**9, 10**9, 500), rng.integers(1, 10**9, 500))]
    for power in (1, -1):
        for f in factors:
            x = PiMultiple(f, power)
            assert float(x) == float(sympy_number(x)) == float(sp.Rational(f.numerator, f.denominator) * sp.pi**power), x
    assert exact_norm((0, 0, Fraction("-9.80665"))) == float(sp.sqrt(sp.Rational("9.80665") ** 2))


SIMPLE_LISTS = [["1", "q1", "q1**2", "fx", "mz"], [1, " q2 ** 3 ", "shoulder", "shoulder**2", "q1**16"], [],
                ["q1*q2", "q3 * q2**2", "shoulder*q6", "mz*q1", "q2*fx*fy**3", "q6**16*q5"],
                ["sin(q1)", "cos(shoulder)", " sin( q2 ) ", "cos(q6)", "sin(fz)"]]


@pytest.mark.parametrize("items", SIMPLE_LISTS + [
    ["q1", "shoulder"], ["q1**1"], ["q1**0"], ["q1**17"], ["pi"], ["unknown"], [True], ["2"], ["lambda"], ["q1**2.0"],
    ["1", "1"], ["q1*q1"], ["q1*q2", "q2*q1"], ["q1**17*q2"], ["q1**1*q2"], ["2*q1"], ["q1*pi"], ["sin(q1)*q2"],
    ["sin(2*q1)"], ["sin(q1 + q2)"], ["sin(pi)"], ["tan(q1)"], ["sin(q1, q2)"], ["sin(x=q1)"], ["sin(q1)", "sin(shoulder)"],
    ["q1*unknown"], ["q1*q2**-1"], ["q1*q2**True"]])
def test_constants_variables_powers_products_and_sines_are_read_without_sympy_as_the_parser_reads_them(items):
    """`simple_terms` gives the parser's terms (text, label, variables) or leaves the list to it
    (NeedsParser), on a robot whose joints have names (aliases of q1..q6): products of variables in
    sympy's order of their names, sin and cos of one variable."""
    ours, theirs = _read_both("industrial6r", items)
    assert ours == theirs or ours is None, (ours, theirs)
    assert (ours is not None) == (items in SIMPLE_LISTS)


def _read_both(name: str, items: list):
    """(`simple_terms`' terms or None when it leaves the list to the parser, the parser's terms or None
    when it refuses the list) of items on robots/NAME.yaml; on industrial6r joint 1 is named
    `shoulder`, a joint name that reads as one."""
    from gecgen.model.error_file import NeedsParser, simple_terms
    from gecgen.model.errors import variable_names
    from gecgen.symbolic.parse import terms_of

    robot = _robot(name)
    names = variable_names(robot, ())
    if name == "industrial6r":
        names["shoulder"] = names.pop(robot.joints[0].name)
    try:
        ours = simple_terms(items, "m", robot, names)
    except NeedsParser:
        ours = None
    try:
        theirs = terms_of(items, "m", robot, names)
    except ModelError:
        theirs = None
    return ours, theirs


@functools.cache
def _robot(name: str):
    return load_robot(ROBOTS / f"{name}.yaml")


#: term lists of load functions read without sympy, on industrial6r (no masses: wrench and regressor
#: signals) and panda (URDF masses: gravity torques and frame loads)
LOAD_LISTS = [("industrial6r", ["1", "gravity(q2)", "gravity(q3, 2)", "wrench_torque(q2)", " wrench_torque( q6 ) "]),
              ("industrial6r", ["gravity(4, mx)", "wrench_load(4, fz)", "wrench_load(shoulder, mz)",
                                "gravity(2, mx, 2)"]),
              ("industrial6r", ["q2*wrench_torque(q2)", "fx*gravity(q3, 1)", "wrench_torque(q3)*q1**2*mz",
                                "gravity(q2,10)*q1*gravity(q2,2)", "wrench_torque(q2)*wrench_torque(q3)"]),
              ("panda", ["1", "gravity_torque(q2)", "gravity_torque(panda_joint6)", "gravity_torque(q4)*q4",
                         "gravity_load(3, mx)", "gravity_load(q4, fz)*fx"])]


#: lists the parser refuses or that only it reads (a function of a signal, a signal twice, a power of one)
LOAD_REFUSED = [["gravity_torque(q6)"], ["gravity_load(3, mx)"], ["gravity(shoulder)"], ["gravity(q2)*q2"],
                ["sign(wrench_torque(q2))"], ["wrench_torque(q2)**2"], ["wrench_torque(q2)*wrench_torque(q2)"],
                ["wrench_torque(q7)"], ["gravity(q2, 99)"], ["gravity(q2, 1)", "gravity(q2)"],
                ["gravity(4, mx)", "gravity(4, mx, 1)"], ["wrench_torque(x=q2)"], ["wrench_torque(fx)"],
                ["wrench_load(4, q1)"], ["sin(wrench_torque(q2))"]]


@pytest.mark.parametrize("name, items", LOAD_LISTS + [("industrial6r", items) for items in LOAD_REFUSED]
                         + [("panda", ["gravity_torque(q2)", "gravity_torque(panda_joint2)"])])
def test_load_functions_are_read_without_sympy_as_the_parser_reads_them(name, items):
    """`simple_terms` reads load signals standing alone, the gravity shorthands (one term per column) and
    products with signals as the term parser does (text, label, variables), or leaves the list to it."""
    ours, theirs = _read_both(name, items)
    assert ours == theirs or ours is None, (ours, theirs)
    assert (ours is not None) == ((name, items) in LOAD_LISTS)
