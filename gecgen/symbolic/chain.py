"""The symbolic DH chain with six generalized errors per frame, and its Jacobians.

Structure instead of brute-force differentiation: the error `E_j` enters the chain at frame j
only, so its effect on a target P is a rigid motion of everything after frame j. With W_j' the
world pose of frame j before its error and o_j the origin after the error translation,

    dP/d(ex, ey, ez)_j = columns of R(W_j')                     (translations)
    dP/d(es, er, ep)_j = a x (P - o_j),  a = R(W_j') y,  R(W_j') Ry(es) z,  R(W_j) x

(the rotation axes of Trans * RotY * RotZ * RotX in the world). This is the exact derivative at
any error values, so identification can iterate. One forward pass gives every column; the
`Builder` shares all intermediates. A coupled joint's frame is a frame like any other (its value
sum_k m_k q_k + o only enters its motion), so J_e needs nothing more; in the joint Jacobian its
column adds to each reading k's times m_k (the chain rule).
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from gecgen.model.robot import ERROR_NAMES, Elementary, Robot
from gecgen.symbolic.exact import sympy_robot
from gecgen.symbolic.parse import joint_symbols
from gecgen.symbolic.program import Builder, Function


@dataclass(frozen=True)
class Pose:
    """A rigid transform as rotation rows R (3x3 nested tuples) and origin p (3)."""

    R: tuple
    p: tuple

    def col(self, k: int) -> tuple:
        return tuple(self.R[i][k] for i in range(3))


IDENTITY = Pose(((1, 0, 0), (0, 1, 0), (0, 0, 1)), (0, 0, 0))


def _elementary(op: Elementary) -> sp.Matrix:
    kind, v = op
    if kind == "H":
        return sp.Matrix(v)
    M = sp.eye(4)
    if kind[0] == "T":
        M["xyz".index(kind[1]), 3] = v
        return M
    c, s = sp.cos(v), sp.sin(v)
    i, j = [(1, 2), (2, 0), (0, 1)]["xyz".index(kind[1])]
    M[i, i], M[i, j], M[j, i], M[j, j] = c, -s, s, c
    return M


def constant_pose(ops: tuple[Elementary, ...]) -> Pose:
    """Exact product of constant elementary transforms (exact zeros survive)."""
    M = sp.eye(4)
    for op in ops:
        M = M * _elementary(op)
    return Pose(tuple(tuple(M[i, j] for j in range(3)) for i in range(3)), tuple(M[i, 3] for i in range(3)))


def compose(b: Builder, A: Pose, B: Pose) -> Pose:
    R = tuple(tuple(b.let(sum(A.R[i][k] * B.R[k][j] for k in range(3))) for j in range(3)) for i in range(3))
    p = tuple(b.let(sum(A.R[i][k] * B.p[k] for k in range(3)) + A.p[i]) for i in range(3))
    return Pose(R, p)


def apply(b: Builder, A: Pose, v, point: bool = True) -> tuple:
    return tuple(b.let(sum(A.R[i][k] * v[k] for k in range(3)) + (A.p[i] if point else 0)) for i in range(3))


def cross(b: Builder, u, v) -> tuple:
    return (b.let(u[1] * v[2] - u[2] * v[1]), b.let(u[2] * v[0] - u[0] * v[2]), b.let(u[0] * v[1] - u[1] * v[0]))


def _rot(axis: int, c, s) -> tuple:
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = [[1 if r == k == axis else 0 for k in range(3)] for r in range(3)]
    R[i][i], R[i][j], R[j][i], R[j][j] = c, -s, s, c
    return tuple(tuple(r) for r in R)


def motion(b: Builder, axis, kind: str, q) -> Pose:
    """M(q) about/along the exact unit axis u (Rodrigues for a general revolute axis)."""
    u = axis
    if kind == "P":
        return Pose(IDENTITY.R, tuple(b.let(q * a) for a in u))
    c, s = b.let(sp.cos(q)), b.let(sp.sin(q))
    for k in range(3):
        if u[k] in (1, -1) and all(u[m] == 0 for m in range(3) if m != k):
            return Pose(_rot(k, c, u[k] * s), IDENTITY.p)
    v = b.let(1 - c)
    K = ((0, -u[2], u[1]), (u[2], 0, -u[0]), (-u[1], u[0], 0))
    R = tuple(tuple(b.let((c if i == j else 0) + s * K[i][j] + v * u[i] * u[j]) for j in range(3)) for i in range(3))
    return Pose(R, IDENTITY.p)


def error_pose(b: Builder, e: tuple) -> tuple[Pose, tuple]:
    """E = Trans(ex,ey,ez) RotY(es) RotZ(er) RotX(ep), and RotY(es) z (the er axis in frame j')."""
    cs = [(b.let(sp.cos(a)), b.let(sp.sin(a))) for a in e[3:]]
    Ry, Rz, Rx = _rot(1, *cs[0]), _rot(2, *cs[1]), _rot(0, *cs[2])
    RyRz = compose(b, Pose(Ry, IDENTITY.p), Pose(Rz, IDENTITY.p))
    R = compose(b, RyRz, Pose(Rx, IDENTITY.p))
    return Pose(R.R, tuple(e[:3])), (cs[0][1], 0, cs[0][0])


@dataclass
class Chain:
    """World poses along the chain (or tree): frame j before (pre) and after (post) its error, joint
    axes, and the tool of each branch."""

    pre: list[Pose]
    post: list[Pose]
    er_axis: list[tuple]  # R(W_j') Ry(es_j) z
    joint_frames: list[Pose]  # world pose in which joint i's motion axis is expressed
    tools: list[Pose]

    @property
    def tool(self) -> Pose:
        """The tool (on a tree, the first branch's)."""
        return self.tools[0]


def joint_values(b: Builder, robot: Robot, q) -> list:
    """Every frame's joint value: its reading, or for a coupled joint the sum of multiplier * q_k
    plus its offset."""
    return [q[terms[0][0]] if joint.coupling is None else b.let(sum(m * q[k] for k, m in terms) + o)
            for joint, (terms, o) in zip(robot.chain, robot.drives())]


def build_chain(b: Builder, robot: Robot, q, eps) -> Chain:
    """Forward pass; `eps` is a flat sequence of 6(m+1) symbols, or None for the nominal chain."""
    robot = sympy_robot(robot)
    W = constant_pose(robot.base)
    pre, post, er_axis, joint_frames = [], [], [], []
    v = joint_values(b, robot, q)
    for j in range(robot.n_frames + 1):
        if j > 0:
            joint, W = robot.chain[j - 1], post[robot.parent(j)]
            F = compose(b, W, constant_pose(joint.pre)) if joint.pre else W
            joint_frames.append(F)
            W = compose(b, compose(b, F, motion(b, joint.axis, joint.kind, v[j - 1])), constant_pose(joint.post)) \
                if joint.post else compose(b, F, motion(b, joint.axis, joint.kind, v[j - 1]))
        pre.append(W)
        if eps is not None:
            E, z_er = error_pose(b, tuple(eps[6 * j:6 * j + 6]))
            er_axis.append(apply(b, W, z_er, point=False))
            W = compose(b, W, E)
        post.append(W)
    tools = [compose(b, post[tip], constant_pose(tool)) if tool else post[tip] for tip, tool in robot.tips()]
    return Chain(pre, post, er_axis, joint_frames, tools)


def error_symbols(robot: Robot) -> tuple[sp.Symbol, ...]:
    return tuple(sp.Symbol(f"eps_{i}_{e}", real=True) for i in range(robot.n_frames + 1) for e in ERROR_NAMES)


def _targets(b: Builder, robot: Robot, chain: Chain) -> list[tuple]:
    return [apply(b, chain.tools[robot.branch_of(name)], t) for name, t in robot.targets.items()]


def _suffix(robot: Robot, branch: int) -> str:
    return f"_{robot.branches[branch].name}" if robot.branches else ""


def fk_function(robot: Robot, branch: int = 0) -> Function:
    """Nominal tool pose of a branch (the tool on a serial chain)."""
    b, q = Builder(), joint_symbols(robot)
    T = build_chain(b, robot, q, None).tools[branch]
    out = [e for i in range(3) for e in (*T.R[i], T.p[i])] + [0, 0, 0, 1]
    return b.function("fk" + _suffix(robot, branch), "Nominal tool pose T (4x4 row-major) at joints q (m/rad).",
                      {"q": q}, {"T": out})


def targets_function(robot: Robot) -> Function:
    b, q, eps = Builder(), joint_symbols(robot), error_symbols(robot)
    P = _targets(b, robot, build_chain(b, robot, q, eps))
    return b.function("targets", "World positions p (n_targets x 3, m) of the targets at joints q and "
                      "generalized errors eps.", {"q": q, "eps": eps}, {"p": [x for t in P for x in t]})


def jacobian_function(robot: Robot) -> Function:
    """J_e: d(target positions)/d(eps), (3 n_targets) x 6(m+1) row-major, at any eps."""
    b, q, eps = Builder(), joint_symbols(robot), error_symbols(robot)
    chain = build_chain(b, robot, q, eps)
    P = _targets(b, robot, chain)
    ne = robot.n_errors
    J = [[0] * ne for _ in range(3 * len(P))]
    paths = [set(robot.path(tip)) for tip, _ in robot.tips()]
    on_path = [paths[robot.branch_of(name)] for name in robot.targets]  # the frames that move each target
    for j in range(robot.n_frames + 1):
        Wp, Wq = chain.pre[j], chain.post[j]
        axes = (Wp.col(1), chain.er_axis[j], Wq.col(0))
        for k, Pk in enumerate(P):
            if j not in on_path[k]:
                continue
            d = tuple(b.let(Pk[i] - Wq.p[i]) for i in range(3))
            cols = [Wp.col(0), Wp.col(1), Wp.col(2)] + [cross(b, a, d) for a in axes]
            for c, col in enumerate(cols):
                for i in range(3):
                    J[3 * k + i][6 * j + c] = col[i]
    return b.function("J_e", "Target positions p (n_targets x 3) and the identification Jacobian "
                      "J = dp/deps (3 n_targets x 6(n+1), row-major) at joints q and errors eps.",
                      {"q": q, "eps": eps}, {"p": [x for t in P for x in t], "J": [x for row in J for x in row]})


def tool_jacobian_function(robot: Robot, branch: int = 0) -> Function:
    """Tool pose with errors and its geometric Jacobian in q ([v; w], 6 x n) for compensation; on a
    tree, a branch's tool and the columns of its own joints only (the trunk and the other branches
    hold their commands: moving the trunk would move every other branch too).

    The q-dependence of eps through the basis terms is left out: it changes the step, not
    the fixed point, and the errors are small, so Newton still converges.
    """
    robot = sympy_robot(robot)
    b, q, eps = Builder(), joint_symbols(robot), error_symbols(robot)
    chain = build_chain(b, robot, q, eps)
    T = chain.tools[branch]
    Jq = [[0] * robot.n for _ in range(6)]
    tips = [tip for tip, _ in robot.tips()]
    shared = {f for k, tip in enumerate(tips) if k != branch for f in robot.path(tip)}
    moving = set(robot.path(tips[branch])) - shared
    for i, (joint, F, (terms, _)) in enumerate(zip(robot.chain, chain.joint_frames, robot.drives()), start=1):
        if i not in moving:
            continue
        a = apply(b, F, joint.axis, point=False)
        if joint.kind == "P":
            v, w = a, (0, 0, 0)
        else:
            v, w = cross(b, a, tuple(b.let(T.p[m] - F.p[m]) for m in range(3))), a
        for i, mult in terms:
            for r, x in enumerate((*v, *w)):
                Jq[r][i] = x if joint.coupling is None and Jq[r][i] == 0 else b.let(Jq[r][i] + mult * x)
    out = [e for i in range(3) for e in (*T.R[i], T.p[i])] + [0, 0, 0, 1]
    return b.function("tool_jacobian" + _suffix(robot, branch), "Tool pose T (4x4 row-major) with errors eps and "
                      "its geometric Jacobian Jq = [v; w] (6 x n row-major) in the joints.", {"q": q, "eps": eps},
                      {"T": out, "Jq": [x for row in Jq for x in row]})
