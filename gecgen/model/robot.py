"""Robot files: kinematics, targets and wrench frame of one robot (CONTRACTS.md section 1).

A robot is a serial chain of frames 0..m. Frame 0 is the base; frame i sits after link i:

    W_0 = base * E_0,      W_i = W_{i-1} * pre_i * M_i(v_i) * post_i * E_i,      tool = W_m * T_tool

`M_i` is the joint motion (rotation about, or translation along, the unit `axis`), `pre_i` and
`post_i` are constant transforms and `E_i` the six generalized errors of frame i. The joint
variables q1..qn are the controller's joint readings, one per joint that has one, in chain order;
the value v_i of frame i's joint is its own reading, or for a coupled joint an affine map of
readings: v_i = sum_k a_ik q_k + b_i (`Coupling`). A coupling comes from the robot file's
`couplings` (a FANUC J3 that reads the forearm's angle to the horizontal: the chain's joint 3 is
J2 + J3; a parallelogram; gears between wrist axes; a passive joint tied to others) or from a URDF
`<mimic>` (one followed joint, no reading of its own). Frames and readings are counted apart:
`Robot.chain` holds the m moving joints (the frames 1..m of the error model), `Robot.joints` the n
that have a reading (the columns q1..qn of every file and of the generated code); without
couplings they are the same. A DH row
`Rz(theta+q) Tz(d+q) Tx(a) Rx(alpha)` becomes `pre = I`, `axis = z`,
`post = Rz(theta) Tz(d) Tx(a) Rx(alpha)`; a URDF joint becomes `pre = origin`, `post = I`.

Constant transforms are kept as exact sympy numbers (90 degrees stays pi/2) so the symbolic
chain prunes exact zeros; `model.kinematics` evaluates them in floating point.
"""
from __future__ import annotations

import ast
import hashlib
import math
import re
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import sympy as sp

from gecgen.model.validation import ModelError, excerpt, read_yaml, require, require_keys

#: An elementary transform: ("Tx"|"Ty"|"Tz"|"Rx"|"Ry"|"Rz", value) or ("H", 4x4 rows).
Elementary = tuple

WRENCH = ("fx", "fy", "fz", "mx", "my", "mz")
ERROR_NAMES = ("ex", "ey", "ez", "es", "er", "ep")
#: standard gravity, m/s^2, in the robot file's world frame unless the file's `gravity` says otherwise
GRAVITY = (0, 0, -9.80665)
#: names of the term language (functions, pi) and of the generated code's variables: neither a joint
#: nor an auxiliary signal may take them
RESERVED = {"pi", "sqrt", "sin", "cos", "sign", "abs", "poly", "fourier", "wrench_torque", "gravity",
            "gravity_torque", "q", "eps", "w", "aux", "c", "f", "p", "J", "T", "Jq", "H", "ca", "np"}


@dataclass(frozen=True)
class Coupling:
    """A joint whose value is an affine map of the controller's readings: the sum over `terms` of
    multiplier * reading, plus `offset`, in its own unit (m or rad) per the reading's unit.

    `own`: the joint has a reading of its own (then one of the terms; the FANUC J3), else it is
    passive (a URDF `<mimic>`, a humanoid torso joint that is -(q2 + q3)). `declared`: the robot
    file's `couplings` states it, and its multipliers are calibration parameters (`ratio_terms`);
    a URDF `<mimic>` read as it is keeps the model it has always had."""

    terms: tuple[tuple[str, sp.Expr], ...]  # (reading joint's name, exact nonzero multiplier), chain order
    offset: sp.Expr  # exact number, m or rad
    own: bool = False
    declared: bool = False

    def text(self, robot: "Robot") -> str:
        """The value in the readings q<k> ("1.0*q2 + 1.0*q3 + 0.0"), as the generated header shows it."""
        parts = [(float(m), f"*q{robot.joint_names.index(name) + 1}") for name, m in self.terms]
        text = f"{parts[0][0]!r}{parts[0][1]}"
        for value, tail in parts[1:] + [(float(self.offset), "")]:
            text += f" {'-' if value < 0 else '+'} {abs(value)!r}{tail}"
        return text


@dataclass(frozen=True)
class Joint:
    """One moving joint and the link after it; lengths in m, angles in rad. An independent joint's
    limits include what its mimic joints' limits allow (see `urdf.urdf_chain`)."""

    name: str
    kind: str  # "R" revolute or "P" prismatic
    axis: tuple  # unit vector (exact sympy numbers) in the frame after `pre`
    pre: tuple[Elementary, ...]
    post: tuple[Elementary, ...]
    lower: float  # joint limits, m or rad (of its reading; a passive joint's are not checked)
    upper: float
    coupling: Coupling | None = None

    @property
    def reads(self) -> bool:
        """The controller reports this joint (it has a variable q<k>)."""
        return self.coupling is None or self.coupling.own


@dataclass(frozen=True)
class Robot:
    """Nominal kinematics of one robot plus its measurement targets (tool-frame xyz, m)."""

    name: str
    chain: tuple[Joint, ...]  # the moving joints, frames 1..m in order (passive joints included)
    base: tuple[Elementary, ...]
    tool: tuple[Elementary, ...]
    targets: dict[str, tuple[float, float, float]]
    wrench_frame: str = "tool"
    #: targets whose placement the robot file leaves to the data (`estimate`); they sit at the tool
    #: origin until `runtime.placement` places them, and nothing is fitted or compensated before
    estimated: tuple[str, ...] = ()
    points: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    source: str = ""
    source_hashes: dict[str, str] = field(default_factory=dict)
    urdf: str = ""  # the URDF file a robot file names (its masses give gravity torques), else ""
    base_link: str = ""
    tip_link: str = ""  # with urdf: the link the tool hangs from
    gravity: tuple = tuple(sp.Rational(repr(v)) for v in GRAVITY)  # world, m/s^2, exact numbers
    #: virtual targets standing for measured orientations (`model.pose_targets`): name -> (the
    #: target whose frame they sample, vertex 0..3); none in a robot file
    vertex_of: dict[str, tuple[str, int]] = field(default_factory=dict)
    pose_length: float = 0.0  # m: 1 rad of orientation error counts as this much position error
    #: the frames pose measurements give, where they are not parallel to the tool frame: target ->
    #: rotation vector (rad) of the measured frame in the tool frame; estimated by
    #: `runtime.placement` from the measured orientations, none in a robot file
    target_frames: dict[str, tuple[float, float, float]] = field(default_factory=dict)

    @property
    def joints(self) -> tuple[Joint, ...]:
        """The joints with a reading: joint variable k is q<k+1>."""
        return tuple(j for j in self.chain if j.reads)

    @property
    def n(self) -> int:
        """Number of joint variables q1..qn."""
        return len(self.joints)

    @property
    def n_frames(self) -> int:
        """Number of moving frames m (the last frame's number); n plus the passive joints."""
        return len(self.chain)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def drives(self) -> list[tuple[tuple[tuple[int, sp.Expr], ...], sp.Expr]]:
        """Per frame 1..m: ((variable k 0-based, multiplier), ...), offset); its joint's value is the
        sum of multiplier * q[k] plus the offset (((own k, 1),), 0 for a joint that is its reading)."""
        index = {name: k for k, name in enumerate(self.joint_names)}
        out = []
        for j in self.chain:
            if j.coupling is None:
                out.append((((index[j.name], sp.Integer(1)),), sp.Integer(0)))
            else:
                out.append((tuple((index[name], m) for name, m in j.coupling.terms), j.coupling.offset))
        return out

    def driven(self, k: int) -> list[tuple[int, sp.Expr]]:
        """The frames (1-based, ascending) whose joint variable k (0-based) moves, with multipliers
        (dv_i/dq_k): its own frame and those of the joints coupled to it."""
        return [(i, m) for i, (terms, _) in enumerate(self.drives(), start=1) for v, m in terms if v == k]

    def frame_of(self, k: int) -> int:
        """The frame (1-based) of the joint whose reading is q<k+1> (k 0-based)."""
        return [i for i, j in enumerate(self.chain, start=1) if j.reads][k]

    def zero_offset_error(self, i: int) -> tuple[int, float] | None:
        """(eps index, sign) of the generalized error that is the zero offset of frame i's joint (i
        from 1), or None when its axis is not along an axis of the adjacent frame or constant
        transforms sit on both sides of its motion.

        The error adjacent to the motion that turns about (revolute) or moves along (prismatic) its
        axis: for a URDF joint (no constant transform after the motion) that of frame i, right after
        it; for a DH joint (none before it) that of frame i-1, right before it: `er` of frame i-1 for
        a revolute joint i (`ez` for a prismatic one), or with a URDF axis along -x, -y or -z the
        matching error with its sign turned. Alone, that error equals the joint value off by its
        value: M_i(v) Rot(u, d) = M_i(v + d) and Rz(d) Rz(v) = Rz(v + d)."""
        joint = self.chain[i - 1]
        u = [float(a) for a in joint.axis]
        frame = i if not joint.post else i - 1 if not joint.pre else None
        k = max(range(3), key=lambda a: abs(u[a]))
        if frame is None or abs(abs(u[k]) - 1) > 1e-12:
            return None
        name = ("ex", "ey", "ez")[k] if joint.kind == "P" else ("ep", "es", "er")[k]
        return 6 * frame + ERROR_NAMES.index(name), math.copysign(1.0, u[k])

    def ratio_terms(self) -> dict[int, list[str]]:
        """The coupling ratios that are calibration parameters: eps index -> terms ["q<k>", ...].

        A declared coupling's joint value moves with reading k by its multiplier; an error d in that
        multiplier turns the joint by d q_k, which is term q_k on the joint's zero-offset error
        (exactly: Rz(d q_k) Rz(v) = Rz(v + d q_k)), its coefficient d times the error's sign. Its own
        reading's multiplier is the joint's scale, left out as for every uncoupled joint; a joint
        with no single zero-offset error carries none (`load_robot` warns)."""
        out: dict[int, list[str]] = {}
        for i, (j, (terms, _)) in enumerate(zip(self.chain, self.drives()), start=1):
            found = self.zero_offset_error(i) if j.coupling is not None and j.coupling.declared else None
            own = self.joint_names.index(j.name) if j.reads else None
            for k, _ in terms if found else ():
                if k != own:
                    out.setdefault(found[0], []).append(f"q{k + 1}")
        return out

    @property
    def target_names(self) -> tuple[str, ...]:
        return tuple(self.targets)

    @property
    def n_errors(self) -> int:
        """Number of generalized errors, 6(m+1)."""
        return 6 * (self.n_frames + 1)

    def require_placed(self):
        """Refuse (one line) to build anything on targets that still wait for measured data."""
        require(not self.estimated, f"{self.source}: target '{self.estimated[0] if self.estimated else ''}' is left "
                                    f"to estimate: place it from measured data first (identify, diagnose and calibrate "
                                    f"do; runtime.placement.place_targets)")

    def error_names(self) -> list[str]:
        """Names like '3.ey' in the order of the generalized error vector eps."""
        return [f"{i}.{e}" for i in range(self.n_frames + 1) for e in ERROR_NAMES]


def exact(value, where: str, unit_deg: bool = False) -> sp.Expr:
    """A YAML number as an exact sympy number; degrees become exact multiples of pi."""
    require(isinstance(value, (int, float)) and not isinstance(value, bool),
            f"{where}: expected a number, got {excerpt(value)}")
    require(_finite(value), f"{where}: {excerpt(value)} is not a finite number; write the value")
    v = sp.Rational(repr(value)) if isinstance(value, float) else sp.Integer(value)
    return v * sp.pi / 180 if unit_deg else v


def _finite(value) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer beyond any float
        return False


def _vector(value, where: str, length: int = 3) -> tuple:
    require(isinstance(value, list) and len(value) == length,
            f"{where}: expected a list of {length} numbers, got {excerpt(value)}")
    return tuple(exact(v, f"{where}[{k}]") for k, v in enumerate(value))


def _transform(spec, where: str, deg: bool) -> tuple[Elementary, ...]:
    """A fixed transform from `{origin: [x,y,z], rotation: 3x3 rows}` or `{origin, rpy}`."""
    if spec is None:
        return ()
    require(isinstance(spec, dict), f"{where}: expected a mapping with origin and rotation or rpy")
    require_keys(spec, where, optional={"origin", "rotation", "rpy"})
    require(not ("rotation" in spec and "rpy" in spec), f"{where}: give either rotation or rpy, not both")
    origin = _vector(spec.get("origin", [0, 0, 0]), f"{where}.origin")
    ops: list[Elementary] = []
    if "rotation" in spec:
        rows = spec["rotation"]
        require(isinstance(rows, list) and len(rows) == 3,
                f"{where}.rotation: expected 3 rows of 3 numbers (columns are the child axes)")
        R = sp.Matrix([_vector(r, f"{where}.rotation[{k}]") for k, r in enumerate(rows)])
        err = (R.T * R - sp.eye(3)).applyfunc(lambda x: abs(float(x)))
        require(max(err) < 1e-9 and float(R.det()) > 0,
                f"{where}.rotation: not a proper rotation matrix (R^T R != I or det != 1); fix the rows")
        H = sp.eye(4)
        H[:3, :3] = R
        H[:3, 3] = sp.Matrix(origin)
        return (("H", tuple(tuple(H.row(k)) for k in range(4))),)
    ops += [("Tx", origin[0]), ("Ty", origin[1]), ("Tz", origin[2])]
    if "rpy" in spec:
        rpy = spec["rpy"]
        require(isinstance(rpy, list) and len(rpy) == 3, f"{where}.rpy: expected [roll, pitch, yaw]")
        r, p, y = (exact(v, f"{where}.rpy[{k}]", deg) for k, v in enumerate(rpy))
        ops += [("Rz", y), ("Ry", p), ("Rx", r)]  # URDF convention: R = Rz(y) Ry(p) Rx(r)
    return tuple(op for op in ops if not (op[0] != "H" and op[1] == 0))


def _limits(value, where: str, kind: str, deg: bool) -> tuple[float, float]:
    require(isinstance(value, list) and len(value) == 2, f"{where}: expected [lower, upper]")
    lo, hi = (float(exact(v, f"{where}[{k}]", deg and kind == "R")) for k, v in enumerate(value))
    require(lo < hi, f"{where}: lower limit {excerpt(value[0])} must be below upper limit {excerpt(value[1])}")
    return lo, hi


def _dh_joint(row, k: int, where: str, deg: bool) -> Joint:
    where = f"{where}: joints[{k}]"
    require(isinstance(row, dict), f"{where}: expected a mapping with type, theta, d, a, alpha, limits")
    require_keys(row, where, required={"type", "a", "alpha", "limits"},
                 optional={"name", "theta", "d"})
    kind = row["type"]
    require(kind in ("R", "P"), f"{where}.type: unknown joint type {excerpt(kind)}; use R (revolute) or P (prismatic)")
    name = row.get("name", f"q{k + 1}")
    require(isinstance(name, str) and name.isidentifier(), f"{where}.name: {excerpt(name)} is not a valid identifier")
    theta = exact(row.get("theta", 0), f"{where}.theta", deg)
    post = (("Rz", theta), ("Tz", exact(row.get("d", 0), f"{where}.d")),
            ("Tx", exact(row["a"], f"{where}.a")), ("Rx", exact(row["alpha"], f"{where}.alpha", deg)))
    lo, hi = _limits(row["limits"], f"{where}.limits", kind, deg)
    return Joint(name, kind, (sp.Integer(0), sp.Integer(0), sp.Integer(1)), (),
                 tuple(op for op in post if op[1] != 0), lo, hi)


#: the value of a target whose position on the tool the data is to give
ESTIMATE = "estimate"


def _targets(spec, where: str) -> tuple[dict[str, tuple[float, float, float]], tuple[str, ...]]:
    """Targets (name -> tool-frame xyz, m) and the names of those left to estimate (at the origin)."""
    require(isinstance(spec, dict) and spec, f"{where}: targets must map names to [x, y, z] in the tool frame, "
                                             f"or to '{ESTIMATE}'")
    out = {}
    for name, xyz in spec.items():
        require(isinstance(name, str) and name.isidentifier(),
                f"{where}: {excerpt(name)}: target names must be identifiers")
        out[name] = (0.0, 0.0, 0.0) if xyz == ESTIMATE else tuple(float(v) for v in _vector(xyz, f"{where}.{name}"))
    return out, tuple(n for n, xyz in spec.items() if xyz == ESTIMATE)


def _affine(text, names: list[str], where: str) -> tuple[dict[str, sp.Expr], sp.Expr]:
    """A coupling's value `text` ("J2 + J3", "-(t2 + t3)", "0.5*j4 + j5 - 10") as multipliers by
    joint name and an offset, exact; only numbers, joint names, + - * / and parentheses."""
    require(isinstance(text, str) and text.strip(), f"{where}: expected the joint's value in the readings as a "
                                                    f"text such as \"J2 + J3\", got {excerpt(text)}")
    symbols = {n: sp.Symbol(f"_{n}") for n in names}

    def walk(node):
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            require(_finite(node.value), f"{where}: {excerpt(text)} holds a number beyond floating point")
            return sp.Rational(repr(node.value)) if isinstance(node.value, float) else sp.Integer(node.value)
        if isinstance(node, ast.Name):
            require(node.id in symbols, f"{where}: {excerpt(text)}: '{node.id}' is not a joint of this robot; "
                                        f"use the joint names ({', '.join(names)})")
            return symbols[node.id]
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            return -walk(node.operand) if isinstance(node.op, ast.USub) else walk(node.operand)
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
            a, b = walk(node.left), walk(node.right)
            if isinstance(node.op, ast.Div):
                require(b.is_number and b != 0, f"{where}: {excerpt(text)}: divide only by a nonzero number")
                return a / b
            return a + b if isinstance(node.op, ast.Add) else a - b if isinstance(node.op, ast.Sub) else a * b
        raise ModelError(f"{where}: {excerpt(text)} is not an affine map of the readings; write a sum of "
                         f"number * joint name plus a number, such as \"J2 + J3\" or \"-0.5*j4 + 0.1\"")

    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError:
        raise ModelError(f"{where}: {excerpt(text)} is not an expression; write e.g. \"J2 + J3\"") from None
    value = sp.expand(walk(tree.body))
    poly = sp.Poly(value, *symbols.values())
    require(poly.total_degree() <= 1, f"{where}: {excerpt(text)} is not affine in the readings (a product or power "
                                      f"of joints); a coupling is a sum of number * joint plus a number")
    multipliers = {n: value.coeff(x) for n, x in symbols.items() if value.coeff(x) != 0}
    require(multipliers, f"{where}: {excerpt(text)} depends on no joint; a joint that never moves is a fixed transform")
    return multipliers, value.subs({x: 0 for x in symbols.values()})


def with_couplings(chain: tuple[Joint, ...], spec, where: str, deg: bool) -> tuple[Joint, ...]:
    """The chain with the robot file's `couplings` (joint name -> its value in the readings) set.

    A coupled joint whose value names itself keeps its reading (the FANUC J3: `J3: J2 + J3`); one
    that does not is passive, with no reading. Numbers are in the file's units (deg or rad, m): a
    multiplier from a revolute reading onto a prismatic joint is m per deg in a deg file. A coupling
    replaces what a URDF `<mimic>` says of that joint."""
    if spec is None:
        return chain
    require(isinstance(spec, dict) and spec, f"{where}: expected a mapping from joint names to their values in the "
                                             f"readings, such as {{J3: \"J2 + J3\"}}")
    names = [j.name for j in chain]
    values = {}
    for name, text in spec.items():
        require(name in names, f"{where}: {excerpt(name)} is not a joint on the chain; couple one of {', '.join(names)}")
        values[name] = _affine(text, names, f"{where}.{name}")
    kinds = {j.name: j.kind for j in chain}

    def scale(kind: str) -> sp.Expr:  # rad (or m) per unit of the file
        return sp.pi / 180 if deg and kind == "R" else sp.Integer(1)

    out = []
    for j in chain:
        if j.name not in values:
            out.append(j)
            continue
        multipliers, offset = values[j.name]
        terms = tuple((n, multipliers[n] * scale(j.kind) / scale(kinds[n])) for n in names if n in multipliers)
        out.append(replace(j, coupling=Coupling(terms, offset * scale(j.kind), own=j.name in multipliers,
                                                declared=True)))
    readings = {j.name for j in out if j.reads}
    for j in out:
        for n, _ in j.coupling.terms if j.coupling else ():
            require(n in readings, f"{where}: joint {excerpt(j.name)} follows {excerpt(n)}, which has no reading of its "
                                   f"own (it is coupled without naming itself); write {excerpt(j.name)}'s value in "
                                   f"the joints the controller reads")
    return tuple(out)


def _check_joint_names(joints, place):
    """Joint names are aliases of q1..qn in error terms, so a name that means something else there
    would silently change what a term measures. `place(k)` says where joint k's name is written."""
    seen: dict[str, int] = {}
    for k, joint in enumerate(joints):
        name = joint.name
        if re.fullmatch(r"q\d+", name) and name != f"q{k + 1}":
            why = f"is spelled like a joint variable but names joint {k + 1} (its own is q{k + 1})"
        elif name in WRENCH:
            why = "is a wrench component (fx fy fz mx my mz)"
        elif name in RESERVED:
            why = "is reserved by the error terms and the generated code"
        elif name in seen:
            why = f"is also the name of joint {seen[name] + 1} (q{seen[name] + 1})"
        else:
            seen[name] = k
            continue
        raise ModelError(f"{place(k)} {excerpt(name)} {why}; rename the joint")


def file_hash(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def load_robot(path: str | Path) -> Robot:
    """Read and validate a robot file (YAML); every problem names the file, the key and the fix."""
    path = Path(path)
    where = str(path)
    spec = read_yaml(path, "robot")
    require(isinstance(spec, dict), f"{where}: expected a mapping at the top level")
    # no default: a file written in degrees and read as radians turns 90 deg into 90 rad
    require("angle_unit" in spec, f"{where}: missing key 'angle_unit'; add 'angle_unit: deg' or 'angle_unit: rad' "
                                  f"(the unit of every angle in the file)")
    require_keys(spec, where, required={"name", "targets", "angle_unit"},
                 optional={"description", "base", "tool", "joints", "urdf", "base_link",
                           "tip_link", "wrench_frame", "points", "gravity", "couplings"})
    unit = spec["angle_unit"]
    require(unit in ("deg", "rad"), f"{where}: angle_unit: {excerpt(unit)}; use deg or rad")
    deg = unit == "deg"
    name = spec["name"]
    require(isinstance(name, str) and name.isidentifier(),
            f"{where}: name: {excerpt(name)} must be an identifier (it names C functions)")
    hashes = {path.name: file_hash(path)}
    base = _transform(spec.get("base"), f"{where}: base", deg)
    urdf_path = None
    if "urdf" in spec:
        from gecgen.model.urdf import urdf_chain

        require("joints" not in spec, f"{where}: give either joints (DH) or urdf, not both")
        for key in ("base_link", "tip_link"):
            require(key in spec, f"{where}: missing key '{key}' (needed with urdf)")
            require(isinstance(spec[key], str), f"{where}: {key}: expected the name of a URDF link")
        require(isinstance(spec["urdf"], str), f"{where}: urdf: expected the path of a URDF file")
        urdf_path = path.parent / spec["urdf"]
        require(urdf_path.is_file(), f"{where}: urdf: no such file {excerpt(str(urdf_path))}")
        hashes[urdf_path.name] = file_hash(urdf_path)
        lead, joints, trail = urdf_chain(urdf_path, spec["base_link"], spec["tip_link"])
        base = base + lead
        tool = trail + _transform(spec.get("tool"), f"{where}: tool", deg)
    else:
        require("joints" in spec, f"{where}: missing key 'joints' (a list of DH rows) or 'urdf'")
        rows = spec["joints"]
        require(isinstance(rows, list) and rows, f"{where}: joints must be a non-empty list of DH rows")
        joints = tuple(_dh_joint(row, k, where, deg) for k, row in enumerate(rows))
        tool = _transform(spec.get("tool"), f"{where}: tool", deg)
    joints = with_couplings(tuple(joints), spec.get("couplings"), f"{where}: couplings", deg)
    rows = {j.name: k for k, j in enumerate(joints)}
    readers = [j for j in joints if j.reads]
    _check_joint_names(readers, (lambda k: f"{urdf_path}: joint") if urdf_path else
                       (lambda k: f"{where}: joints[{rows[readers[k].name]}].name:"))
    wrench_frame = spec.get("wrench_frame", "tool")
    require(wrench_frame == "tool" or (type(wrench_frame) is int and 0 <= wrench_frame <= len(joints)),
            f"{where}: wrench_frame: {excerpt(wrench_frame)}; use 'tool' or a frame number 0..{len(joints)}")
    points = spec.get("points") or {}
    require(isinstance(points, dict), f"{where}: points: expected a mapping from names to [x, y, z] in the world")
    points = {k: tuple(float(v) for v in _vector(p, f"{where}: points.{excerpt(str(k))}")) for k, p in points.items()}
    targets, estimated = _targets(spec["targets"], f"{where}: targets")
    robot = Robot(name=name, chain=tuple(joints), base=base, tool=tool, targets=targets, estimated=estimated,
                  wrench_frame=wrench_frame,
                  points=points, source=str(path), source_hashes=hashes,
                  urdf=str(urdf_path or ""), base_link=str(spec["base_link"]) if urdf_path else "",
                  tip_link=str(spec["tip_link"]) if urdf_path else "",
                  gravity=_vector(spec.get("gravity", list(GRAVITY)), f"{where}: gravity"))
    for i, j in enumerate(robot.chain, start=1):
        if j.coupling and j.coupling.declared and len(j.coupling.terms) > j.coupling.own \
                and robot.zero_offset_error(i) is None:
            warnings.warn(f"{where}: couplings.{j.name}: the joint's axis is not along an axis of the frame next to "
                          f"its motion, so its coupling ratios are not calibrated (only its frames' errors are)",
                          stacklevel=2)
    return robot
