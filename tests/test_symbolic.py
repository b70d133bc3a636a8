"""J_e and H_e against central finite differences of the exact nonlinear chain (model.kinematics)."""
import numpy as np
import pytest
from conftest import random_q

from gecgen.model.kinematics import target_positions
from gecgen.runtime.compiled import CompiledModel
from gecgen.symbolic.chain import jacobian_function


def fd_jacobian(robot, q, eps, h=1e-6):
    J = np.zeros((3 * len(robot.targets), robot.n_errors))
    for k in range(robot.n_errors):
        e1, e2 = eps.copy(), eps.copy()
        e1[k] += h
        e2[k] -= h
        J[:, k] = ((target_positions(robot, q, e1) - target_positions(robot, q, e2)) / (2 * h)).ravel()
    return J


@pytest.mark.parametrize("scale", [0.0, 0.02])
def test_J_e_symbolic_matches_finite_differences(shipped, rng, scale):
    robot, _ = shipped
    fn = jacobian_function(robot)
    for _ in range(2):
        q, eps = random_q(robot, rng), rng.normal(0, scale, robot.n_errors)
        out = fn.evaluate(q=q, eps=eps)
        np.testing.assert_allclose(out["p"], target_positions(robot, q, eps).ravel(), atol=1e-14)
        np.testing.assert_allclose(out["J"].reshape(-1, robot.n_errors), fd_jacobian(robot, q, eps), atol=1e-8)


def test_H_e_is_J_e_times_basis_and_matches_finite_differences(shipped, rng):
    robot, model = shipped
    cm = CompiledModel(robot, model)
    q, w = random_q(robot, rng, 3), rng.normal(0, 100, (3, 6))
    c = rng.normal(0, 1e-4, len(model.coefficients))
    p, H = cm.model_targets(q, w, None, c, with_H=True)
    eps = cm.eps(q, w, None, c)
    h = 1e-7
    for k in rng.choice(len(c), size=min(25, len(c)), replace=False):
        c1, c2 = c.copy(), c.copy()
        c1[k] += h
        c2[k] -= h
        fd = (cm.model_targets(q, w, None, c1) - cm.model_targets(q, w, None, c2)) / (2 * h)
        # H_e at eps(c) is exact where the error is linear in c; finite differences agree to O(h^2)
        np.testing.assert_allclose(H[:, :, k], fd.reshape(3, -1), atol=1e-7 * max(1, np.abs(fd).max()))
    np.testing.assert_allclose(p, target_positions(robot, q, eps), atol=1e-14)
