"""Load signals: the torques that the measured wrench and gravity put on each joint, as basis terms.

A compliant joint (harmonic drive, belt, long gear train) or one with play turns with the load it
carries. These functions of the term language give that load from the joints and the wrench, so an
error model can carry `er: ["1", "gravity_torque(q6)"]` (a joint stiffness) or
`er: ["sign(gravity_torque(q6))"]` (free play):

| spelling | value (J a joint name or q<k>) |
|---|---|
| `wrench_torque(J)` | (J(q)^T w)_J: the torque (N m; N for a prismatic joint) of the measured wrench on joint J |
| `gravity(J, r)` | column r of joint J's static gravity regressor, reduced to independent columns (no masses needed) |
| `gravity(J)` | shorthand for `gravity(J, 1) .. gravity(J, r_J)` |
| `gravity_torque(J)` | the static gravity torque on joint J from a URDF's masses, tau = -dV/dq (N m or N) |
| `gravity_load(F, c)` | component c (fx fy fz mx my mz) of the gravity wrench frame F carries, URDF masses (N, N m) |
| `gravity(F, c, r)` | column r of that component's regressor, reduced to independent columns (no masses needed) |
| `gravity(F, c)` | shorthand for `gravity(F, c, 1) .. gravity(F, c, r_Fc)` |
| `wrench_load(F, c)` | component c of the measured wrench that frame F carries (N, N m) |

Joint loads (the first four) belong to a *reading*: by virtual work through the couplings, the load
that the controller's joint J feels. Frame loads (the last four) belong to a *frame* F of the chain
or tree, whatever moves it: an actuated, coupled or passive joint's frame, or the base (0). F is
written as the frame's joint name (a passive joint's too), a reading q<k> (the frame of its own
joint) or the frame's number. The wrench is the one everything after frame F's generalized errors
exerts across them: the weight of every body rigid with frame F or hanging from it (every branch),
and the measured wrench when the sensor hangs there, as force and moment about frame F's origin, in
frame F's axes. So each of the frame's six errors has its matching component: a rotation about
frame x (`ep`) with `mx`, `es` with `my`, `er` with `mz`, a translation along x with `fx`, ...;
the component about a joint's own axis is its torque, the two others the moments across the axis
that tilt a bearing or bend a link. It equals minus what pinocchio's static RNEA calls the joint's
transmitted force (`data.f`) on a URDF robot, and minus the derivative of the potential energy in
each of frame F's errors.

The canonical spelling (a Term's text, and the names `CompiledModel.load_signals` returns) writes
the joint as q<k> and the frame as its number, with no spaces: `wrench_torque(q2)`, `gravity(q2,1)`,
`gravity_torque(q6)`, `gravity_load(4,mx)`, `gravity(4,mx,2)`, `wrench_load(4,mx)`. In
sympy each is a real Symbol of that name; the generated code computes it from the nominal chain
(`gecgen.symbolic.loads`). This module decides which signals a robot supports, and the constants
they need: which regressor columns are independent (a numerical rank test at generic poses, fixed
seed, so the emitted columns are fixed) and the masses each frame carries.

The gravity regressor of joint J: a unit mass at the origin of frame i (i >= J), and a unit first
moment of mass along each of frame i's axes, produce the torques

    revolute:   (p_i - o_J) . u,   R_i[:, k] . u   with u = g x a_J   (a . (r x m g) = m r . (g x a))
    prismatic:  a_J . g,           0

(a_J, o_J the joint's world axis and a point on it, g the robot file's `gravity`). Every body the
joint carries is rigid with one frame i >= J (fixed URDF links, the tool, branches off the chain
with their joints held at zero), so its mass and first moment are a combination of frame i's four
columns: these 4 (n - J + 1) candidates span joint J's row of the full regressor restricted to the
masses and first moments, and the rank test keeps the first independent ones in that order.

The frame wrench's regressor: per frame k that frame F carries, a unit mass at k's origin gives the
force g and the moment (p_k - o_F) x g, a unit first moment along k's axis j the moment
R_k[:, j] x g, each turned into frame F's axes (R_F^T); per component the rank test keeps the first
independent ones, as for the joints.

A joint with mimic joints moves several frames: by virtual work its load is the sum over the
frames k it moves of dq_k/dq_J times frame k's load (`joint_columns`, `frame_wrench_torque`), so
each of its gravity columns is that sum for one carried frame, from its first moved frame on.
A link off the chain that a mimic joint moves with a chain joint is rigid with no frame: its mass
is refused for gravity_torque (`gecgen gravity` walks the URDF tree and carries it).
"""
from __future__ import annotations

import ast
import re
from dataclasses import dataclass

import numpy as np

from gecgen.model.exact import exact_norm
from gecgen.model.kinematics import constant, frames
from gecgen.model.robot import WRENCH, Robot
from gecgen.model.urdf import load_mass_tree
from gecgen.model.validation import ModelError, excerpt

LOAD_FUNCTIONS = ("wrench_torque", "gravity", "gravity_torque", "gravity_load", "wrench_load")
#: a candidate column is independent when its part outside the earlier ones exceeds this fraction of
#: the joint's largest column (the redundancy analysis's exact-dependency level; see _independent)
RANK_TOL = 1e-7
#: the rank test's generic poses: uniform within the joint limits (clipped to +-pi), fixed seed
SEED, MIN_POSES = 20240611, 64


def dot(u, v):
    return sum(x * y for x, y in zip(u, v))


def cross3(u, v) -> tuple:
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


def regressor_columns(let, kind: str, a, o, carried, g) -> list:
    """Candidate gravity-regressor columns of one joint, four per carried frame, in the order
    [unit mass at the origin, unit first moment along x, y, z]: N m (N for kind "P") per kg and
    per kg m. a, o: the joint's world axis and a point on it; carried: (R rows, p) world poses of
    frames J..n; g: gravity (m/s^2, world). Entries are sympy expressions (let = Builder.let) or
    numpy arrays over poses (let = identity): one formula for the rank test and the emitted code."""
    if kind == "P":
        along = let(dot(a, g))
        return [c for _ in carried for c in (along, 0, 0, 0)]
    u = tuple(let(x) for x in cross3(g, a))
    cols = []
    for R, p in carried:
        cols.append(let(dot([p[k] - o[k] for k in range(3)], u)))
        cols += [let(dot([R[k][j] for k in range(3)], u)) for j in range(3)]
    return cols


def joint_columns(let, robot: Robot, J: int, axes, origins, carried, g, numeric: bool = False) -> list:
    """Candidate gravity-regressor columns of joint variable J (1-based): per carried frame from the
    first frame J moves to the last, the sum over the frames k it moves of multiplier times frame
    k's `regressor_columns` (zero for frames k does not carry: those before it, and on a tree those
    on other branches). axes, origins: world axis and a point on it
    of every frame's joint (1..m); carried: (R, p) of frames 0..m; let, g as for regressor_columns,
    `numeric` with numpy arrays (the multipliers then as floats)."""
    moved = [(k, float(m) if numeric else m) for k, m in robot.driven(J - 1)]
    first = moved[0][0]
    total: list = []
    for k, mult in moved:
        subtree = set(robot.subtree(k))  # what frame k's joint carries (frames k..m on a chain)
        own = iter(regressor_columns(let, robot.chain[k - 1].kind, axes[k - 1], origins[k - 1],
                                     [carried[i] for i in sorted(subtree)], g))
        cols = [c for i in range(first, robot.n_frames + 1) for c in ([next(own) for _ in range(4)]
                                                                       if i in subtree else [0] * 4)]
        cols = cols if mult == 1 else [let(mult * c) for c in cols]
        total = [let(a + c) for a, c in zip(total, cols)] if total else cols
    return total


def frame_wrench_torque(let, kind: str, a, o, sensor_p, force, moment):
    """The measured wrench's load on one frame's joint (axis a, point o, world): a . f along a
    prismatic joint, a . (m + (p_s - o) x f) about a revolute one (N or N m)."""
    if kind == "P":
        return dot(a, force)
    lever = tuple(let(sensor_p[k] - o[k]) for k in range(3))
    return dot(a, [moment[k] + c for k, c in enumerate(cross3(lever, force))])


def local(let, R, v) -> list:
    """The world vector v in the axes of a frame whose world rotation has rows R: R^T v."""
    return [let(sum(R[k][c] * v[k] for k in range(3))) for c in range(3)]


def frame_wrench_columns(let, R, o, carried, g) -> list[list]:
    """Candidate regressor columns of the gravity wrench one frame carries, per component fx..mz (six
    lists), four per carried frame as in `regressor_columns`: N per kg for the forces, N m per kg
    and per kg m for the moments, in the frame's axes about its origin. R (rows), o: the frame's world
    rotation and origin; carried: (R rows, p) world poses of the frames it carries, itself first;
    let, g as for regressor_columns."""
    weight = local(let, R, g)
    cols: list[list] = [[] for _ in WRENCH]
    for Rk, p in carried:
        moments = [local(let, R, cross3([p[k] - o[k] for k in range(3)], g))] + \
                  [local(let, R, cross3([Rk[k][j] for k in range(3)], g)) for j in range(3)]
        for c in range(3):
            cols[c] += [weight[c], 0, 0, 0]
            cols[3 + c] += [m[c] for m in moments]
    return cols


def frame_wrench_load(let, R, o, sensor_p, force, moment) -> list:
    """The measured wrench (world force and moment about the sensor's origin sensor_p) as a frame
    (rotation rows R, origin o) carries it: force and moment about o in its axes, fx..mz (N, N m)."""
    lever = tuple(let(sensor_p[k] - o[k]) for k in range(3))
    return local(let, R, force) + local(let, R, [moment[k] + c for k, c in enumerate(cross3(lever, force))])


@dataclass(frozen=True)
class Signal:
    """One load signal: its canonical name, kind (one of LOAD_FUNCTIONS, or "frame_gravity" for a
    column of a frame wrench's regressor), joint (1-based; joint loads) or frame and component
    (0..5, fx..mz; frame loads) and, for the regressors, the index of its column among the
    candidates."""

    name: str
    kind: str
    joint: int = -1
    column: int = -1
    frame: int = -1
    component: int = -1


@dataclass(frozen=True)
class LoadCatalog:
    """The load signals one robot supports, in the order the generated `NAME_loads` returns them:
    wrench_torque by joint, gravity by joint and column, gravity_torque by joint.

    params[i]: (mass kg, first moment kg m in frame i's coordinates) of everything rigid with frame
    i, flat as 4 numbers (URDF robots; empty otherwise). why_not: canonical name of a spelling
    that is refused -> the reason (gravity(qJ) stands for the joint's gravity columns)."""

    signals: tuple[Signal, ...]
    params: tuple[tuple[float, ...], ...]
    why_not: dict

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.signals]

    def by_name(self, name: str) -> Signal | None:
        return next((s for s in self.signals if s.name == name), None)

    def gravity_rank(self, joint: int) -> int:
        return sum(1 for s in self.signals if s.kind == "gravity" and s.joint == joint)

    def frame_rank(self, frame: int, component: int) -> int:
        return sum(1 for s in self.signals
                   if s.kind == "frame_gravity" and (s.frame, s.component) == (frame, component))

    def describe(self, s: Signal, robot: Robot) -> str:
        """What a signal is, with its unit, in one line (the generated header lists them)."""
        if s.joint < 0:
            if s.kind == "frame_gravity":
                k, at = s.column % 4, robot.subtree(s.frame)[s.column // 4]
                load = "a unit mass at the origin" if k == 0 else f"a unit first moment along the {'xyz'[k - 1]} axis"
                what, per = f"gravity wrench of {load} of frame {at}", " per kg" + " m" * (k > 0)
            else:
                what = "measured wrench" if s.kind == "wrench_load" else "gravity wrench from the URDF masses"
                per = ""
            return (f"{WRENCH[s.component]} (N{' m' * (s.component > 2)}{per}) of the {what} that frame {s.frame} "
                    f"({frame_name(robot, s.frame)}) carries, about its origin in its axes")
        joint = robot.joints[s.joint - 1]
        where = f"joint q{s.joint} ({joint.name})"
        unit = "N" if joint.kind == "P" else "N m"
        if s.kind == "wrench_torque":
            return f"{'force' if joint.kind == 'P' else 'torque'} of the measured wrench on {where}, {unit}"
        if s.kind == "gravity_torque":
            return f"static gravity {'force' if joint.kind == 'P' else 'torque'} on {where} from the URDF masses " \
                   f"(-dV/dq), {unit}"
        frame, k = robot.driven(s.joint - 1)[0][0] + s.column // 4, s.column % 4
        load = "a unit mass at the origin of" if k == 0 else f"a unit first moment along the {'xyz'[k - 1]} axis of"
        return f"gravity on {where} of {load} frame {frame}, {unit} per {'kg' if k == 0 else 'kg m'}"


_CATALOGS: dict[tuple, LoadCatalog] = {}


def catalog(robot: Robot) -> LoadCatalog:
    """The robot's load signals; computed once per robot content (kinematics, gravity, files)."""
    key = (robot.chain, robot.base, robot.tool, robot.gravity, robot.wrench_frame, robot.urdf,
           robot.base_link, tuple(sorted(robot.source_hashes.items())), robot.parents, robot.branches)
    if key not in _CATALOGS:
        _CATALOGS[key] = _build_catalog(robot)
    return _CATALOGS[key]


def generic_poses(robot: Robot) -> np.ndarray:
    """(P, n) joint values for the rank test: deterministic, away from special postures."""
    lo, hi = map(np.array, robot.sampling_box())
    return np.random.default_rng(SEED).uniform(lo, hi, (max(MIN_POSES, 8 * robot.n + 8), robot.n))


def _chain_geometry(robot: Robot, q: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """At poses q (P, n): the world frames W (frames 0..m, then each branch's tool; (P, 4, 4) each)
    and every frame's joint axis and a point on it in the world ((3, P) each), as the generated
    code computes them on the nominal chain."""
    W = frames(robot, q)
    F = [W[robot.parent(k)] @ constant(joint.pre) for k, joint in enumerate(robot.chain, start=1)]
    axes = [(Fk[:, :3, :3] @ np.array([float(v) for v in joint.axis])).T for Fk, joint in zip(F, robot.chain)]
    return W, axes, [Fk[:, :3, 3].T for Fk in F]


def frame_name(robot: Robot, f: int) -> str:
    """Frame f's name in messages: its joint's, or `base` for frame 0."""
    return robot.chain[f - 1].name if f else "base"


def _poses(robot: Robot, W: list[np.ndarray]) -> list[tuple]:
    """(R rows, p) of frames 0..m as the formulas take them, each entry (P,)."""
    return [(tuple(tuple(T[:, r, c] for c in range(3)) for r in range(3)), tuple(T[:, r, 3] for r in range(3)))
            for T in W[:robot.n_frames + 1]]


def _numeric_frame_columns(robot: Robot, q: np.ndarray, geometry=None) -> list[list[np.ndarray]]:
    """Per frame F (0..m) and component fx..mz, the candidate columns of its wrench's regressor at
    poses q: (P, 4 |subtree(F)|), the carried frames in ascending order (`frame_wrench_columns`)."""
    W = (geometry or _chain_geometry(robot, q))[0]
    g = np.array([float(v) for v in robot.gravity])
    poses = _poses(robot, W)
    return [[np.column_stack([np.broadcast_to(c, len(q)) for c in cols])
             for cols in frame_wrench_columns(lambda x: x, *poses[f], [poses[k] for k in robot.subtree(f)], g)]
            for f in range(robot.n_frames + 1)]


def _numeric_columns(robot: Robot, q: np.ndarray, geometry=None) -> list[np.ndarray]:
    """Per joint variable J, its candidate columns at poses q: (P, 4 (m - k + 1)), k its first frame;
    geometry: `_chain_geometry(robot, q)` when already at hand."""
    W, axes, origins = geometry or _chain_geometry(robot, q)
    g = np.array([float(v) for v in robot.gravity])
    poses = _poses(robot, W)
    return [np.column_stack([np.broadcast_to(c, len(q)) for c in joint_columns(lambda x: x, robot, J, axes, origins,
                                                                                 poses, g, numeric=True)])
            for J in range(1, robot.n + 1)]


def signal_values(robot: Robot, q: np.ndarray, w: np.ndarray, names: list[str] | None = None) -> np.ndarray:
    """The load signals `names` (canonical spellings; None: every signal of the robot's catalog, in
    its order) (N, L) at joints q (N, n) and wrenches w (N, 6) or (6,), by the formulas the generated
    code prints (module docstring), on the nominal chain in numpy: diagnose's candidates use every
    signal, an error model's terms only their own."""
    q = np.atleast_2d(np.asarray(q, float))
    w = np.broadcast_to(np.asarray(w, float), (len(q), 6))
    cat = catalog(robot)
    signals = cat.signals if names is None else [cat.by_name(name) for name in names]
    geometry = W, axes, origins = _chain_geometry(robot, q)
    S = W[robot.n_frames + 1] if robot.wrench_frame == "tool" else W[robot.wrench_frame]  # the sensor frame
    force, moment = (np.einsum("nij,nj->in", S[:, :3, :3], w[:, k:k + 3]) for k in (0, 3))
    moving = set(robot.path(robot.sensor_frame()))  # the frames that move the sensor
    columns = _numeric_columns(robot, q, geometry) if any(s.kind in ("gravity", "gravity_torque")
                                                         for s in signals) else []
    by_frame = _numeric_frame_columns(robot, q, geometry) if any(s.kind in ("frame_gravity", "gravity_load")
                                                                 for s in signals) else []
    poses = _poses(robot, W)
    out = np.empty((len(q), len(signals)))
    for i, s in enumerate(signals):
        if s.kind == "frame_gravity":
            out[:, i] = by_frame[s.frame][s.component][:, s.column]
        elif s.kind == "gravity_load":
            out[:, i] = by_frame[s.frame][s.component] @ np.concatenate([cat.params[k] for k in robot.subtree(s.frame)])
        elif s.kind == "wrench_load":
            out[:, i] = frame_wrench_load(lambda x: x, *poses[s.frame], S[:, :3, 3].T, force, moment)[s.component]
        elif s.kind == "wrench_torque":
            out[:, i] = sum(float(mult) * frame_wrench_torque(lambda x: x, robot.chain[k - 1].kind, axes[k - 1],
                                                              origins[k - 1], S[:, :3, 3].T, force, moment)
                            for k, mult in robot.driven(s.joint - 1) if k in moving)
        elif s.kind == "gravity":
            out[:, i] = columns[s.joint - 1][:, s.column]
        else:
            out[:, i] = columns[s.joint - 1] @ np.concatenate(cat.params[robot.driven(s.joint - 1)[0][0]:])
    return out


def _independent(Y: np.ndarray, g: float) -> list[int]:
    """Indices of the columns of Y (P poses) that are independent of the columns before them
    (Gram-Schmidt, twice for accuracy), relative to Y's largest column and at least to |g| sqrt(P),
    the size of a unit first moment's column: the rounding of a float pi/2 in the chain leaves
    columns of 1e-15 that are no load."""
    scale = max(np.linalg.norm(Y, axis=0).max(initial=0.0), g * np.sqrt(len(Y)))
    Q, keep = np.zeros((len(Y), 0)), []
    for k in range(Y.shape[1]):
        r = Y[:, k].copy()
        for _ in range(2):
            r -= Q @ (Q.T @ r)
        if np.linalg.norm(r) > RANK_TOL * scale:
            keep.append(k)
            Q = np.column_stack([Q, r / np.linalg.norm(r)])
    return keep


def frame_params(robot: Robot) -> tuple[tuple[float, ...], ...]:
    """Per frame 0..m, (m, m cx, m cy, m cz) of every URDF link rigid with it (kg, kg m, frame i's
    coordinates); off-chain joints held at zero (their mimic joints at the offset). Links above joint
    1 count for no joint: frame 0 is 0. A massive link that an off-chain mimic joint moves with a
    chain joint is refused (ModelError): it is rigid with no frame."""
    tree = load_mass_tree(robot.urdf, robot.base_link)
    rest = tree.rest_poses()
    frame_of_joint = {j.name: i for i, j in enumerate(robot.chain, start=1)}
    anchor, link_of_frame, swung = {tree.links[0]: 0}, {}, {tree.links[0]: None}
    for link in tree.links[1:]:
        j = tree.joint[link]
        i = frame_of_joint.get(j.name)
        if i is not None:
            link_of_frame[i] = link
        anchor[link] = anchor[tree.parent[link]] if i is None else i
        moves = i is None and j.mimic is not None and j.mimic.root in frame_of_joint
        swung[link] = (j.name, j.mimic.root) if moves else None if i is not None else swung[tree.parent[link]]
    params = np.zeros((robot.n_frames + 1, 4))
    for link, m in tree.mass.items():
        i = anchor[link]
        if i and m and swung[link]:
            raise ModelError(f"{tree.source}: link {excerpt(link)} hangs from joint {excerpt(swung[link][0])}, which "
                             f"mimics chain joint {excerpt(swung[link][1])} off the chain, so it moves against every "
                             f"frame and gravity_torque cannot carry its mass; use `gecgen gravity`'s tau columns")
        if i:
            T = np.linalg.solve(rest[link_of_frame[i]], rest[link])
            params[i] += m * np.r_[1.0, T[:3, :3] @ tree.com[link] + T[:3, 3]]
    return tuple(tuple(float(v) for v in row) for row in params)


def _build_catalog(robot: Robot) -> LoadCatalog:
    n = robot.n
    sensor = robot.sensor_frame()
    moving = set(robot.path(sensor))
    carrying = [J for J in range(1, n + 1) if any(k in moving for k, _ in robot.driven(J - 1))]
    signals = [Signal(f"wrench_torque(q{J})", "wrench_torque", J) for J in carrying]
    use = (f"wrench_torque(q1) .. wrench_torque(q{len(carrying)})" if carrying == list(range(1, len(carrying) + 1))
           else ", ".join(f"wrench_torque(q{J})" for J in carrying))
    why_not = {}
    for J in sorted(set(range(1, n + 1)) - set(carrying)):
        why_not[f"wrench_torque(q{J})"] = (f"the wrench is measured in frame {sensor}, which joint q{J} does not move"
                                           + (f"; use {use}" if carrying else ""))
    Y = _numeric_columns(robot, generic_poses(robot))
    g = exact_norm(robot.gravity)
    for J, joint in enumerate(robot.joints, start=1):
        keep = _independent(Y[J - 1], g)
        signals += [Signal(f"gravity(q{J},{r})", "gravity", J, k) for r, k in enumerate(keep, start=1)]
        if not keep:
            unloaded = "its axis is along gravity" if joint.kind == "R" else "it moves across gravity"
            why_not[f"gravity(q{J})"] = why_not[f"gravity_torque(q{J})"] = \
                f"gravity loads joint q{J} ({joint.name}) in no posture ({unloaded}); drop the term"
    frame_columns = _numeric_frame_columns(robot, generic_poses(robot))
    for f, by_component in enumerate(frame_columns):
        for c, Yc in enumerate(by_component):
            keep = _independent(Yc, g)
            signals += [Signal(f"gravity({f},{WRENCH[c]},{r})", "frame_gravity", column=k, frame=f, component=c)
                        for r, k in enumerate(keep, start=1)]
            if not keep:
                why_not[f"gravity({f},{WRENCH[c]})"] = why_not[f"gravity_load({f},{WRENCH[c]})"] = \
                    f"gravity puts no {WRENCH[c]} on frame {f} ({frame_name(robot, f)}) in any posture; drop the term"
    for f in range(robot.n_frames + 1):
        if sensor in robot.subtree(f):
            signals += [Signal(f"wrench_load({f},{c})", "wrench_load", frame=f, component=k)
                        for k, c in enumerate(WRENCH)]
        else:
            for c in WRENCH:
                why_not[f"wrench_load({f},{c})"] = f"the wrench is measured in frame {sensor}, which frame {f} " \
                                                   f"({frame_name(robot, f)}) does not carry"
    params: tuple = ()
    with_masses = [f"gravity_load({f},{c})" for f in range(robot.n_frames + 1) for c in WRENCH]
    if not robot.urdf:
        for J in range(1, n + 1):
            why_not.setdefault(f"gravity_torque(q{J})", f"needs link masses, which {robot.source or 'this robot'} "
                                                        f"does not give (DH rows); use gravity(q{J}) (unknown masses) "
                                                        f"or build the robot from its URDF")
        for name in with_masses:
            why_not.setdefault(name, f"needs link masses, which {robot.source or 'this robot'} does not give (DH "
                                     f"rows); use {name.replace('gravity_load', 'gravity')} (unknown masses) or "
                                     f"build the robot from its URDF")
    else:
        try:
            params = frame_params(robot)
        except ModelError as exc:  # only the loads from masses need the inertials: other terms stay usable
            params, reason = (), str(exc)
            for name in [f"gravity_torque(q{J})" for J in range(1, n + 1)] + with_masses:
                why_not.setdefault(name, reason)
        for J in range(1, n + 1):
            if f"gravity_torque(q{J})" in why_not:
                continue
            carried = np.concatenate(params[robot.driven(J - 1)[0][0]:])  # from the first frame J moves
            if np.linalg.norm(Y[J - 1] @ carried) <= RANK_TOL * np.linalg.norm(Y[J - 1]) * np.linalg.norm(carried):
                why_not[f"gravity_torque(q{J})"] = (f"the URDF's masses put no gravity torque on joint q{J} "
                                                    f"({robot.joints[J - 1].name}); drop the term")
            else:
                signals.append(Signal(f"gravity_torque(q{J})", "gravity_torque", J))
        for f, by_component in enumerate(frame_columns if params else ()):
            carried = np.concatenate([params[k] for k in robot.subtree(f)])
            for c, Yc in enumerate(by_component):
                name = f"gravity_load({f},{WRENCH[c]})"
                if name in why_not:
                    continue
                if np.linalg.norm(Yc @ carried) <= RANK_TOL * np.linalg.norm(Yc) * np.linalg.norm(carried):
                    why_not[name] = (f"the URDF's masses put no {WRENCH[c]} on frame {f} ({frame_name(robot, f)}); "
                                     f"drop the term")
                else:
                    signals.append(Signal(name, "gravity_load", frame=f, component=c))
    return LoadCatalog(tuple(signals), params, why_not)


class LoadTerms:
    """The load functions of the term parser for one robot: `name` for a call inside a term (the
    signal's canonical spelling), `expand` for the shorthands gravity(J) and gravity(F, c).
    `variables` maps the names a term may use to the variables they stand for (joints are q<k>).
    Errors go through the parser's `fail(text, why)`."""

    def __init__(self, robot: Robot, variables: dict[str, str]):
        self.robot, self.variables = robot, variables

    @staticmethod
    def is_shorthand(node) -> bool:
        return (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "gravity"
                and (len(node.args) == 1 or len(node.args) == 2 and isinstance(node.args[1], ast.Name)))

    def _joint(self, text: str, node, fail) -> int:
        s = self.variables.get(node.id) if isinstance(node, ast.Name) else None
        if s is None or not re.fullmatch(r"q\d+", s):
            fail(text, f"'{ast.unparse(node)}' is not a joint of {self.robot.name}; use a joint name or "
                       f"q1..q{self.robot.n}")
        return int(s[1:])

    def _frame(self, text: str, node, fail) -> int:
        """A frame written as its joint's name (passive joints too), a reading q<k> or its number."""
        names = [j.name for j in self.robot.chain]
        if isinstance(node, ast.Constant) and isinstance(node.value, int) and not isinstance(node.value, bool) \
                and 0 <= node.value <= self.robot.n_frames:
            return node.value
        if isinstance(node, ast.Name) and node.id in names:
            return names.index(node.id) + 1
        s = self.variables.get(node.id) if isinstance(node, ast.Name) else None
        if s is None or not re.fullmatch(r"q\d+", s):
            fail(text, f"'{ast.unparse(node)}' is not a frame of {self.robot.name}; use a joint's name (a passive "
                       f"joint's too), q1..q{self.robot.n} or a frame number 0..{self.robot.n_frames}")
        return self.robot.frame_of(int(s[1:]) - 1)

    def _component(self, text: str, node, fail) -> str:
        if not (isinstance(node, ast.Name) and node.id in WRENCH):
            fail(text, f"'{ast.unparse(node)}' is not a wrench component; use one of {' '.join(WRENCH)}")
        return node.id

    def _call(self, text: str, node, fail) -> tuple[str, int, list]:
        """(function, joint or frame, the remaining arguments: the component as a name, a column)."""
        f, args = node.func.id, node.args
        if node.keywords:
            fail(text, "keyword arguments are not allowed")
        frame_load = f in ("gravity_load", "wrench_load") or f == "gravity" and len(args) >= 2 \
            and isinstance(args[1], ast.Name)
        if frame_load:
            if len(args) not in ((2, 3) if f == "gravity" else (2,)):
                fail(text, f"{f} takes (frame, component){' or (frame, component, column)' * (f == 'gravity')}, "
                           f"e.g. {f}(q2, mx)")
            return f, self._frame(text, args[0], fail), [self._component(text, args[1], fail)] + args[2:]
        if not args or len(args) > (2 if f == "gravity" else 1):
            fail(text, "gravity takes (joint) or (joint, column), or (frame, component[, column]), e.g. gravity(q2), "
                       "gravity(q2, 1) or gravity(q2, mx)" if f == "gravity" else f"{f} takes one joint, e.g. {f}(q2)")
        return f, self._joint(text, args[0], fail), args[1:]

    def _refuse_if_unsupported(self, text: str, name: str, fail):
        reason = catalog(self.robot).why_not.get(name)
        if reason:
            fail(text, reason)

    def _column(self, text: str, node, rank: int, base: str, fail) -> int:
        """The column number r of gravity(base, r), 1..rank."""
        r = node.value if isinstance(node, ast.Constant) else None
        what = f"joint {base}" if base.startswith("q") else "frame {} {}".format(*base.split(","))
        if not (isinstance(r, int) and not isinstance(r, bool) and 1 <= r <= rank):
            fail(text, f"{what} has {rank} independent gravity column{'s' * (rank > 1)}: use gravity({base}, 1)"
                       f"{f' .. gravity({base}, {rank})' if rank > 1 else ''}, or gravity({base}) for all")
        return r

    def name(self, text: str, node, fail) -> str:
        f, at, rest = self._call(text, node, fail)
        cat = catalog(self.robot)
        if f in ("gravity_load", "wrench_load"):
            name = f"{f}({at},{rest[0]})"
        elif f == "gravity" and len(rest) == 2:
            base = f"{at},{rest[0]}"
            self._refuse_if_unsupported(text, f"gravity({base})", fail)
            rank = cat.frame_rank(at, WRENCH.index(rest[0]))
            name = f"gravity({base},{self._column(text, rest[1], rank, base, fail)})"
        elif f == "gravity":
            if not rest or isinstance(rest[0], str):
                base = f"q{at}" if not rest else f"{at},{rest[0]}"
                fail(text, f"gravity({base}) expands into several terms and must stand alone; inside an expression "
                           f"write one column, gravity({base}, r)")
            self._refuse_if_unsupported(text, f"gravity(q{at})", fail)
            name = f"gravity(q{at},{self._column(text, rest[0], cat.gravity_rank(at), f'q{at}', fail)})"
        else:
            name = f"{f}(q{at})"
        self._refuse_if_unsupported(text, name, fail)
        return name

    def expand(self, text: str, node, fail) -> list[tuple[str, str]]:
        """gravity(J) or gravity(F, c) -> (signal name, label) of each of its columns, labelled as written."""
        _, at, rest = self._call(text, node, fail)
        written = ", ".join(ast.unparse(a) for a in node.args)
        cat = catalog(self.robot)
        base, rank = (f"q{at}", cat.gravity_rank(at)) if not rest else \
            (f"{at},{rest[0]}", cat.frame_rank(at, WRENCH.index(rest[0])))
        self._refuse_if_unsupported(text, f"gravity({base})", fail)
        return [(f"gravity({base},{r})", f"gravity({written}, {r})") for r in range(1, rank + 1)]
