"""The candidate dictionary of diagnose: what a generalized error may lack, as groups of terms
each tested as one (their columns together, degrees of freedom counted).

Two kinds. Kinematic shapes (`kinematic_candidates`) are offered to every generalized error.
Physical effects (`load_candidates`) are derived from the chain, not listed by shape: each joint
has one generalized error that turns (or slides) about its own axis, found geometrically, and the
compiler gives the loads it carries (`CompiledModel.load_signals`: the static gravity regressor's
base columns, the torque of the measured wrench, the gravity torque from known masses). Then

* joint compliance: the joint's own error times its loads (a harmonic drive twisting under
  the arm's weight, with the masses unknown: the regressor columns; or known: one torque);
* link bending: the other five errors of that frame times the same loads;
* free play: the sign of the load on the joint's own error (the joint sits against the side of its
  play that the load pushes it to).

Those are the loads a reading feels, offered where the reading turns one frame (a reading that a
coupling ties to other joints feels their loads by virtual work, which no one frame's errors do).
Every frame, besides,
carries a whole wrench (`frame_load_candidates`): passive joints and the base too, and the moments
across a joint's axis (a bearing that tilts, a link that bends) as well as about it, each offered
to the frame's errors it acts on.
"""
from __future__ import annotations

import re

import numpy as np

from gecgen.loop.screening import Candidate
from gecgen.model.errors import ErrorModel
from gecgen.model.kinematics import constant, frames
from gecgen.model.measurements import Measurements
from gecgen.model.robot import ERROR_NAMES, MATCHING, WRENCH, Robot
from gecgen.runtime.compiled import CompiledModel

#: periods scanned per joint for Fourier pairs
PERIODS = 40
#: a load signal's name: function(joint[, column])
SIGNAL = re.compile(r"^(\w+)\((q\d+)\s*(?:,\s*(\d+))?\)$")
#: a frame load's name: function(frame,component[,column])
FRAME_SIGNAL = re.compile(r"^(gravity|gravity_load|wrench_load)\((\d+),(\w+)(?:,(\d+))?\)$")


def _range(v: np.ndarray) -> float:
    return float(v.max() - v.min()) if len(v) else 0.0


def parallel_joint_groups(robot: Robot, rng: np.random.Generator) -> list[tuple[int, ...]]:
    """Runs of consecutive revolute joints whose axes stay parallel (e.g. shoulder and elbow); on a
    tree, consecutive along one branch (a joint and its parent's)."""
    lo, hi = map(np.array, robot.sampling_box())
    q = rng.uniform(lo, hi, (16, robot.n))
    W = frames(robot, q)
    axes = [W[robot.parent(robot.frame_of(i))][:, :3, :3] @ constant(j.pre)[:3, :3]
            @ np.array([float(a) for a in j.axis]) for i, j in enumerate(robot.joints)]
    groups, run = [], [0]
    for i in range(1, robot.n):
        both_r = robot.joints[i].kind == robot.joints[run[-1]].kind == "R"
        chained = robot.parent(robot.frame_of(i)) == robot.frame_of(run[-1])
        if both_r and chained and np.allclose(np.cross(axes[run[-1]], axes[i]), 0, atol=1e-9):
            run.append(i)
        else:
            if len(run) > 1:
                groups.append(tuple(run))
            run = [i]
    if len(run) > 1:
        groups.append(tuple(run))
    return groups


def fourier_candidate(name: str, v: np.ndarray, period: float) -> Candidate:
    """sin and cos of 2 pi v / period (period rounded to 4 significant digits, as written)."""
    period = float(f"{period:.4g}")
    a = 2 * np.pi * v / period
    return Candidate("fourier", (name,), (f"sin(2*pi*{name}/{period:g})", f"cos(2*pi*{name}/{period:g})"),
                     np.column_stack([np.sin(a), np.cos(a)]))


def shown_family(c: Candidate, data: Measurements) -> str:
    """The family a person reads for candidate c: a Fourier pair whose period is longer than the
    range its joint covers in the data shows less than one cycle there, a "smooth" bend rather
    than a periodic error (a 3.28 m period over a 1.45 m stroke)."""
    if c.family != "fourier":
        return c.family
    period = float(c.terms[0].split("/")[-1].rstrip(")"))
    return "fourier" if period <= _range(data.q[:, int(c.variables[0][1:]) - 1]) else "smooth"


def refine_period(best: Candidate, data: Measurements, screen_one) -> Candidate:
    """A fine scan of periods around a Fourier winner of the coarse scan (one grid step each way)."""
    name = best.variables[0]
    v = data.q[:, int(name[1:]) - 1]
    period = float(best.terms[0].split("/")[-1].rstrip(")"))
    span = _range(v)
    step = (2 * span / max(span / 60, 1e-12)) ** (1 / (PERIODS - 1))
    fine = [fourier_candidate(name, v, p) for p in np.geomspace(period / step, period * step, 41)]
    return max(fine, key=screen_one)


def kinematic_candidates(robot: Robot, model: ErrorModel, data: Measurements,
                         rng: np.random.Generator) -> list[Candidate]:
    """Shapes of errors in the joints, wrench and aux signals, offered to every generalized error:
    a missing constant, powers (cross-joint coupling included: a joint's angle error times another
    joint's angle is a power of that joint on that error), Fourier pairs over a scan of periods
    (rail waviness), sin/cos of one and of twice a revolute angle (eccentricity), of sums of
    parallel-axis joints (gravity on planar arms), wrench and payload times a joint, aux signals
    (thermal growth, drift)."""
    out: list[Candidate] = []
    present = {t.text for ts in model.terms for t in ts}

    def add(family, variables, terms, values):
        out.append(Candidate(family, tuple(variables), tuple(terms), np.column_stack(values)))

    moving = [i for i in range(robot.n) if _range(data.q[:, i]) > 1e-9]
    # a constant generalized error the model leaves out (screen() only pairs it with errors that lack it)
    add("geometric", [], ["1"], [np.ones(data.n_poses)])
    for i in moving:
        v, name, joint = data.q[:, i], f"q{i + 1}", robot.joints[i]
        top = max([k for k in range(1, 9) if f"{name}**{k}" in present or (k == 1 and name in present)], default=0)
        for k in range(1, top + 3):  # every order up to two above the model's highest
            add("polynomial", [name], [f"{name}**{k}" if k > 1 else name], [v ** k])
        if joint.kind == "R":
            add("trigonometric", [name], [f"sin({name})", f"cos({name})"], [np.sin(v), np.cos(v)])
            add("trigonometric", [name], [f"sin(2*{name})", f"cos(2*{name})"], [np.sin(2 * v), np.cos(2 * v)])
        span = _range(v)
        if joint.kind == "P" or span < np.pi:
            distinct = np.unique(v)
            spacing = np.median(np.diff(distinct)) if len(distinct) > 2 else span / 2
            # at least four distinct values of the variable per period, or a sinusoid can alias through the data
            shortest = max(2.5 * spacing, span / 60, 4 * span / max(len(distinct), 1))
            for period in np.geomspace(shortest, 2 * span, PERIODS) if 2 * span > shortest else ():
                out.append(fourier_candidate(name, v, period))
    for group in parallel_joint_groups(robot, rng):
        for a, b in zip(group, group[1:]):
            names = [f"q{a + 1}", f"q{b + 1}"]
            s = data.q[:, a] + data.q[:, b]
            add("trigonometric", names, [f"sin({names[0]} + {names[1]})", f"cos({names[0]} + {names[1]})"],
                [np.sin(s), np.cos(s)])
    wrench = [k for k in range(6) if _range(data.w[:, k]) > 1e-9]
    for k in wrench:
        f, fn = data.w[:, k], WRENCH[k]
        add("wrench", [fn], [fn], [f])
        for i in moving:
            name = f"q{i + 1}"
            add("wrench x joint", [fn, name], [f"{fn}*{name}"], [f * data.q[:, i]])
            add("wrench x joint", [fn, name], [f"{fn}*{name}**2"], [f * data.q[:, i] ** 2])
    force = np.linalg.norm(data.w[:, :3], axis=1)
    # only when the force turns in the sensor frame does its magnitude differ from one component
    if sum(_range(data.w[:, k]) > 0.01 * _range(force) for k in range(3)) > 1:
        # the payload's weight, whatever direction the sensor sees it in
        magnitude = "sqrt(fx**2 + fy**2 + fz**2)"
        add("payload", ["payload"], [magnitude], [force])
        for i in moving:
            add("payload x joint", ["payload", f"q{i + 1}"], [f"{magnitude}*q{i + 1}"], [force * data.q[:, i]])
    constant = tuple(e for e, ts in enumerate(model.terms) if any(t.text == "1" for t in ts))
    for k, a in enumerate(data.aux_names):
        v = data.aux[:, k]
        span = _range(v)
        if not span > 1e-12 * max(1.0, np.abs(v).max()):
            continue
        if abs(np.mean(v)) > 10 * span:
            # far from zero (time in Unix seconds) a signal's variation drowns in its offset, and the
            # screen would find it inside the constant term: screened about its mean, which with the
            # error's constant term spans what the signal itself does; its square is not offered (it
            # differs from the centred one by more than a constant)
            out.append(Candidate("auxiliary", (a,), (a,), (v - np.mean(v))[:, None], constant))
            continue
        add("auxiliary", [a], [a], [v])
        add("auxiliary", [a], [f"{a}**2"], [v ** 2])
    return out




def frame_own_errors(robot: Robot, rng: np.random.Generator) -> dict[int, int]:
    """Frame (1..m, passive joints' too) -> the generalized error (eps index) that moves exactly as
    its joint does: a rotation about (revolute) or translation along (prismatic) the joint's axis,
    through a point on it, at the frame after the joint or, failing that, the frame before it.
    Decided at generic poses on the nominal chain; a joint with neither has no entry."""
    lo, hi = map(np.array, robot.sampling_box())
    F = frames(robot, rng.uniform(lo, hi, (8, robot.n)))
    out = {}
    for frame, joint in enumerate(robot.chain, start=1):
        J = F[robot.parent(frame)] @ constant(joint.pre)
        axis = J[:, :3, :3] @ np.array([float(a) for a in joint.axis])
        for f in (frame, robot.parent(frame)):
            W = F[f]
            # column k of a frame is the axis of translation e{x,y,z}[k] and of rotation (ep, es, er)[k]
            for k in range(3):
                parallel = np.allclose(np.cross(W[:, :3, k], axis), 0, atol=1e-9)
                through = joint.kind == "P" or np.allclose(np.cross(W[:, :3, 3] - J[:, :3, 3], axis), 0, atol=1e-9)
                if parallel and through:
                    name = ("ex", "ey", "ez")[k] if joint.kind == "P" else ("ep", "es", "er")[k]
                    out[frame] = 6 * f + ERROR_NAMES.index(name)
                    break
            if frame in out:
                break
    return out


def own_errors(robot: Robot, rng: np.random.Generator) -> dict[int, int]:
    """Joint index (0-based, a reading) -> its own joint's error (`frame_own_errors`)."""
    by_frame = frame_own_errors(robot, rng)
    return {i: by_frame[robot.frame_of(i)] for i in range(robot.n) if robot.frame_of(i) in by_frame}


def loads_by_joint(names: list[str], values: np.ndarray) -> dict[int, dict[str, list[int]]]:
    """The load signals (`CompiledModel.load_signals`: names, values (P, L)) that vary over the
    data, by joint (0-based) and kind: {joint: {"gravity": [columns], "wrench_torque": [...], ...}}."""
    by_joint: dict[int, dict[str, list[int]]] = {}
    for k, name in enumerate(names):
        m = SIGNAL.match(name)
        if m and _range(values[:, k]) > 1e-12 * max(1.0, float(np.abs(values[:, k]).max())):
            by_joint.setdefault(int(m.group(2)[1:]) - 1, {}).setdefault(m.group(1), []).append(k)
    return by_joint


def load_candidates(cm: CompiledModel, data: Measurements, rng: np.random.Generator,
                    memo: dict | None = None) -> list[Candidate]:
    """Joint compliance, link bending and free play (see the module docstring) for every joint
    whose own error exists and whose loads vary over the data. memo: a dict kept by the caller
    across calls with the same robot and data (diagnose's rounds), where the list is kept by the
    joints' own errors: the loads depend on nothing else, and take most of the dictionary's time."""
    by_frame = frame_own_errors(cm.robot, rng)
    key = tuple(by_frame.items())
    if memo is not None and key in memo:
        return memo[key]
    names, values = cm.load_signals(data.q, data.w)
    by_joint = loads_by_joint(names, values)
    out: list[Candidate] = []
    for i, e in ((i, by_frame[cm.robot.frame_of(i)]) for i in range(cm.robot.n) if cm.robot.frame_of(i) in by_frame):
        # a reading that turns several frames (couplings) feels their loads summed by virtual work,
        # which acts on no one frame's errors: each frame's own loads are offered below instead
        loads = by_joint.get(i, {}) if len(cm.robot.driven(i)) == 1 else {}
        frame = e // 6
        others = tuple(6 * frame + k for k in range(6) if 6 * frame + k != e)
        joint = (f"q{i + 1}",)
        # unknown masses: the regressor's columns and the wrench torque together; known: one torque
        groups = [loads.get("gravity", []) + loads.get("wrench_torque", []), loads.get("gravity_torque", [])]
        for cols in (g for g in groups if g):
            terms, v = tuple(names[k] for k in cols), values[:, cols]
            out.append(Candidate("joint compliance", joint, terms, v, (e,)))
            out.append(Candidate("link bending", joint, terms, v, others))
        for k in loads.get("gravity_torque") or loads.get("gravity", []):
            out.append(Candidate("free play", joint, (f"sign({names[k]})",), np.sign(values[:, [k]]), (e,)))
    out += frame_load_candidates(cm, data, names, values, set(by_frame.values()), out)
    if memo is not None:
        memo[key] = out
    return out




def moves_with(values: np.ndarray, inputs: list[tuple[str, np.ndarray]], wrench: bool) -> tuple[str, ...]:
    """What a person plots a load against: the reading its largest column follows most closely, and,
    for a load with the measured wrench in it, the wrench component likewise (|correlation| over the
    poses). values: (P, k) the load's columns; inputs: `standardized_inputs`."""
    v = values[:, np.argmax(values.std(axis=0))]
    v = (v - v.mean()) / v.std()
    out = []
    for kind in ("q", "w")[:1 + wrench]:
        names, Z = zip(*[(n, z) for n, z in inputs if (n[0] == "q") == (kind == "q")]) if inputs else ((), ())
        if names:
            out.append(names[int(np.argmax(np.abs(np.column_stack(Z).T @ v)))])
    return tuple(out)


def standardized_inputs(data: Measurements) -> list[tuple[str, np.ndarray]]:
    """The readings and wrench components that move over the data, each centred and scaled to unit
    standard deviation (P,): their dot product with a standardized load is its correlation times P."""
    raw = [(f"q{i + 1}", data.q[:, i]) for i in range(data.q.shape[1])] + list(zip(WRENCH, data.w.T))
    return [(name, (x - x.mean()) / x.std()) for name, x in raw if _range(x) > 1e-9]


def frame_load_candidates(cm: CompiledModel, data: Measurements, names: list[str], values: np.ndarray,
                          own: set[int], taken: list[Candidate]) -> list[Candidate]:
    """For every frame (actuated, coupled or passive joint, or the base) and each of its six errors,
    the loads that act there: the matching component of the wrench the frame carries (the moment
    about the error's axis: about the joint's own axis a joint compliance, across it a bearing that
    tilts; the force along a translation), and a beam's coupling (a link bending under a force
    across it turns, under a moment it moves: the moments about the other two axes for a
    translation, the forces along them for a rotation). Each load as the measured wrench's component
    alone, as the regressor's columns with it (unknown masses), and from the URDF's masses with it; a
    group equal to one already offered on that error (the joint loads, `taken`) is left out. own:
    the joints' own errors (`frame_own_errors`)."""
    by: dict[tuple[int, str, int], list[int]] = {}
    for k, name in enumerate(names):
        m = FRAME_SIGNAL.match(name)
        if m and _range(values[:, k]) > 1e-12 * max(1.0, float(np.abs(values[:, k]).max())):
            # a measured wrench adds to the weight in both forms, and stands alone too: a payload that
            # changes from pose to pose is a load no fixed mass explains
            forms = {"gravity_load": ("masses",), "gravity": ("regressor",),
                     "wrench_load": ("regressor", "masses", "wrench")}[m.group(1)]
            for form in forms:
                by.setdefault((int(m.group(2)), form, WRENCH.index(m.group(3))), []).append(k)
    robot, out, inputs = cm.robot, [], standardized_inputs(data)
    for f in range(robot.n_frames + 1):
        for k in range(6):
            e, matched = 6 * f + k, WRENCH.index(MATCHING[k])
            axis = matched % 3
            across = [b + 3 * (k < 3) for b in range(3) if b != axis]
            for c, family in [(matched, "joint compliance" if e in own else
                               "lateral compliance" if k >= 3 else "frame compliance")] + \
                             [(c, "link bending") for c in across]:
                for form in ("wrench", "regressor", "masses"):
                    cols = by.get((f, form, c), [])
                    v = values[:, cols]
                    if not cols or any(e in t.errors and t.values.shape == v.shape
                                       and np.allclose(t.values, v, rtol=1e-9, atol=1e-12) for t in taken + out):
                        continue
                    terms = tuple(names[j] for j in cols)
                    out.append(Candidate(family, moves_with(v, inputs, any(t.startswith("wrench") for t in terms)),
                                         terms, v, (e,)))
    return out


def candidates(cm: CompiledModel, data: Measurements, rng: np.random.Generator,
               memo: dict | None = None) -> list[Candidate]:
    """The whole dictionary for the current model on this data (memo: as for `load_candidates`)."""
    return kinematic_candidates(cm.robot, cm.model, data, rng) + load_candidates(cm, data, rng, memo)
