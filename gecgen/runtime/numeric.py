"""The generated code's entry points evaluated in numpy, from the robot and error model alone.

What `runtime.compiled.CompiledModel` offers with its "numpy" backend while the C of a new model is
compiled: the targets at eps(c) and H_e, J_e, the nominal targets, eps and the basis terms. It needs
no computer algebra, no code generation and no compiler (`model.kinematics`, `model.jacobian`,
`model.term_values`), and agrees with the compiled C to rounding. Shapes as CompiledModel's: q (N,
nq) in m or rad, w (N, 6) in N and N m, aux (N, naux), c (nc,), eps (N, ne); targets (N, nt, 3) in m.

Compensation (`NumericModel.correct`) is the generated C's compensate_bounded step for step (the
same residual, Gauss-Newton steps, backtracking, damping ladder and status codes), one command at a
time in Python: for a few commands (an example program's) while the C is built, not for programs.
"""
from __future__ import annotations

import numpy as np

from gecgen.model.errors import ErrorModel
from gecgen.model.jacobian import target_jacobian
from gecgen.model.kinematics import chain_frames, constant, target_positions
from gecgen.model.loads import signal_values
from gecgen.model.robot import Robot
from gecgen.model.term_values import basis_values

#: status codes of compensation: the generated C's GECGEN_ codes
OK, NOT_CONVERGED, SINGULAR, OUTSIDE_LIMITS, NONFINITE, BOUNDED = range(6)
#: the generated header's defaults (GECGEN_NONLINEAR_SHARE, GECGEN_NEAR_SINGULAR) and the C's STALL_STEPS:
#: a correction is justified to this share of the error; a singular value (m per rad) below this is
#: near a singular posture; this many Newton steps in a row under 0.1 % end a solve
NONLINEAR_SHARE, NEAR_SINGULAR, STALL_STEPS = 0.25, 0.01, 20


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

    # -- compensation (the generated C's place/solve, see its comments for the why) ---------------------
    def correct(self, q_cmd, w, aux, c, max_iter: int = 50, tol: float = 1e-11, branch: int = 0, bound=None):
        """As `CompiledModel.correct`: corrected joint commands (N, nq), status codes (N,) and residuals
        (N,) (m, 1 rad as 1 m), the C's numbers to rounding."""
        q_cmd = np.atleast_2d(np.asarray(q_cmd, float))
        N = len(q_cmd)
        w = np.zeros((N, 6)) if w is None else np.broadcast_to(np.asarray(w, float), (N, 6))
        aux = None if aux is None else np.broadcast_to(np.asarray(aux, float), (N, len(self.model.aux)))
        bound = None if bound is None else np.broadcast_to(np.asarray(bound, float), (self.robot.n,))
        rows = self.robot.task_rows(branch)  # the rule the generated C was printed with
        out, status, residual = np.empty_like(q_cmd), np.empty(N, dtype=np.intc), np.empty(N)
        for i in range(N):
            args = (q_cmd[i], w[i], None if aux is None else aux[i], np.asarray(c, float), max_iter, tol, bound, branch)
            status[i], out[i], residual[i] = self._place(*args, 6)
            if rows == 3 and status[i] not in (OK, NONFINITE):
                status[i], out[i], residual[i] = self._place(*args, 3)
        return out, status, residual

    def _pose_residual(self, q, w, aux, L, c, Tn, rows, branch):
        """(residual norm, r (6,), Jq (6, nq)) of the modelled tool at q against the wanted pose Tn."""
        robot = self.robot
        f = basis_values(robot, self.model, q[None], w[None], None if aux is None else aux[None], L[None])
        eps = self._eps(f, c)
        _, post, tools = chain_frames(robot, q[None], eps)
        T = tools[branch][0]
        Jq = np.zeros((6, robot.n))
        moving = self.robot.own_frames(branch)
        for i, (joint, (terms, _)) in enumerate(zip(robot.chain, robot.drives()), start=1):
            if i not in moving:
                continue
            F = post[robot.parent(i)][0] @ constant(joint.pre)
            a = F[:3, :3] @ np.array([float(x) for x in joint.axis])
            col = np.concatenate([a, np.zeros(3)] if joint.kind == "P" else [np.cross(a, T[:3, 3] - F[:3, 3]), a])
            for k, mult in terms:
                Jq[:, k] += float(mult) * col
        r = np.empty(6)
        r[:3] = Tn[:3, 3] - T[:3, 3]
        trace = 0.0
        for i in range(3):
            u, v = (i + 1) % 3, (i + 2) % 3
            r[3 + i] = sum(0.5 * (T[u, k] * Tn[v, k] - T[v, k] * Tn[u, k]) for k in range(3))
            trace += sum(T[i, k] * Tn[i, k] for k in range(3))
        position = np.hypot(np.hypot(r[0], r[1]), r[2])
        if rows == 3:
            Jq[3:], r[3:] = 0.0, 0.0
            return position, r, Jq
        turn = np.hypot(np.hypot(r[3], r[4]), r[5])
        return np.hypot(position, 2.0 - turn if trace < 1.0 else turn), r, Jq

    def _solve(self, q_cmd, w, aux, L, c, Tn, rows, P, bound, max_iter, tol, branch):
        """The C's solve: (1 converged, 0 stopped short, -1 overflowed; q, r, Jq, norm, held, steps)."""
        q = q_cmd.copy()
        held = np.zeros(len(q), bool) if bound is None else bound == 0.0
        norm, r, Jq = self._pose_residual(q, w, aux, L, c, Tn, rows, branch)
        merit, stalled, it = norm * norm, 0, 0
        while True:
            if not np.isfinite(norm):
                return -1, q, r, Jq, norm, held, it
            if norm <= tol or it == max_iter or stalled == STALL_STEPS:
                return int(norm <= tol), q, r, Jq, norm, held, it
            dq = _gauss_newton_step(Jq, r, P, q - q_cmd, held)
            alpha = 1.0
            for _ in range(30):
                q_try = q + alpha * dq
                clipped = np.zeros(len(q), bool) if bound is None else np.abs(q_try - q_cmd) >= bound
                if clipped.any():  # a bound clips the trial, and holds the joint once the trial is taken
                    q_try[clipped] = (q_cmd + np.where(q_try > q_cmd, bound, -bound))[clipped]
                norm_try, r_try, J_try = self._pose_residual(q_try, w, aux, L, c, Tn, rows, branch)
                merit_try = norm_try * norm_try + (0.0 if P is None else (q_try - q_cmd) @ P @ (q_try - q_cmd))
                if merit_try < merit:
                    break
                alpha *= 0.5
            if not merit_try < merit:
                return (0 if np.isfinite(merit_try) else -1), q, r, Jq, norm, held, it
            q, r, Jq = q_try, r_try, J_try
            held = held | clipped
            stalled = stalled + 1 if merit_try > 0.998001 * merit else 0
            merit, norm, it = merit_try, norm_try, it + 1

    def _place(self, q_cmd, w, aux, c, max_iter, tol, bound, branch, rows):
        """The C's place: (status, q_out, residual) for one command placing `rows` of the tool's pose."""
        robot = self.robot
        nonfinite = NONFINITE, q_cmd.copy(), np.inf
        if not (np.isfinite(q_cmd).all() and np.isfinite(w).all() and (aux is None or np.isfinite(aux).all())
                and np.isfinite(c).all() and np.isfinite(tol) and tol > 0.0 and max_iter >= 0):
            return nonfinite
        if bound is not None and not (bound >= 0.0).all():
            return nonfinite
        Tn = chain_frames(robot, q_cmd[None])[2][branch][0]
        names = self.model.load_signals(robot)
        L = signal_values(robot, q_cmd[None], w[None], names)[0] if names else np.zeros(0)
        norm0, r0, J0 = self._pose_residual(q_cmd, w, aux, L, c, Tn, rows, branch)
        if not np.isfinite(norm0):
            return nonfinite
        ntask = min(int((J0 != 0.0).any(axis=0).sum()), rows)
        lam, V = np.linalg.eigh(J0.T @ J0)
        order = np.argsort(-lam, kind="stable")
        smallest = np.sqrt(max(lam[order[ntask - 1]], 0.0)) if ntask else 0.0
        status, steps, q_out = NOT_CONVERGED, 0, q_cmd
        norm, r, held = np.inf, r0, np.zeros(robot.n, bool)
        if smallest >= NEAR_SINGULAR:
            got, q_out, r, _, norm, held, steps = self._solve(q_cmd, w, aux, L, c, Tn, rows, None, bound, max_iter,
                                                              tol, branch)
            if got < 0:
                return nonfinite
            status = OK if got else NOT_CONVERGED
        if smallest < NEAR_SINGULAR or (max_iter > 0 and not _justified(r0, J0, lam, V, 0.0, r, q_out, q_cmd)):
            status = NOT_CONVERGED
            for rung in range(10):
                sigma = NEAR_SINGULAR * float(1 << rung)
                P = (V * np.where(sigma * sigma - lam > 0.0, sigma * sigma - lam, 0.0)) @ V.T
                got, q_out, r, _, norm, held, _ = self._solve(q_cmd, w, aux, L, c, Tn, rows, P, bound, max_iter, tol,
                                                              branch)
                if got < 0:
                    return nonfinite
                if _justified(r0, J0, lam, V, sigma, r, q_out, q_cmd):
                    status = OK if got else SINGULAR
                    break
        if not np.isfinite(q_out).all():
            return nonfinite
        if bound is not None and (held & ((bound > 0.0) | (status != OK))).any():
            return BOUNDED, q_out, norm
        if status != OK:
            return status, q_out, norm
        lower = np.array([float(j.lower) for j in robot.joints])
        upper = np.array([float(j.upper) for j in robot.joints])
        return (OUTSIDE_LIMITS if ((q_out < lower) | (q_out > upper)).any() else OK), q_out, norm


def _gauss_newton_step(Jq, r, P, d, held) -> np.ndarray:
    """The C's gauss_newton_step: the minimum-norm solution of (Jq^T Jq + P) dq = Jq^T r - P d over
    the eigenvalues above 1e-12 of the largest, held joints not moving."""
    free = ~held
    g = Jq.T @ r - (0.0 if P is None else P @ d)
    A = Jq.T @ Jq + (0.0 if P is None else P)
    g, A = np.where(free, g, 0.0), A * np.outer(free, free)
    lam, V = np.linalg.eigh(A)
    use = lam > 1e-12 * max(lam.max(), 0.0)
    return V[:, use] @ ((V[:, use].T @ g) / lam[use])


def _justified(r0, J0, lam, V, sigma, r, q, q_cmd) -> bool:
    """The C's justified: what the correction q - q_cmd does to the tool is J0's first-order
    prediction, and it is the first-order correction damped at sigma, each to NONLINEAR_SHARE."""
    dq = q - q_cmd
    miss = r0 - r - J0 @ dq
    eig = np.where(lam < sigma * sigma, sigma * sigma, lam)
    use = eig > 1e-12 * lam.max()
    first = V[:, use] @ ((V[:, use].T @ (J0.T @ r0)) / eig[use])
    share = NONLINEAR_SHARE * NONLINEAR_SHARE
    return bool(miss @ miss <= share * (r0 @ r0) and (dq - first) @ (dq - first) <= share * (first @ first))
