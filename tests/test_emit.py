"""Generated code: C, CasADi and sympy agree; generate is deterministic; generated/ is current;
the C is C99-clean under -Wall -Wextra -Werror and clean under AddressSanitizer and UBSan."""
import subprocess

import numpy as np
import pytest
from conftest import ROBOTS, ROOT, SHIPPED, random_q

from gecgen.cli import main
from gecgen.emit import render
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.loads import catalog
from gecgen.runtime.compiled import CompiledModel
from gecgen.symbolic.functions import all_functions
from gecgen.symbolic.loads import loads_function


def test_c_casadi_and_sympy_agree(shipped, rng):
    robot, model = shipped
    c_model, ca_model = CompiledModel(robot, model, "c"), CompiledModel(robot, model, "casadi")
    fns = {f.name: f for f in all_functions(robot, model)}
    q, eps = random_q(robot, rng, 3), rng.normal(0, 0.01, (3, robot.n_errors))
    w, coef = rng.normal(0, 50, (3, 6)), rng.normal(0, 1e-4, len(model.coefficients))
    for (p_c, J_c), (p_ca, J_ca) in [(c_model.J_e(q, eps), ca_model.J_e(q, eps))]:
        np.testing.assert_allclose(p_c, p_ca, atol=1e-12)
        np.testing.assert_allclose(J_c, J_ca, atol=1e-12)
    for i in range(3):
        ref = fns["J_e"].evaluate(q=q[i], eps=eps[i])
        np.testing.assert_allclose(J_c[i].ravel(), ref["J"], atol=1e-12)
        np.testing.assert_allclose(p_c[i].ravel(), ref["p"], atol=1e-12)
    pc, Hc = c_model.model_targets(q, w, None, coef, with_H=True)
    pa, Ha = ca_model.model_targets(q, w, None, coef, with_H=True)
    np.testing.assert_allclose(pc, pa, atol=1e-12)
    np.testing.assert_allclose(Hc, Ha, atol=1e-12)
    np.testing.assert_allclose(c_model.eps(q, w, None, coef), ca_model.eps(q, w, None, coef), atol=1e-15)
    np.testing.assert_allclose(c_model.basis(q, w, None), ca_model.basis(q, w, None), atol=1e-12)
    np.testing.assert_allclose(c_model.nominal_targets(q), ca_model.nominal_targets(q), atol=1e-12)
    # every load signal the robot supports, in numpy (what diagnose screens), against the symbolic
    # formulas; the generated code computes only the model's own (none for these models)
    names, L = c_model.load_signals(q, w)
    assert names == catalog(robot).names and L.shape == (3, len(names)) and len(names) > robot.n
    assert fns["loads"].outputs["L"] == () and model.load_signals(robot) == []
    every = loads_function(robot, names)
    for i in range(3):
        np.testing.assert_allclose(L[i], every.evaluate(q=q[i], w=w[i])["L"], atol=1e-12)


def test_generate_is_deterministic_and_generated_folder_is_current(tmp_path):
    for name in SHIPPED:
        args = [str(ROBOTS / f"{name}.yaml"), "-o"]
        assert main(["generate", *args, str(tmp_path / "a" / name)]) == 0
        assert main(["generate", *args, str(tmp_path / "b" / name)]) == 0
        for f in (tmp_path / "a" / name).iterdir():
            assert f.read_bytes() == (tmp_path / "b" / name / f.name).read_bytes(), f.name
            committed = ROOT / "generated" / name / f.name
            assert committed.exists() and committed.read_bytes() == f.read_bytes(), \
                f"generated/{name}/{f.name} is stale: run gecgen generate robots/{name}.yaml"


DRIVER = r"""
#include <stdio.h>
#include <string.h>
#include "%(name)s.h"
int main(void) {
    double q[%(N)s_NQ], w[6] = {10, -20, 300, 1, -2, 3}, c[%(N)s_NC], eps[%(N)s_NE];
    double p[3 * %(N)s_NT], J[3 * %(N)s_NT * %(N)s_NE], H[3 * %(N)s_NT * %(N)s_NC], T[16], qo[%(N)s_NQ];
    double L[%(N)s_NL > 0 ? %(N)s_NL : 1];  /* none when the model uses no load signal */
    int k, it, st;
    /* 60 %% of each range, away from the middle: the middle of a wrist's range is its singular J5 = 0 */
    for (k = 0; k < %(N)s_NQ; ++k) q[k] = 0.4 * %(name)s_q_min[k] + 0.6 * %(name)s_q_max[k] + 0.01 * k;
    for (k = 0; k < %(N)s_NC; ++k) c[k] = 1e-5 * ((k %% 7) - 3);
    %(name)s_fk(q, T);
    %(name)s_eps(q, w, NULL, c, eps);
    %(name)s_J_e(q, eps, p, J);
    %(name)s_H_e(q, w, NULL, eps, H);
    %(name)s_model_batch(1, q, w, NULL, c, p, H);
    %(name)s_loads_batch(1, q, w, L);
    st = %(name)s_compensate(q, w, NULL, c, 30, 1e-11, qo, &it);
    printf("status %%d iterations %%d x %%.6f\n", st, it, T[3]);
    return st == GECGEN_NOT_CONVERGED || st == GECGEN_SINGULAR;
}
"""


@pytest.mark.parametrize("name", SHIPPED)
def test_c_builds_pedantic_and_runs_clean_under_sanitizers(tmp_path, name):
    robot = load_robot(ROBOTS / f"{name}.yaml")
    files = render(robot, load_error_model(ROBOTS / f"{name}.errors.yaml", robot))
    for fname, text in files.items():
        (tmp_path / fname).write_text(text)
    (tmp_path / "driver.c").write_text(DRIVER % {"name": name, "N": name.upper()})
    flags = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-Wshadow", "-Wconversion", "-g",
             "-fsanitize=address,undefined", "-fno-sanitize-recover=all"]
    build = subprocess.run(["cc", *flags, "driver.c", f"{name}.c", "-o", "driver", "-lm"], cwd=tmp_path,
                           capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    run = subprocess.run(["./driver"], cwd=tmp_path, capture_output=True, text=True)
    assert run.returncode == 0 and "status" in run.stdout, run.stdout + run.stderr
    assert "runtime error" not in run.stderr and "AddressSanitizer" not in run.stderr


def test_casadi_functions_emit_their_own_c(tmp_path, monkeypatch):
    robot = load_robot(ROBOTS / "puma560.yaml")
    cm = CompiledModel(robot, load_error_model(ROBOTS / "puma560.errors.yaml", robot), "casadi")
    monkeypatch.chdir(tmp_path)  # casadi writes into the working folder
    cm._ca["J_e"].generate("j.c")
    build = subprocess.run(["cc", "-std=c99", "-c", "j.c", "-o", "j.o"], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr


def test_without_a_c_compiler_the_casadi_form_is_used_and_said(monkeypatch, rng):
    from gecgen.runtime import compiled

    robot = load_robot(ROBOTS / "puma560.yaml")
    model = load_error_model(ROBOTS / "puma560.errors.yaml", robot)
    c_model = CompiledModel(robot, model, "c")
    monkeypatch.setattr(compiled, "compiler", lambda: None)
    monkeypatch.delenv("GECGEN_BACKEND")  # the choice left to gecgen
    with pytest.warns(UserWarning, match="no C compiler found"):
        fallback = CompiledModel(robot, model)
    assert fallback.backend == "casadi"
    q, eps = random_q(robot, rng, 4), rng.normal(0, 0.01, (4, robot.n_errors))
    for a, b in zip(fallback.J_e(q, eps), c_model.J_e(q, eps)):
        np.testing.assert_allclose(a, b, atol=1e-12)


def test_urdf_names_cannot_end_the_header_comments(tmp_path):
    """URDF joint names are free text: `*/` in one would close the header's comment and turn the
    rest of the name into code; a line break in one would leave the comment's layout."""
    (tmp_path / "arm.urdf").write_text("""<robot name="arm">
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="shoulder */ int oops; /*" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="elbow&#10;#error line" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>""")
    (tmp_path / "arm.yaml").write_text("name: arm\nurdf: arm.urdf\nbase_link: base\ntip_link: l2\nangle_unit: rad\n"
                                       "targets: {t: [0.1, 0, 0]}\n")
    assert main(["generate", str(tmp_path / "arm.yaml"), "--errors", str(ROBOTS / "constant.errors.yaml"),
                 "-o", str(tmp_path / "out")]) == 0
    header = (tmp_path / "out" / "arm.h").read_text()
    assert "shoulder *\\/ int oops; /\\*" in header and "elbow #error line" in header
    build = subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-c", "arm.c", "-o", "arm.o"],
                           cwd=tmp_path / "out", capture_output=True, text=True)
    assert build.returncode == 0, build.stderr


def test_a_new_model_of_a_robot_prints_only_its_own_terms(tmp_path, monkeypatch):
    """The chain's printed code is kept per robot: a second error model of the same robot builds no
    chain function again, and its files are those a fresh `render` writes, byte for byte."""
    import gecgen.emit as emit
    from gecgen.symbolic.terms import error_model_from_dict
    from gecgen.runtime.compiled import rendered

    monkeypatch.setenv("GECGEN_CACHE", str(tmp_path))
    robot = load_robot(ROBOTS / "puma560.yaml")
    built = []
    original = emit.printed_chain
    monkeypatch.setattr(emit, "printed_chain", lambda r: built.append(r.name) or original(r))
    models = [error_model_from_dict({"default": terms}, robot, "<test>") for terms in (["1"], ["1", "q2"], ["1", "q3"])]
    files = [rendered(robot, m) for m in models]
    assert built == ["puma560"]
    monkeypatch.setattr(emit, "printed_chain", original)
    assert all(f == emit.render(robot, m) for f, m in zip(files, models))


def test_each_model_links_to_the_robots_chain_compiled_once(tmp_path, monkeypatch, rng):
    """The runtime compiles a robot's chain (kinematics, J_e) once, as an object file, and links each
    model's own code to it: three models, one chain object. The linked library computes what the
    one-file build of the same model (`render`, what export writes) computes, bit for bit."""
    import gecgen.runtime.compiled as compiled
    from gecgen.symbolic.terms import error_model_from_dict

    monkeypatch.setenv("GECGEN_CACHE", str(tmp_path / "cache"))
    robot = load_robot(ROBOTS / "puma560.yaml")
    models = [error_model_from_dict({"default": terms}, robot, "<test>") for terms in (["1"], ["1", "q2"], ["1", "q3"])]
    linked = [CompiledModel(robot, m) for m in models]
    assert len(list((tmp_path / "cache").glob("puma560-*.chain.o"))) == 1
    for fname, text in render(robot, models[-1]).items():
        (tmp_path / fname).write_text(text)
    subprocess.run([compiled.compiler(), *compiled.CFLAGS, "puma560.c", "-o", "one.so", "-lm"], cwd=tmp_path,
                   check=True)
    monkeypatch.setattr(compiled, "shared_library", lambda *args: tmp_path / "one.so")
    one = CompiledModel(robot, models[-1])
    q, eps = random_q(robot, rng, 20), rng.normal(0, 1e-3, (20, robot.n_errors))
    c = rng.normal(0, 1e-3, len(models[-1].coefficients))
    for a, b in zip(linked[-1].J_e(q, eps), one.J_e(q, eps)):
        assert np.array_equal(a, b)
    for a, b in zip(linked[-1].model_targets(q, None, None, c, with_H=True),
                    one.model_targets(q, None, None, c, with_H=True)):
        assert np.array_equal(a, b)
    for a, b in zip(linked[-1].compensate(q, None, None, c), one.compensate(q, None, None, c)):
        assert np.array_equal(a, b)
    assert np.array_equal(linked[-1].nominal_targets(q), one.nominal_targets(q))
    assert np.array_equal(linked[-1].eps(q, None, None, c), one.eps(q, None, None, c))
