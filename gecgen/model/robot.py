"""Robot files: kinematics, targets and wrench frame of one robot (CONTRACTS.md section 1).

A robot is a serial chain of frames 0..n. Frame 0 is the base; frame i sits after link i:

    W_0 = base * E_0,      W_i = W_{i-1} * pre_i * M_i(q_i) * post_i * E_i,      tool = W_n * T_tool

`M_i` is the joint motion (rotation about, or translation along, the unit `axis`), `pre_i` and
`post_i` are constant transforms and `E_i` the six generalized errors of frame i. A DH row
`Rz(theta+q) Tz(d+q) Tx(a) Rx(alpha)` becomes `pre = I`, `axis = z`,
`post = Rz(theta) Tz(d) Tx(a) Rx(alpha)`; a URDF joint becomes `pre = origin`, `post = I`.

Constant transforms are kept as exact sympy numbers (90 degrees stays pi/2) so the symbolic
chain prunes exact zeros; `model.kinematics` evaluates them in floating point.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import sympy as sp

from gecgen.model.validation import read_yaml, require, require_keys

#: An elementary transform: ("Tx"|"Ty"|"Tz"|"Rx"|"Ry"|"Rz", value) or ("H", 4x4 rows).
Elementary = tuple

WRENCH = ("fx", "fy", "fz", "mx", "my", "mz")
ERROR_NAMES = ("ex", "ey", "ez", "es", "er", "ep")
#: standard gravity, m/s^2, in the robot file's world frame unless the file's `gravity` says otherwise
GRAVITY = (0, 0, -9.80665)


@dataclass(frozen=True)
class Joint:
    """One moving joint and the link after it; lengths in m, angles in rad."""

    name: str
    kind: str  # "R" revolute or "P" prismatic
    axis: tuple  # unit vector (exact sympy numbers) in the frame after `pre`
    pre: tuple[Elementary, ...]
    post: tuple[Elementary, ...]
    lower: float  # joint limits, m or rad
    upper: float


@dataclass(frozen=True)
class Robot:
    """Nominal kinematics of one robot plus its measurement targets (tool-frame xyz, m)."""

    name: str
    joints: tuple[Joint, ...]
    base: tuple[Elementary, ...]
    tool: tuple[Elementary, ...]
    targets: dict[str, tuple[float, float, float]]
    wrench_frame: str = "tool"
    points: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    source: str = ""
    source_hashes: dict[str, str] = field(default_factory=dict)
    urdf: str = ""  # the URDF file a robot file names (its masses give gravity torques), else ""
    base_link: str = ""
    gravity: tuple = tuple(sp.Rational(repr(v)) for v in GRAVITY)  # world, m/s^2, exact numbers

    @property
    def n(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def target_names(self) -> tuple[str, ...]:
        return tuple(self.targets)

    @property
    def n_errors(self) -> int:
        """Number of generalized errors, 6(n+1)."""
        return 6 * (self.n + 1)

    def error_names(self) -> list[str]:
        """Names like '3.ey' in the order of the generalized error vector eps."""
        return [f"{i}.{e}" for i in range(self.n + 1) for e in ERROR_NAMES]


def exact(value, where: str, unit_deg: bool = False) -> sp.Expr:
    """A YAML number as an exact sympy number; degrees become exact multiples of pi."""
    require(isinstance(value, (int, float)) and not isinstance(value, bool),
            f"{where}: expected a number, got {value!r}")
    v = sp.Rational(repr(value)) if isinstance(value, float) else sp.Integer(value)
    return v * sp.pi / 180 if unit_deg else v


def _vector(value, where: str, length: int = 3) -> tuple:
    require(isinstance(value, list) and len(value) == length,
            f"{where}: expected a list of {length} numbers, got {value!r}")
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
    require(lo < hi, f"{where}: lower limit {value[0]} must be below upper limit {value[1]}")
    return lo, hi


def _dh_joint(row, k: int, where: str, deg: bool) -> Joint:
    where = f"{where}: joints[{k}]"
    require(isinstance(row, dict), f"{where}: expected a mapping with type, theta, d, a, alpha, limits")
    require_keys(row, where, required={"type", "a", "alpha", "limits"},
                 optional={"name", "theta", "d"})
    kind = row["type"]
    require(kind in ("R", "P"), f"{where}.type: unknown joint type {kind!r}; use R (revolute) or P (prismatic)")
    name = row.get("name", f"q{k + 1}")
    require(isinstance(name, str) and name.isidentifier(), f"{where}.name: {name!r} is not a valid identifier")
    theta = exact(row.get("theta", 0), f"{where}.theta", deg)
    post = (("Rz", theta), ("Tz", exact(row.get("d", 0), f"{where}.d")),
            ("Tx", exact(row["a"], f"{where}.a")), ("Rx", exact(row["alpha"], f"{where}.alpha", deg)))
    lo, hi = _limits(row["limits"], f"{where}.limits", kind, deg)
    return Joint(name, kind, (sp.Integer(0), sp.Integer(0), sp.Integer(1)), (),
                 tuple(op for op in post if op[1] != 0), lo, hi)


def _targets(spec, where: str) -> dict[str, tuple[float, float, float]]:
    require(isinstance(spec, dict) and spec, f"{where}: targets must map names to [x, y, z] in the tool frame")
    out = {}
    for name, xyz in spec.items():
        require(isinstance(name, str) and name.isidentifier(), f"{where}.{name}: target names must be identifiers")
        out[name] = tuple(float(v) for v in _vector(xyz, f"{where}.{name}"))
    return out


def file_hash(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def load_robot(path: str | Path) -> Robot:
    """Read and validate a robot file (YAML); every problem names the file, the key and the fix."""
    path = Path(path)
    where = str(path)
    spec = read_yaml(path, "robot")
    require(isinstance(spec, dict), f"{where}: expected a mapping at the top level")
    require_keys(spec, where, required={"name", "targets"},
                 optional={"description", "angle_unit", "base", "tool", "joints", "urdf", "base_link",
                           "tip_link", "wrench_frame", "points", "gravity"})
    unit = spec.get("angle_unit", "rad")
    require(unit in ("deg", "rad"), f"{where}: angle_unit: {unit!r}; use deg or rad")
    deg = unit == "deg"
    name = spec["name"]
    require(isinstance(name, str) and name.isidentifier(), f"{where}: name: {name!r} must be an identifier (it names C functions)")
    hashes = {path.name: file_hash(path)}
    base = _transform(spec.get("base"), f"{where}: base", deg)
    urdf_path = None
    if "urdf" in spec:
        from gecgen.model.urdf import urdf_chain

        require("joints" not in spec, f"{where}: give either joints (DH) or urdf, not both")
        for key in ("base_link", "tip_link"):
            require(key in spec, f"{where}: missing key '{key}' (needed with urdf)")
        urdf_path = path.parent / str(spec["urdf"])
        require(urdf_path.is_file(), f"{where}: urdf: no such file {urdf_path}")
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
    names = [j.name for j in joints]
    require(len(set(names)) == len(names), f"{where}: joint names must be unique, got {names}")
    wrench_frame = spec.get("wrench_frame", "tool")
    require(wrench_frame == "tool" or (isinstance(wrench_frame, int) and 0 <= wrench_frame <= len(joints)),
            f"{where}: wrench_frame: {wrench_frame!r}; use 'tool' or a frame number 0..{len(joints)}")
    points = {k: tuple(float(v) for v in _vector(p, f"{where}: points.{k}"))
              for k, p in (spec.get("points") or {}).items()}
    return Robot(name=name, joints=tuple(joints), base=base, tool=tool,
                 targets=_targets(spec["targets"], f"{where}: targets"), wrench_frame=wrench_frame,
                 points=points, source=str(path), source_hashes=hashes,
                 urdf=str(urdf_path or ""), base_link=str(spec["base_link"]) if urdf_path else "",
                 gravity=_vector(spec.get("gravity", list(GRAVITY)), f"{where}: gravity"))
