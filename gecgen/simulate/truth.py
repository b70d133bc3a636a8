"""Truth robots: a robot file plus physically motivated error sources, in SI units.

Each source adds either a joint-angle error (the joint really sits at q_read + dq: encoder
offset, gear eccentricity, backlash, compliance under gravity) or a generalized-error
contribution d eps (rail waviness, cantilever bending, thermal growth) at every pose. The
measured points are then the exact nonlinear chain at the true joints and errors, plus
repeatability and tracker noise.

A truth file (YAML) looks like

    seed: 1
    gravity: [0, -9.80665, 0]              # world, m/s^2 (default: 0, 0, -9.80665)
    constant: {translation_std: 1.0e-3, rotation_std: 5.0e-4}   # or values: {"1.ex": 0.001}
    joint_offsets: {std: 2.0e-4}            # or values: [..] per joint (m or rad)
    masses: [{frame: 4, mass: 60, at: [0, 0, 0]}]              # link masses, kg, frame coordinates
                                            # or `masses: urdf`: the URDF's <inertial> masses, gravity
                                            # then given in the base link's frame
    sources:
      - {type: sinusoid, variable: 1, error: "1.ey", amplitude: 3.0e-4, period: 0.45, phase: 0.3}
      - {type: sinusoid, variable: 4, joint: 4, amplitude: 1.0e-4, period: 6.283185, phase: 0}
      - {type: cantilever, joint: 3, offset: 0.735, flexibility: 1.1e-6, mass: 40,
         deflection: "-3.ez", slope: "-3.ep"}
      - {type: compliance, joint: 5, compliance: 2.0e-6}
      - {type: backlash, joint: 2, width: 2.0e-4}    # half the width, on the side of the last motion
      - {type: play, joint: 6, width: 1.0e-3}        # free play: half the width, on the side the load pushes
      - {type: thermal, error: "1.ez", per_kelvin: 3.6e-5, reference: 20, start: 20, end: 26}
      - {type: frame_compliance, frame: torso_2, compliance: {ep: 4.0e-5, es: 4.0e-5}}
                                             # frame torso_2's errors give under the wrench it carries:
                                             # error -> per matching component (ep: mx, es: my, er: mz,
                                             # ex: fx, ...; rad per N m, m per N), or {component: value}
      - {type: beam, frame: 3, axis: x, length: 0.6, flexibility: 2.0e-6}
                                             # a compliant link: a cantilever from frame 3's origin along
                                             # its x axis, 1/EI in 1/(N m^2), loaded at its tip by the
                                             # wrench frame 3 carries
    couplings: {J3: "1.003*J2 + J3"}        # the robot as built: coupled joints' true values in the
                                            # readings (the robot file's syntax and units)
    noise: {repeatability: 5.0e-5, tracker: 4.0e-5, orientation: 2.0e-4}
                                            # orientation (rad): per measured frame and axis, when
                                            # simulated measurements give orientations
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from gecgen.model.gravity import robot_frame_wrenches, robot_gravity_torques
from gecgen.model.kinematics import constant, frames
from gecgen.model.robot import ERROR_NAMES, GRAVITY, MATCHING, WRENCH, Robot
from gecgen.model.robot_file import with_couplings
from gecgen.model.validation import require, require_keys


@dataclass(frozen=True)
class Source:
    """One physical error source; `params` are its validated settings (SI units)."""

    kind: str
    params: dict


@dataclass(frozen=True)
class Truth:
    constant: np.ndarray  # (6(n+1),) constant generalized errors
    joint_offsets: np.ndarray  # (n,) m or rad
    sources: tuple[Source, ...]
    gravity: np.ndarray  # (3,) m/s^2 in the world frame
    masses: tuple[dict, ...] | str  # {frame, mass (kg), at (3,) in that frame}, or "urdf"
    repeatability: float  # m, per pose (all targets of a pose move together)
    tracker: float  # m, per measured point and coordinate
    spec: dict = field(default_factory=dict)
    orientation: float = 0.0  # rad, per measured frame and axis (a small rotation in the measuring frame)
    #: the kinematics as built: the robot file's, with the truth's `couplings`; None for the nominal's
    robot: Robot | None = None

    @property
    def aux_names(self) -> tuple[str, ...]:
        return tuple(s.params["column"] for s in self.sources if s.kind == "thermal")


_SOURCE_KEYS = {
    "sinusoid": ({"variable", "amplitude", "period"}, {"phase", "error", "joint"}),
    "cantilever": ({"joint", "flexibility"}, {"offset", "mass", "deflection", "slope"}),
    "compliance": ({"joint", "compliance"}, set()),
    "backlash": ({"joint", "width"}, set()),
    "play": ({"joint", "width"}, set()),
    "thermal": ({"error", "per_kelvin"}, {"reference", "start", "end", "column"}),
    "frame_compliance": ({"frame", "compliance"}, set()),
    "beam": ({"frame", "axis", "length", "flexibility"}, set()),
}
#: the generalized error of a small rotation about a frame's x, y and z axes
ROTATION = ("ep", "es", "er")


def _frame(robot: Robot, value, where: str) -> int:
    """A frame given by its joint's name (passive joints too) or number 0..m."""
    names = [j.name for j in robot.chain]
    if isinstance(value, str) and value in names:
        return names.index(value) + 1
    require(isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= robot.n_frames,
            f"{where}: {value!r} is not a frame; give a joint's name ({', '.join(names)}) or 0..{robot.n_frames}")
    return value


def _compliance(spec, where: str) -> np.ndarray:
    """error -> number (its matching component) or {component: number} as a (6, 6) matrix C: the
    frame's errors (ex..ep) are C times the wrench it carries (fx..mz)."""
    require(isinstance(spec, dict) and spec, f"{where}: expected a mapping such as {{ep: 4.0e-5}} (error -> rad "
                                             f"per N m or m per N)")
    C = np.zeros((6, 6))
    for error, value in spec.items():
        require(error in ERROR_NAMES, f"{where}: {error!r} is not a generalized error; use {' '.join(ERROR_NAMES)}")
        per = value if isinstance(value, dict) else {MATCHING[ERROR_NAMES.index(error)]: value}
        for component, c in per.items():
            require(component in WRENCH, f"{where}.{error}: {component!r} is not a wrench component; use "
                                         f"{' '.join(WRENCH)}")
            require(isinstance(c, (int, float)) and not isinstance(c, bool) and np.isfinite(c),
                    f"{where}.{error}.{component}: expected a number")
            C[ERROR_NAMES.index(error), WRENCH.index(component)] = c
    return C


def beam_compliance(axis: str, length: float, flexibility: float) -> np.ndarray:
    """The (6, 6) compliance of a cantilever clamped at a frame's origin along its `axis` (x, y or z),
    `length` m, 1/EI `flexibility` (1/(N m^2)), loaded at its tip by the wrench W (about the
    origin; about the tip the moment is M - L u x F): the tip turns by theta = (F_v L^2/2 + M_w L)/EI
    about w = u x v and moves by delta = (F_v L^3/3 + M_w L^2/2)/EI along v, for each v across u;
    as the frame's errors, the turn theta w and the move (delta - theta L) v at its origin."""
    u = np.eye(3)["xyz".index(axis)]
    L, C = length, np.zeros((6, 6))
    to_tip = np.zeros((6, 6))  # W -> (F, M about the tip)
    to_tip[:3, :3] = to_tip[3:, 3:] = np.eye(3)
    to_tip[3:, :3] = -L * np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    for v in (e for e in np.eye(3) if abs(e @ u) < 0.5):
        w = np.cross(u, v)
        load = np.concatenate([v, np.zeros(3)]), np.concatenate([np.zeros(3), w])  # F_v and M_w at the tip
        theta = (L ** 2 / 2 * load[0] + L * load[1]) * flexibility
        delta = (L ** 3 / 3 * load[0] + L ** 2 / 2 * load[1]) * flexibility
        C[:3] += np.outer(v, delta - L * theta)
        for k, name in enumerate(ROTATION):
            C[ERROR_NAMES.index(name)] += w[k] * theta
    return C @ to_tip


def _error_index(robot: Robot, text, where: str) -> tuple[int, float]:
    """'-3.ez' -> (index of 3.ez in eps, sign -1)."""
    require(isinstance(text, str), f"{where}: expected an error name such as \"1.ey\" or \"-3.ez\"")
    sign = -1.0 if text.startswith("-") else 1.0
    name = text.lstrip("+-")
    names = robot.error_names()
    require(name in names, f"{where}: unknown generalized error '{name}'; use FRAME.ERROR such as 1.ey (frames 0..{robot.n_frames})")
    return names.index(name), sign


def _joint(robot: Robot, value, where: str) -> int:
    require(isinstance(value, int) and 1 <= value <= robot.n, f"{where}: joint must be 1..{robot.n}, got {value!r}")
    return value - 1


def load_truth(spec: dict, robot: Robot, where: str = "<truth>") -> Truth:
    """Validate a truth spec (the parsed YAML) for `robot`; random parts are drawn from `seed`."""
    require(isinstance(spec, dict), f"{where}: expected a mapping")
    require_keys(spec, where, optional={"seed", "gravity", "constant", "joint_offsets", "masses", "sources", "noise",
                                        "description", "couplings", "angle_unit"})
    rng = np.random.default_rng(spec.get("seed", 0))
    ne = robot.n_errors
    const = np.zeros(ne)
    c = spec.get("constant") or {}
    require_keys(c, f"{where}: constant", optional={"translation_std", "rotation_std", "values"})
    if "translation_std" in c or "rotation_std" in c:
        std = np.tile([c.get("translation_std", 0.0)] * 3 + [c.get("rotation_std", 0.0)] * 3, robot.n_frames + 1)
        const += rng.normal(0.0, 1.0, ne) * std
    for name, value in (c.get("values") or {}).items():
        k, sign = _error_index(robot, name, f"{where}: constant.values")
        const[k] = sign * float(value)
    j = spec.get("joint_offsets") or {}
    require_keys(j, f"{where}: joint_offsets", optional={"std", "values"})
    offsets = rng.normal(0.0, j.get("std", 0.0), robot.n) if "std" in j else np.zeros(robot.n)
    if "values" in j:
        require(len(j["values"]) == robot.n, f"{where}: joint_offsets.values needs {robot.n} numbers")
        offsets = np.array(j["values"], float)
    sources = []
    for k, s in enumerate(spec.get("sources") or []):
        sw = f"{where}: sources[{k}]"
        require(isinstance(s, dict) and s.get("type") in _SOURCE_KEYS,
                f"{sw}: type must be one of {', '.join(_SOURCE_KEYS)}")
        required, optional = _SOURCE_KEYS[s["type"]]
        require_keys(s, sw, required=required | {"type"}, optional=optional)
        p = dict(s)
        if s["type"] == "sinusoid":
            p["variable"] = _joint(robot, s["variable"], f"{sw}.variable")
            require(("error" in s) != ("joint" in s), f"{sw}: give either error (a generalized error) or joint")
            if "error" in s:
                p["error"] = _error_index(robot, s["error"], f"{sw}.error")
            else:
                p["joint"] = _joint(robot, s["joint"], f"{sw}.joint")
            require(float(s["period"]) > 0, f"{sw}.period must be positive")
        elif s["type"] == "cantilever":
            p["joint"] = _joint(robot, s["joint"], f"{sw}.joint")
            require(robot.joints[p["joint"]].kind == "P", f"{sw}.joint: a cantilever grows with a prismatic joint")
            for key in ("deflection", "slope"):
                if key in s:
                    p[key] = _error_index(robot, s[key], f"{sw}.{key}")
        elif s["type"] in ("frame_compliance", "beam"):
            p["frame"] = _frame(robot, s["frame"], f"{sw}.frame")
            if s["type"] == "beam":
                require(s["axis"] in ("x", "y", "z"), f"{sw}.axis: x, y or z (the frame's axis the link runs along)")
                for key in ("length", "flexibility"):
                    require(isinstance(s[key], (int, float)) and s[key] > 0, f"{sw}.{key}: expected a positive number")
                p["matrix"] = beam_compliance(s["axis"], float(s["length"]), float(s["flexibility"]))
            else:
                p["matrix"] = _compliance(s["compliance"], f"{sw}.compliance")
        elif s["type"] in ("compliance", "backlash", "play"):
            p["joint"] = _joint(robot, s["joint"], f"{sw}.joint")
            require(robot.joints[p["joint"]].kind == "R", f"{sw}.joint: {s['type']} needs a revolute joint")
        else:
            p["error"] = _error_index(robot, s["error"], f"{sw}.error")
            p.setdefault("column", "temp_c")
        sources.append(Source(s["type"], p))
    noise = spec.get("noise") or {}
    require_keys(noise, f"{where}: noise", optional={"repeatability", "tracker", "orientation"})
    masses = spec.get("masses") or []
    if masses == "urdf":
        require(robot.urdf, f"{where}: masses: urdf needs a robot built from a URDF")
    else:
        require(isinstance(masses, list), f"{where}: masses: a list of {{frame, mass, at}}, or urdf")
        masses = tuple(masses)
    for k, m in enumerate(() if masses == "urdf" else masses):
        require(isinstance(m, dict), f"{where}: masses[{k}]: expected {{frame, mass, at}}")
        require_keys(m, f"{where}: masses[{k}]", required={"frame", "mass"}, optional={"at"})
    built = None
    if spec.get("couplings") is not None:
        unit = spec.get("angle_unit", "rad")
        require(unit in ("deg", "rad"), f"{where}: angle_unit: {unit!r}; use deg or rad (of the couplings' numbers)")
        built = replace(robot, chain=with_couplings(robot.chain, spec["couplings"], f"{where}: couplings",
                                                    unit == "deg"))
        require(built.joint_names == robot.joint_names, f"{where}: couplings: the robot as built must read the same "
                                                        f"joints as {robot.source or 'the robot file'} "
                                                        f"({', '.join(robot.joint_names)}); keep each joint's own name "
                                                        f"in its value exactly where the robot file does")
    resolved = dict(spec)
    resolved["constant"] = {"values": {n: float(v) for n, v in zip(robot.error_names(), const)}}
    resolved["joint_offsets"] = {"values": offsets.tolist()}
    return Truth(const, offsets, tuple(sources), np.array(spec.get("gravity", GRAVITY), float), masses,
                 float(noise.get("repeatability", 0.0)), float(noise.get("tracker", 0.0)), resolved,
                 float(noise.get("orientation", 0.0)), built)


def gravity_torques(robot: Robot, truth: Truth, q: np.ndarray, payload_kg: np.ndarray,
                    payload_at: np.ndarray) -> np.ndarray:
    """Static torque on every revolute joint variable (N, n), N m, from the link masses beyond it and
    the payload, on the nominal chain: by virtual work, the sum over the frames it moves of each
    frame's load times dv_i/dq_k (its own frame's, and its coupled joints' times their multipliers)."""
    F = frames(robot, q)
    N = len(q)
    points = []  # (mass (N,), world position (N, 3), the frame it is rigid with)
    tau = np.zeros((N, robot.n))
    if truth.masses == "urdf":
        revolute = [i for i, j in enumerate(robot.joints) if j.kind == "R"]
        tau[:, revolute] = robot_gravity_torques(robot, q, [robot.joints[i].name for i in revolute], truth.gravity)
    for m in () if truth.masses == "urdf" else truth.masses:
        at = np.array(m.get("at", [0, 0, 0]), float)
        W = F[m["frame"]]
        points.append((np.full(N, float(m["mass"])), W[:, :3, :3] @ at + W[:, :3, 3], m["frame"]))
    tip, _ = robot.tips()[0]  # the payload hangs from the first branch's tool
    tool = F[robot.n_frames + 1]
    points.append((payload_kg, tool[:, :3, :3] @ payload_at + tool[:, :3, 3], tip))
    for i, (joint, (terms, _)) in enumerate(zip(robot.chain, robot.drives())):
        J = F[robot.parent(i + 1)] @ constant(joint.pre)  # the frame the joint axis is expressed in
        axis = J[:, :3, :3] @ np.array([float(a) for a in joint.axis])
        carried = set(robot.subtree(i + 1))
        for mass, pos, frame in points:
            if frame not in carried:
                continue
            load = mass[:, None] * truth.gravity  # a prismatic coupled joint's force along its axis, times m/rad
            moment = np.einsum("ni,ni->n", np.cross(pos - J[:, :3, 3], load) if joint.kind == "R" else load, axis)
            for k, mult in terms:
                if robot.joints[k].kind == "R":
                    tau[:, k] += float(mult) * moment
    return tau


def frame_wrenches(robot: Robot, truth: Truth, q: np.ndarray, payload_kg: np.ndarray,
                   payload_at: np.ndarray) -> np.ndarray:
    """The static wrench every frame 0..m carries (N, m+1, 6): the weight of the links (the truth's
    masses) and of the payload at the first branch's tool, as force (N) and moment about the frame's
    origin (N m) in its axes, on the nominal chain. With `masses: urdf` the links' part comes from a
    walk down the URDF (`model.gravity`), independent of the load signals the fit uses."""
    F = frames(robot, q)
    N, m = len(q), robot.n_frames
    out = np.zeros((N, m + 1, 6))
    if truth.masses == "urdf":
        out += robot_frame_wrenches(robot, q, list(range(m + 1)), truth.gravity)
    tip, _ = robot.tips()[0]
    tool = F[m + 1]
    points = [(np.full(N, float(p["mass"])), F[p["frame"]][:, :3, :3] @ np.array(p.get("at", [0, 0, 0]), float)
               + F[p["frame"]][:, :3, 3], p["frame"]) for p in (() if truth.masses == "urdf" else truth.masses)]
    points.append((payload_kg, tool[:, :3, :3] @ payload_at + tool[:, :3, 3], tip))
    for f in range(m + 1):
        R, o = F[f][:, :3, :3], F[f][:, :3, 3]
        carried = set(robot.subtree(f))
        for mass, pos, frame in points:
            if frame in carried:
                weight = mass[:, None] * truth.gravity
                out[:, f, :3] += np.einsum("nji,nj->ni", R, weight)
                out[:, f, 3:] += np.einsum("nji,nj->ni", R, np.cross(pos - o, weight))
    return out


def true_state(robot: Robot, truth: Truth, q: np.ndarray, payload_kg: np.ndarray, payload_at: np.ndarray,
               aux: dict[str, np.ndarray], approach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True joints (N, n) and generalized errors (N, 6(n+1)) at read joints q.

    approach (N, n): sign of the last motion of each joint before the pose (for backlash)."""
    N = len(q)
    dq = np.tile(truth.joint_offsets, (N, 1))
    eps = np.tile(truth.constant, (N, 1))
    tau = wrench = None
    for s in truth.sources:
        p = s.params
        if s.kind == "sinusoid":
            value = p["amplitude"] * np.sin(2 * np.pi * q[:, p["variable"]] / p["period"] + p.get("phase", 0.0))
            if "error" in p:
                eps[:, p["error"][0]] += p["error"][1] * value
            else:
                dq[:, p["joint"]] += value
        elif s.kind == "cantilever":
            length = q[:, p["joint"]] + p.get("offset", 0.0)  # extension of the beam, m
            weight = (p.get("mass", 0.0) + payload_kg) * np.linalg.norm(truth.gravity)
            if "deflection" in p:  # tip deflection W L^3 / (3 EI), flexibility = 1 / EI
                eps[:, p["deflection"][0]] += p["deflection"][1] * p["flexibility"] * weight * length ** 3 / 3
            if "slope" in p:  # tip slope W L^2 / (2 EI)
                eps[:, p["slope"][0]] += p["slope"][1] * p["flexibility"] * weight * length ** 2 / 2
        elif s.kind in ("compliance", "play"):
            if tau is None:
                tau = gravity_torques(robot, truth, q, payload_kg, payload_at)
            load = tau[:, p["joint"]]
            dq[:, p["joint"]] += p["compliance"] * load if s.kind == "compliance" else 0.5 * p["width"] * np.sign(load)
        elif s.kind in ("frame_compliance", "beam"):
            if wrench is None:
                wrench = frame_wrenches(robot, truth, q, payload_kg, payload_at)
            f = p["frame"]
            eps[:, 6 * f:6 * f + 6] += wrench[:, f] @ p["matrix"].T
        elif s.kind == "backlash":
            dq[:, p["joint"]] += 0.5 * p["width"] * approach[:, p["joint"]]
        elif s.kind == "thermal":
            require(p["column"] in aux, f"thermal source needs the auxiliary column '{p['column']}' in the design")
            eps[:, p["error"][0]] += p["error"][1] * p["per_kelvin"] * (aux[p["column"]] - p.get("reference", 20.0))
    return q + dq, eps


def thermal_profile(truth: Truth, n_poses: int) -> dict[str, np.ndarray]:
    """Temperatures over a measurement session: a linear drift from start to end (deg C)."""
    out = {}
    for s in truth.sources:
        if s.kind == "thermal":
            ref = s.params.get("reference", 20.0)
            out[s.params["column"]] = np.linspace(s.params.get("start", ref), s.params.get("end", ref + 6.0), n_poses)
    return out

