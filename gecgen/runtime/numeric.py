"""The generated code's entry points evaluated in numpy, from the robot and error model alone.

What `runtime.compiled.CompiledModel` offers with its "numpy" backend while the C of a new model is
compiled: the targets at eps(c) and H_e, J_e, the nominal targets, eps and the basis terms. It needs
no computer algebra, no code generation and no compiler (`model.kinematics`, `model.jacobian`,
`model.term_values`), and agrees with the compiled C to rounding. Shapes as CompiledModel's: q (N,
nq) in m or rad, w (N, 6) in N and N m, aux (N, naux), c (nc,), eps (N, ne); targets (N, nt, 3) in m.
"""
from __future__ import annotations

import numpy as np

from gecgen.model.errors import ErrorModel
from gecgen.model.jacobian import target_jacobian
from gecgen.model.kinematics import target_positions
from gecgen.model.robot import Robot
from gecgen.model.term_values import basis_values


class NumericModel:
    """One robot and error model: eps = sum_k c_k f_term(k) on error error(k) (the generated C's
    coef_error and coef_term), and the chain of `model.kinematics`."""

    def __init__(self, robot: Robot, model: ErrorModel):
        self.robot, self.model = robot, model
        texts = [t.text for t in model.unique_terms()]
        self.coef_error = np.array([k.error for k in model.coefficients], dtype=int)
        self.coef_term = np.array([texts.index(k.term.text) for k in model.coefficients], dtype=int)
        self._last: tuple[list, np.ndarray] | None = None  # (q, w, aux) of the last basis call, and f

    def basis(self, q, w, aux) -> np.ndarray:
        """The distinct basis terms f (N, nf), `model.unique_terms()` order (read-only: the last poses'
        are kept, since a fit evaluates the model at the same poses at every step)."""
        poses = [np.array(a, float, copy=True) if a is not None else None for a in (q, w, aux)]
        if self._last is None or not all(a is b is None or a is not None and b is not None and np.array_equal(a, b)
                                         for a, b in zip(poses, self._last[0])):
            f = basis_values(self.robot, self.model, q, w, aux)
            f.setflags(write=False)
            self._last = poses, f
        return self._last[1]

    def _eps(self, f: np.ndarray, c: np.ndarray) -> np.ndarray:
        eps = np.zeros((len(f), self.robot.n_errors))
        np.add.at(eps.T, self.coef_error, (f[:, self.coef_term] * c).T)
        return eps

    def eps(self, q, w, aux, c) -> np.ndarray:
        """Generalized errors (N, ne) at each pose for coefficients c (nc,)."""
        return self._eps(self.basis(q, w, aux), c)

    def model_targets(self, q, w, aux, c, with_H: bool = False):
        """Target positions (N, nt, 3) at eps(c), and H_e (N, 3 nt, nc) = J_e's column of each
        coefficient's error times its basis term, if asked."""
        f = self.basis(q, w, aux)
        eps = self._eps(f, c)
        if not with_H:
            return target_positions(self.robot, q, eps)
        p, J = target_jacobian(self.robot, q, eps)
        return p, J[:, :, self.coef_error] * f[:, None, self.coef_term]

    def J_e(self, q, eps):
        """Target positions (N, nt, 3) and J_e (N, 3 nt, ne) at per-pose errors eps (N, ne)."""
        return target_jacobian(self.robot, q, eps)

    def nominal_targets(self, q) -> np.ndarray:
        """Target positions (N, nt, 3) of the nominal model."""
        return target_positions(self.robot, q)
