"""Robot files (CONTRACTS.md section 1): read and validate a robot file into a `model.robot.Robot`.

DH rows or a URDF path (`model.urdf`), base and tool transforms, targets, and the `couplings` that
state coupled joints' values in the controller's readings; every problem names the file, the key
and the fix.
"""
from __future__ import annotations

import ast
import hashlib
import math
import re
import warnings
from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import numpy as np

from gecgen.model.exact import decimal_number, degrees, pi_factor, pi_multiple
from gecgen.model.robot import CONTROLLERS, GRAVITY, RESERVED, WRENCH, Branch, Coupling, Elementary, Joint, Robot
from gecgen.model.urdf import urdf_chain
from gecgen.model.validation import ModelError, excerpt, is_name, read_yaml, require, require_keys


def exact(value, where: str, unit_deg: bool = False):
    """A YAML number as an exact number (`model.exact`); degrees become exact multiples of pi."""
    require(isinstance(value, (int, float)) and not isinstance(value, bool),
            f"{where}: expected a number, got {excerpt(value)}")
    require(_finite(value), f"{where}: {excerpt(value)} is not a finite number; write the value")
    v = decimal_number(value)
    return degrees(v) if unit_deg else v


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
        R = [_vector(r, f"{where}.rotation[{k}]") for k, r in enumerate(rows)]
        Rf = np.array(R, dtype=float)
        require(np.abs(Rf.T @ Rf - np.eye(3)).max() < 1e-9 and np.linalg.det(Rf) > 0,
                f"{where}.rotation: not a proper rotation matrix (R^T R != I or det != 1); fix the rows")
        return (("H", tuple(tuple(row) + (o,) for row, o in zip(R, origin)) + ((0, 0, 0, 1),)),)
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
                 optional={"name", "theta", "d", "parent"})
    kind = row["type"]
    require(kind in ("R", "P"), f"{where}.type: unknown joint type {excerpt(kind)}; use R (revolute) or P (prismatic)")
    name = row.get("name", f"q{k + 1}")
    require(is_name(name), f"{where}.name: {excerpt(name)} is not an ASCII identifier; rename the joint")
    theta = exact(row.get("theta", 0), f"{where}.theta", deg)
    post = (("Rz", theta), ("Tz", exact(row.get("d", 0), f"{where}.d")),
            ("Tx", exact(row["a"], f"{where}.a")), ("Rx", exact(row["alpha"], f"{where}.alpha", deg)))
    lo, hi = _limits(row["limits"], f"{where}.limits", kind, deg)
    return Joint(name, kind, (0, 0, 1), (),
                 tuple(op for op in post if op[1] != 0), lo, hi)


#: characters of a coupling's value at most (a sum of a few number * joint terms)
MAX_COUPLING_LENGTH = 1000
#: a coupling's multipliers and offset at most, in SI units (rad or m per rad or m of reading; rad or m)
MAX_RATIO = 1e3
#: condition number of the readings-to-joints map at most
MAX_CONDITION = 1e6

#: the value of a target whose position on the tool the data is to give
ESTIMATE = "estimate"


def _targets(spec, where: str) -> tuple[dict[str, tuple[float, float, float]], tuple[str, ...]]:
    """Targets (name -> tool-frame xyz, m) and the names of those left to estimate (at the origin)."""
    require(isinstance(spec, dict) and spec, f"{where}: targets must map names to [x, y, z] in the tool frame, "
                                             f"or to '{ESTIMATE}'")
    out = {}
    for name, xyz in spec.items():
        require(is_name(name),
                f"{where}: {excerpt(name)}: target names must be identifiers")
        out[name] = (0.0, 0.0, 0.0) if xyz == ESTIMATE else tuple(float(v) for v in _vector(xyz, f"{where}.{name}"))
    return out, tuple(n for n, xyz in spec.items() if xyz == ESTIMATE)


def _affine(text, own: str, names: list[str], where: str) -> tuple[dict[str, Fraction], Fraction]:
    """Joint `own`'s coupling value `text` ("J2 + J3", "-(t2 + t3)", "0.5*j4 + j5 - 10") as
    multipliers by joint name and an offset, exact; only numbers, joint names, + - * / and parentheses."""
    require(isinstance(text, str) and text.strip(), f"{where}: expected the joint's value in the readings as a "
                                                    f"text such as \"J2 + J3\", got {excerpt(text)}")
    # the parser and the walk below recurse once per nested sign or bracket: a long text would end
    # in a MemoryError or RecursionError, and no coupling of a robot's joints needs this many
    require(len(text) <= MAX_COUPLING_LENGTH, f"{where}: {excerpt(text)} is longer than {MAX_COUPLING_LENGTH} "
                                              f"characters; a coupling is a short sum such as \"J2 + J3\"")
    nonlinear = (f"{where}: {excerpt(text)} is not affine in the readings (a product or power of joints); a "
                 f"coupling is a sum of number * joint plus a number")

    # a value is (multipliers by joint name, offset): an affine map, exact
    def walk(node) -> tuple[dict[str, Fraction], Fraction]:
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            require(_finite(node.value), f"{where}: {excerpt(text)} holds a number beyond floating point")
            return {}, Fraction(decimal_number(node.value))
        if isinstance(node, ast.Name):
            require(node.id in names, f"{where}: {excerpt(text)}: '{node.id}' is not a joint of this robot; "
                                      f"use the joint names ({', '.join(names)})")
            return {node.id: Fraction(1)}, Fraction(0)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
            value = walk(node.operand)
            return scaled(value, -1) if isinstance(node.op, ast.USub) else value
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
            a, b = walk(node.left), walk(node.right)
            if isinstance(node.op, ast.Div):
                require(not any(b[0].values()) and b[1] != 0, f"{where}: {excerpt(text)}: divide only by a nonzero "
                                                              f"number")
                return scaled(a, 1 / b[1])
            if isinstance(node.op, ast.Mult):
                require(not any(a[0].values()) or not any(b[0].values()), nonlinear)
                return scaled(b, a[1]) if not any(a[0].values()) else scaled(a, b[1])
            sign = 1 if isinstance(node.op, ast.Add) else -1
            return ({n: a[0].get(n, 0) + sign * b[0].get(n, 0) for n in {**a[0], **b[0]}}, a[1] + sign * b[1])
        raise ModelError(f"{where}: {excerpt(text)} is not an affine map of the readings; write a sum of "
                         f"number * joint name plus a number, such as \"J2 + J3\" or \"-0.5*j4 + 0.1\"")

    def scaled(value, k):
        return {n: m * k for n, m in value[0].items()}, value[1] * k

    try:
        tree = ast.parse(text.strip(), mode="eval")
        value = walk(tree.body)
    except SyntaxError:
        raise ModelError(f"{where}: {excerpt(text)} is not an expression; write e.g. \"J2 + J3\"") from None
    except (RecursionError, MemoryError):
        raise ModelError(f"{where}: {excerpt(text)} nests its signs or brackets too deeply; write the sum "
                         f"plainly, such as \"-J2 + J3\"") from None
    multipliers = {n: value[0][n] for n in names if value[0].get(n, 0) != 0}
    require(multipliers, f"{where}: {excerpt(text)} depends on no joint; a joint that never moves is a fixed transform")
    # a joint's own name whose multiplier cancels (0*J3, J3 - J3) would make the joint passive and
    # drop its reading, which shifts every later column of the data: the text says otherwise
    named = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}
    require(own in multipliers or own not in named, f"{where}: {excerpt(text)}: the multiplier of "
            f"{own}'s own reading cancels to 0; write {own}'s value without {own} to make it passive (no reading), "
            f"or give its reading a nonzero multiplier")
    return multipliers, value[1]


def with_couplings(chain: tuple[Joint, ...], spec, where: str, deg: bool) -> tuple[Joint, ...]:
    """The chain with the robot file's `couplings` (joint name -> its value in the readings) set.

    A coupled joint whose value names itself keeps its reading (the FANUC J3: `J3: J2 + J3`); one
    that does not is passive, with no reading. Numbers are in the file's units (deg or rad, m): a
    multiplier from a revolute reading onto a prismatic joint is m per deg in a deg file. A coupling
    may not restate a URDF `<mimic>` joint (its limits have narrowed the joint it follows)."""
    if spec is None:
        return chain
    require(isinstance(spec, dict) and spec, f"{where}: expected a mapping from joint names to their values in the "
                                             f"readings, such as {{J3: \"J2 + J3\"}}")
    names = [j.name for j in chain]
    values = {}
    mimics = {j.name for j in chain if j.coupling is not None and not j.coupling.declared}
    for name, text in spec.items():
        require(name in names, f"{where}: {excerpt(name)} is not a joint on the chain; couple one of "
                               f"{', '.join(names)}")
        require(name not in mimics, f"{where}: {excerpt(name)} is a <mimic> joint of the URDF, whose limits already "
                                    f"narrowed the joint it follows; change its <mimic> in the URDF instead")
        values[name] = _affine(text, name, names, f"{where}.{name}")
    kinds = {j.name: j.kind for j in chain}

    def scale(kind: str):  # rad (or m) per unit of the file
        return pi_multiple(Fraction(1, 180), 1) if deg and kind == "R" else 1

    out = []
    for j in chain:
        if j.name not in values:
            out.append(j)
            continue
        multipliers, offset = values[j.name]
        terms = tuple((n, multipliers[n] * scale(j.kind) / scale(kinds[n])) for n in names if n in multipliers)
        unit = {"R": "rad", "P": "m"}
        for size, what in [(m, f"the multiplier of {n}, {unit[j.kind]} per {unit[kinds[n]]},") for n, m in terms] + \
                [(offset * scale(j.kind), f"the offset, {unit[j.kind]},")]:
            # gears, belts and four-bar linkages couple joints by ratios of a few; 1e300 is a typing
            # error that would fit and print as inf
            require(abs(float(size)) <= MAX_RATIO, f"{where}.{j.name}: {excerpt(spec[j.name])}: {what} is "
                    f"{float(size):.3g}, beyond +-{MAX_RATIO:g}; check the number (a coupling's ratios are a few)")
        out.append(replace(j, coupling=Coupling(terms, offset * scale(j.kind), own=j.name in multipliers,
                                                declared=True)))
    readings = {j.name for j in out if j.reads}
    for j in out:
        for n, _ in j.coupling.terms if j.coupling else ():
            require(n in readings, f"{where}: joint {excerpt(j.name)} follows {excerpt(n)}, which has no reading "
                                   f"of its own (it is coupled without naming itself); write {excerpt(j.name)}'s "
                                   f"value in the joints the controller reads")
    _check_invertible(out, where)
    return tuple(out)


def _check_invertible(chain, where: str) -> None:
    """The joints that keep a reading must give back their readings: the controller's readings are
    what a calibration corrects, so a map of them that has no inverse (J2: J2 + J3, J3: J2 + J3)
    cannot be compensated, and one nearly without an inverse multiplies every error."""
    readers = [j for j in chain if j.reads]
    coupled = [j for j in readers if j.coupling is not None]
    if not coupled:
        return
    index = {j.name: k for k, j in enumerate(readers)}
    A = np.eye(len(readers)).tolist()
    for j in coupled:
        A[index[j.name]][index[j.name]] = 0
        for n, m in j.coupling.terms:
            A[index[j.name]][index[n]] = m
    # rows of uncoupled readers are unit rows, so the determinant is that of the coupled joints' block
    rows = [index[j.name] for j in coupled]
    named = ", ".join(j.name for j in coupled)
    require(_nonsingular([[A[r][c] for c in rows] for r in rows]),
            f"{where}: {named}: the joints' values do not determine their readings (the map from the readings to "
            f"these joints cannot be inverted), so no correction of the readings exists; give each joint that keeps "
            f"its reading a map of its own, such as J3: J2 + J3 with J2 left uncoupled")
    cond = np.linalg.cond(np.array([[float(v) for v in row] for row in A]))
    require(cond <= MAX_CONDITION, f"{where}: {named}: these couplings can hardly be inverted (condition number "
                                   f"{cond:.3g}, beyond {MAX_CONDITION:g}): a reading's error would be magnified as "
                                   f"much; check the multipliers")


def _nonsingular(block) -> bool:
    """Whether the exact square matrix `block` of coupling multipliers has a nonzero determinant.

    Entry (i, j) is a rational times pi**(s_i - s_j), s_k = 1 for a revolute joint of a file in
    degrees and 0 otherwise (`with_couplings`' units), so the determinant is that of the rational
    factors times pi**0: Gaussian elimination over the rationals decides it exactly."""
    M = [[pi_factor(v) for v in row] for row in block]
    for k in range(len(M)):
        pivot = next((r for r in range(k, len(M)) if M[r][k] != 0), None)
        if pivot is None:
            return False
        M[k], M[pivot] = M[pivot], M[k]
        for r in range(k + 1, len(M)):
            f = M[r][k] / M[k][k]
            M[r] = [a - f * b for a, b in zip(M[r], M[k])]
    return True


def _check_joint_names(joints, place):
    """Joint names are aliases of q1..qn in error terms, so a name that means something else there
    would silently change what a term measures. `place(k)` says where joint k's name is written."""
    seen: dict[str, int] = {}
    for k, joint in enumerate(joints):
        name = joint.name
        if name.isidentifier() and not name.isascii():
            why = "is not ASCII: the terms read a full-width or accented name as another (NFKC: 'ｑ3' is 'q3')"
        elif re.fullmatch(r"q\d+", name) and name != f"q{k + 1}":
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


def _branch_specs(spec: dict, where: str, urdf: bool) -> list[tuple[str, dict, str]]:
    """(name, spec, where) per branch: the file's `branches` (a tree), or the serial robot's one
    branch from its top-level `tool`, `targets` and, with urdf, `tip_link`."""
    tip = "tip_link" if urdf else "tip"
    if "branches" not in spec:
        if urdf:
            require("tip_link" in spec, f"{where}: missing key 'tip_link' (needed with urdf)")
            require(isinstance(spec["tip_link"], str), f"{where}: tip_link: expected the name of a URDF link")
        return [("", {k: spec[k] for k in ("tool", "targets", "tip_link") if k in spec}, where)]
    for key in ("tool", "targets", "tip_link"):
        require(key not in spec, f"{where}: {key}: a robot with branches gives each branch its own {key}; move it "
                                 f"under its branch")
    branches = spec["branches"]
    require(isinstance(branches, dict) and branches, f"{where}: branches: expected a mapping from branch names to "
                                                     f"{{{tip}, tool, targets}}")
    out = []
    for name, b in branches.items():
        bwhere = f"{where}: branches.{excerpt(str(name))}"
        require(is_name(name), f"{bwhere}: branch names must be identifiers")
        require(isinstance(b, dict), f"{bwhere}: expected a mapping with {tip}, tool and targets")
        require_keys(b, bwhere, required={tip, "targets"}, optional={"tool"})
        require(isinstance(b[tip], str) and b[tip],
                f"{bwhere}: {tip}: expected the name of a {'URDF link' if urdf else 'joint'}, got {excerpt(b[tip])}")
        out.append((name, b, bwhere))
    _check_branch_identifiers(spec["name"], [n for n, _, _ in out], where)
    return out


#: the generated C's functions of each branch, named <robot>_<function>_<branch> (gecgen/emit)
BRANCH_FUNCTIONS = ("fk", "tool_jacobian", "compensate", "compensate_batch")


def _check_branch_identifiers(robot: str, names: list[str], where: str) -> None:
    """Branch names whose generated functions coincide ('left' and 'batch_left' both give
    compensate_batch_left) would define one C function twice: the code would not compile."""
    seen: dict[str, tuple[str, str]] = {}
    for name in names:
        for fn in BRANCH_FUNCTIONS:
            ident = f"{fn}_{name}"
            other = seen.setdefault(ident, (name, fn))
            require(other[0] == name, f"{where}: branches {excerpt(other[0])} and {excerpt(name)}: the generated C "
                                      f"would define {robot}_{ident} twice ({other[1]} of {excerpt(other[0])}, {fn} "
                                      f"of {excerpt(name)}); rename one of them")


def _urdf_tree(path: Path, base_link: str, branches):
    """(base ops, joints, parent frame of each, (tip frame, tool ops) per branch) of the URDF paths
    from base_link to every branch's tip_link, shared joints once (frames numbered along the first
    branch, then each further branch's own joints)."""
    paths = [urdf_chain(path, base_link, b["tip_link"]) for _, b, _ in branches]
    shared_start = len({js[0].name for _, js, _ in paths}) == 1
    joints: list[Joint] = []
    parents, tips, frame = [], [], {}
    for lead, js, trail in paths:
        prev = 0
        for k, j in enumerate(js):
            if j.name in frame:  # a joint shared with an earlier branch: the trunk
                i = frame[j.name]
                joints[i - 1] = replace(joints[i - 1], lower=max(joints[i - 1].lower, j.lower),
                                        upper=min(joints[i - 1].upper, j.upper))
            else:
                # branches that part before any joint start from the base link, each with its own lead
                joints.append(j if k or shared_start else replace(j, pre=lead + j.pre))
                parents.append(prev)
                frame[j.name] = i = len(joints)
            prev = i
        tips.append((prev, trail))
    return (paths[0][0] if shared_start else ()), tuple(joints), parents, tips


def _path_of(i: int, parents: list[int]) -> list[int]:
    """Frames from i down to the base along `parents` (parent of frame f is parents[f - 1])."""
    out = [i]
    while out[-1] > 0:
        out.append(parents[out[-1] - 1])
    return out


def _dh_tree(rows: list, joints: tuple[Joint, ...], branches, where: str):
    """(parent frame of each DH row, (tip frame, ()) per branch): a row hangs from its `parent` (a
    joint name of an earlier row, or `base`), else from the row before it."""
    frame = {j.name: i for i, j in enumerate(joints, start=1)}
    parents = []
    for k, row in enumerate(rows):
        parent = row.get("parent")
        if parent is None:
            parents.append(k)
            continue
        require(branches[0][0], f"{where}: joints[{k}].parent: only a robot with branches may have one; add "
                                f"'branches' with each tip")
        require(isinstance(parent, str), f"{where}: joints[{k}].parent: expected an earlier row's joint name or "
                                         f"'base', got {excerpt(parent)}")
        require(parent == "base" or frame.get(parent, k + 1) <= k,
                f"{where}: joints[{k}].parent: {excerpt(parent)} is not an earlier row's joint name or 'base'")
        parents.append(0 if parent == "base" else frame[parent])
    tips = []
    for _, b, bwhere in branches:
        require(not b.get("tip") or b["tip"] in frame, f"{bwhere}: tip: {excerpt(b.get('tip'))} is not a joint name "
                                                       f"of the rows")
        tips.append((frame[b["tip"]] if b.get("tip") else len(joints), ()))
    return parents, tips


def load_robot(path: str | Path) -> Robot:
    """Read and validate a robot file (YAML); every problem names the file, the key and the fix."""
    path = Path(path)
    where = str(path)
    spec = read_yaml(path, "robot")
    require(isinstance(spec, dict), f"{where}: expected a mapping at the top level")
    # no default: a file written in degrees and read as radians turns 90 deg into 90 rad
    require("angle_unit" in spec, f"{where}: missing key 'angle_unit'; add 'angle_unit: deg' or 'angle_unit: rad' "
                                  f"(the unit of every angle in the file)")
    require_keys(spec, where, required={"name", "angle_unit"} | (set() if "branches" in spec else {"targets"}),
                 optional={"description", "base", "tool", "joints", "urdf", "base_link", "targets",
                           "tip_link", "wrench_frame", "points", "gravity", "couplings", "branches",
                           "controller"})
    unit = spec["angle_unit"]
    require(unit in ("deg", "rad"), f"{where}: angle_unit: {excerpt(unit)}; use deg or rad")
    deg = unit == "deg"
    name = spec["name"]
    require(is_name(name),
            f"{where}: name: {excerpt(name)} must be an identifier (it names C functions)")
    controller = spec.get("controller", "")
    require(controller == "" or controller in CONTROLLERS,
            f"{where}: controller: {excerpt(controller)}; give one of {', '.join(CONTROLLERS)} (the controller whose "
            f"programs gecgen filter corrects for this robot), or leave the key out")
    hashes = {path.name: file_hash(path)}
    base = _transform(spec.get("base"), f"{where}: base", deg)
    urdf_path = None
    branches = _branch_specs(spec, where, "urdf" in spec)
    if "urdf" in spec:
        require("joints" not in spec, f"{where}: give either joints (DH) or urdf, not both")
        require("base_link" in spec, f"{where}: missing key 'base_link' (needed with urdf)")
        require(isinstance(spec["base_link"], str), f"{where}: base_link: expected the name of a URDF link")
        require(isinstance(spec["urdf"], str), f"{where}: urdf: expected the path of a URDF file")
        urdf_path = path.parent / spec["urdf"]
        require(urdf_path.is_file(), f"{where}: urdf: no such file {excerpt(str(urdf_path))} (the path is relative to "
                                     f"the robot file's folder, {path.parent.resolve()})")
        hashes[urdf_path.name] = file_hash(urdf_path)
        lead, joints, parents, tips = _urdf_tree(urdf_path, spec["base_link"], branches)
        base = base + lead
    else:
        require("joints" in spec, f"{where}: missing key 'joints' (a list of DH rows) or 'urdf'")
        rows = spec["joints"]
        require(isinstance(rows, list) and rows, f"{where}: joints must be a non-empty list of DH rows")
        joints = tuple(_dh_joint(row, k, where, deg) for k, row in enumerate(rows))
        parents, tips = _dh_tree(rows, joints, branches, where)
    tools = [trail + _transform(b.get("tool"), f"{bwhere}: tool", deg)
             for (_, b, bwhere), (_, trail) in zip(branches, tips)]
    joints = with_couplings(tuple(joints), spec.get("couplings"), f"{where}: couplings", deg)
    unnamed = [k for k, row in enumerate(spec.get("joints") or []) if isinstance(row, dict) and "name" not in row]
    require(all(j.reads for j in joints) or not unnamed,
            f"{where}: joints[{unnamed[0] if unnamed else 0}]: give every DH row a name when couplings make a joint "
            f"passive (the readings q1..qn skip it, so the row's default name q{(unnamed[0] if unnamed else 0) + 1} "
            f"would be another joint's reading)")
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
    targets, estimated, target_branch = {}, (), {}
    for k, (_, b, bwhere) in enumerate(branches):
        more, left = _targets(b.get("targets"), f"{bwhere}: targets")
        twice = sorted(set(more) & set(targets))
        require(not twice, f"{bwhere}: targets: {excerpt(twice[0]) if twice else ''} is a target of another branch "
                           f"too; give every target its own name")
        targets, estimated = targets | more, estimated + left
        target_branch |= {t: k for t in more}
    tree = bool(spec.get("branches"))
    if tree:
        carried = {f for tip, _ in tips for f in _path_of(tip, parents)}
        idle = [j.name for i, j in enumerate(joints, start=1) if i not in carried]
        require(not idle, f"{where}: joint {excerpt(idle[0]) if idle else ''} carries no branch's tool; make it a "
                          f"branch's tip or drop it")
    robot = Robot(name=name, chain=tuple(joints), base=base, tool=tools[0], targets=targets, estimated=estimated,
                  wrench_frame=wrench_frame,
                  points=points, source=str(path), source_hashes=hashes,
                  urdf=str(urdf_path or ""), base_link=str(spec["base_link"]) if urdf_path else "",
                  tip_link=str(branches[0][1].get("tip_link", "")) if urdf_path else "",
                  gravity=_vector(spec.get("gravity", list(GRAVITY)), f"{where}: gravity"),
                  parents=tuple(parents) if tree else (),
                  branches=tuple(Branch(n, tip, tool, str(b.get("tip_link", "")))
                                 for (n, b, _), (tip, _), tool in zip(branches, tips, tools)) if tree else (),
                  target_branch=target_branch if tree else {}, angle_unit=unit, controller=controller)
    for i, j in enumerate(robot.chain, start=1):
        if j.coupling and j.coupling.declared and len(j.coupling.terms) > j.coupling.own \
                and robot.zero_offset_error(i) is None:
            warnings.warn(f"{where}: couplings.{j.name}: the joint's axis is not along an axis of the frame next to "
                          f"its motion, so its coupling ratios are not calibrated (only its frames' errors are)",
                          stacklevel=2)
    return robot
