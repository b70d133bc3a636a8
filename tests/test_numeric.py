"""The numpy evaluation of the generated code's entry points (`runtime.numeric`), the backend a new
model runs on while its C compiles, against the compiled C: targets at eps(c), H_e, J_e, the nominal
targets, eps and the basis terms, on a serial arm, a coupled arm, a prismatic table, a tree with a
passive joint and frame loads, joint loads and auxiliary signals; and identify's result either way."""
import json

import numpy as np
import pytest
from conftest import FRAME_LOADS, JOINT_LOADS, ROBOTS, ROOT, random_q, run_json

from gecgen.model import ModelError, load_robot
from gecgen.runtime.compiled import BOUNDED, NONFINITE, NOT_CONVERGED, OK, OUTSIDE_LIMITS, SINGULAR, CompiledModel
from gecgen.runtime.numeric import NumericModel
from gecgen.symbolic.terms import error_model_from_dict, load_error_model

#: 1e-9 mm: the numpy and C values may differ by rounding only
TOL = 1e-12

CASES = {  # robot -> its error model: the models other tests compile too, so their C is built once
    "industrial6r": "industrial6r.errors.yaml",  # serial, q and q**2 terms and the wrench
    "fanuc": None,                                # J2/J3 coupling, with its ratio term
    "pps": "pps.errors.yaml",                     # three prismatic joints
    "tiago": "tiago.elastic.errors.yaml",         # auxiliary signals (gravity torques)
    "humanoid": FRAME_LOADS,                      # tree, passive joint, frame loads
    "panda": JOINT_LOADS,                         # joint loads, sign and abs
}


def _case(name: str):
    """The robot and error model of CASES[name]."""
    robot = load_robot(ROBOTS / f"{name}.yaml")
    spec = CASES[name]
    return robot, error_model_from_dict(spec, robot, "<loads>") if isinstance(spec, dict) else \
        load_error_model(spec and ROBOTS / spec, robot)


@pytest.mark.parametrize("name", CASES)
def test_numpy_evaluation_agrees_with_the_compiled_c(name, rng):
    robot, model = _case(name)
    c, numeric = CompiledModel(robot, model, "c"), NumericModel(robot, model)
    N = 5
    q, w = random_q(robot, rng, N), rng.normal(0, 30, (N, 6))
    aux = rng.normal(0, 20, (N, len(model.aux))) if model.aux else None
    coef = rng.normal(0, 1e-3, c.dims.nc)
    assert c.dims.nc > robot.n_errors / 6 and (name != "fanuc" or any(t.text == "q2" for t in model.unique_terms()))
    f = c.basis(q, w, aux)
    assert np.ptp(f, axis=0).max() > 0.1  # the terms vary: the comparison sees them
    np.testing.assert_allclose(numeric.basis(q, w, aux), f, rtol=1e-13, atol=TOL)
    back = slice(None, None, -1)  # other poses: the basis of the last ones is not reused for them
    np.testing.assert_allclose(numeric.basis(q[back], w[back], None if aux is None else aux[back]), f[back],
                               rtol=1e-13, atol=TOL)
    eps = c.eps(q, w, aux, coef)
    np.testing.assert_allclose(numeric.eps(q, w, aux, coef), eps, rtol=1e-13, atol=TOL)
    p, H = c.model_targets(q, w, aux, coef, with_H=True)
    p_n, H_n = numeric.model_targets(q, w, aux, coef, with_H=True)
    np.testing.assert_allclose(p_n, p, rtol=0, atol=TOL)
    np.testing.assert_allclose(H_n, H, rtol=1e-13, atol=TOL)
    np.testing.assert_allclose(numeric.model_targets(q, w, aux, coef), p, rtol=0, atol=TOL)
    for got, want in zip(numeric.J_e(q, eps), c.J_e(q, eps)):
        np.testing.assert_allclose(got, want, rtol=0, atol=TOL)
    np.testing.assert_allclose(numeric.nominal_targets(q), c.nominal_targets(q), rtol=0, atol=TOL)
    assert np.abs(p - c.nominal_targets(q)).max() > 1e-4  # the errors move the targets


def _same_compensation(c: CompiledModel, numeric: NumericModel, *args, **options) -> np.ndarray:
    """The status codes of c.correct(*args, **options), asserted to be numeric's, and wherever a solve
    ended (every status but NOT_CONVERGED, whose last step depends on rounding, and NONFINITE), the same
    joints and residuals to 1e-12 (1e-9 mm)."""
    want, got = c.correct(*args, **options), numeric.correct(*args, **options)
    np.testing.assert_array_equal(got[1], want[1])
    ended = ~np.isin(want[1], (NOT_CONVERGED, NONFINITE))
    for k in (0, 2):
        np.testing.assert_allclose(got[k][ended], want[k][ended], rtol=0, atol=TOL)
    return want[1]


@pytest.mark.parametrize("name", CASES)
def test_numpy_compensation_is_the_compiled_c_s(name, rng):
    """`NumericModel.correct` against the generated C's compensate_bounded_batch, on every branch of the
    tree (arms of fewer than six joints: the whole pose, else the position), with loads held at the
    command's."""
    robot, model = _case(name)
    c, numeric = CompiledModel(robot, model, "c"), NumericModel(robot, model)
    N = 2  # a tree's arm runs the damping ladder twice (whole pose, then position): 0.3 s a command
    q, w = random_q(robot, rng, N), rng.normal(0, 30, (N, 6))
    aux = rng.normal(0, 20, (N, len(model.aux))) if model.aux else None
    coef = rng.normal(0, 1e-4, c.dims.nc)
    statuses = [_same_compensation(c, numeric, q, w, aux, coef, branch=b) for b in range(len(robot.tips()))]
    assert np.isin(np.concatenate(statuses), (OK, OUTSIDE_LIMITS)).any()  # placed answers were compared


def test_numpy_compensation_through_the_damping_ladder_is_the_compiled_c_s(rng):
    """The wrist straightening (q5 -> 0): at q5 = 0.1 rad an undamped solve places the tool; nearer,
    every command runs the damping ladder to its end (SINGULAR), whose joints are the C's to 1e-12."""
    robot, model = _case("industrial6r")
    c, numeric = CompiledModel(robot, model, "c"), NumericModel(robot, model)
    q = np.array([[0.3, -0.4, 0.5, 0.7, q5, -0.2] for q5 in (0.0, 0.01, 0.05, 0.1)])
    damped = []
    solve = numeric._solve
    numeric._solve = lambda *a: damped.append(a[7] is not None) or solve(*a)  # a[7]: the damping P
    statuses = _same_compensation(c, numeric, q, None, None, rng.normal(0, 1e-4, c.dims.nc))
    assert list(statuses) == [SINGULAR, SINGULAR, SINGULAR, OK] and damped.count(False) == 1 and sum(damped) >= 3


def test_numpy_compensation_with_a_bound_is_the_compiled_c_s(rng):
    robot, model = _case("industrial6r")
    c, numeric = CompiledModel(robot, model, "c"), NumericModel(robot, model)
    q, coef = random_q(robot, rng, 2), rng.normal(0, 2e-3, c.dims.nc)
    assert BOUNDED in _same_compensation(c, numeric, q, None, None, coef, bound=1e-3)


def test_numpy_jacobian_is_the_derivative_of_the_chain(rng):
    """J_e at nonzero errors against central differences of the targets, on the tree (a column of the
    other branch's frames is zero)."""
    robot = load_robot(ROBOTS / "humanoid.yaml")
    numeric = NumericModel(robot, load_error_model(None, robot))
    q, eps = random_q(robot, rng, 2), rng.normal(0, 0.02, (2, robot.n_errors))
    p, J = numeric.J_e(q, eps)
    h = 1e-6
    for k in rng.choice(robot.n_errors, 12, replace=False):
        step = np.zeros(robot.n_errors)
        step[k] = h
        d = (numeric.J_e(q, eps + step)[0] - numeric.J_e(q, eps - step)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], d.reshape(2, -1), atol=1e-8)


def test_identify_gives_the_same_calibration_in_numpy_and_in_c(tmp_path, monkeypatch):
    """TIAGo's training file as docs/real-data-tiago.md imports it, the default model: the fit, its
    residuals and every coefficient the same to 1e-9 mm (or 1e-12 rad) on either backend."""
    data = tmp_path / "train.csv"
    run_json("import", ROBOTS / "tiago.yaml", ROOT / "tests" / "data" / "tiago-mocap" / "train_2021-11-30.csv",
             "--mapping", ROBOTS / "tiago.import.yaml", "-o", data)
    fits, calibrations = {}, {}
    for backend in ("c", "numpy"):
        monkeypatch.setenv("GECGEN_BACKEND", backend)
        out = tmp_path / f"{backend}.json"
        fits[backend] = run_json("identify", ROBOTS / "tiago.yaml", data, "-o", out)
        calibrations[backend] = json.loads(out.read_text())
    c, n = fits["c"], fits["numpy"]
    assert c["n_carried"] == n["n_carried"] > 20 and c["eliminated"] == n["eliminated"]
    assert c["iterations"] == n["iterations"] and c["held"] == n["held"]
    for key in ("before", "train"):
        for stat in ("rms_mm", "max_mm"):
            assert abs(c[key][stat] - n[key][stat]) < 1e-9
    coef_c, coef_n = calibrations["c"]["coefficients"], calibrations["numpy"]["coefficients"]
    assert [(k["name"], k["identified"]) for k in coef_c] == [(k["name"], k["identified"]) for k in coef_n]
    assert calibrations["c"]["kept"] == calibrations["numpy"]["kept"] and any(k["value"] for k in coef_c)
    assert max(abs(a["value"] - b["value"]) for a, b in zip(coef_c, coef_n)) < 1e-12  # m, rad


def test_compensation_on_the_numpy_backend_is_the_c_and_a_wrong_backend_is_one_line(rng, monkeypatch):
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    model = load_error_model(ROBOTS / "industrial6r.errors.yaml", robot)
    c, numeric = CompiledModel(robot, model, "c"), CompiledModel(robot, model, "numpy")
    q, coef = random_q(robot, rng, 4), rng.normal(0, 1e-4, c.dims.nc)
    for got, want in zip(numeric.correct(q, None, None, coef), c.correct(q, None, None, coef)):
        np.testing.assert_array_equal(got, want)
    monkeypatch.setenv("GECGEN_BACKEND", "fortran")
    with pytest.raises(ModelError, match=r"^GECGEN_BACKEND='fortran' is not a backend; set it to auto, c, numpy, "
                                         r"casadi, or unset it$"):
        CompiledModel(robot, model)


def test_no_background_build_into_a_cache_that_lasts_one_run(tmp_path, monkeypatch):
    """A cache folder that cannot be written is replaced by a temporary one for the run: no C built
    there would be found by the next run, so none is started."""
    from gecgen.runtime.compiled import build_in_background

    (tmp_path / "file").write_text("")
    monkeypatch.setenv("GECGEN_CACHE", str(tmp_path / "file" / "cache"))
    robot = load_robot(ROBOTS / "industrial6r.yaml")
    with pytest.warns(UserWarning, match="cannot be written"):
        assert not build_in_background(robot, load_error_model(None, robot), "key")


def test_numpy_compensation_uses_the_generated_c_s_constants():
    """NONLINEAR_SHARE, NEAR_SINGULAR and STALL_STEPS are the values the C templates define."""
    from gecgen.runtime import numeric

    templates = ROOT / "gecgen" / "emit" / "c" / "templates"
    header, source = (templates / "header.h.j2").read_text(), (templates / "source.c.j2").read_text()
    assert f"#define GECGEN_NONLINEAR_SHARE {numeric.NONLINEAR_SHARE}\n" in header
    assert f"#define GECGEN_NEAR_SINGULAR {numeric.NEAR_SINGULAR}\n" in header
    assert f"#define STALL_STEPS {numeric.STALL_STEPS}\n" in source
