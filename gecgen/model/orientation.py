"""Measured orientations: the conventions a measurement file or a wide table writes them in, and
their rotation matrices (scipy.spatial.transform.Rotation).

A measured orientation is that of a target's frame - parallel to the tool frame, at the target
point - in the measuring system's frame: the columns of its matrix R are the tool frame's x, y, z
axes there. The measurement file's columns (docs/reference.md, "Pose measurements"), one set per file:

* `quat_w quat_x quat_y quat_z` - a unit quaternion, scalar first;
* `rot_11 .. rot_33` - the matrix R, row i column j in `rot_ij`;
* `euler_<seq>_<unit>_1 .. _3` - three angles in scipy's convention `seq` (three of `xyz`,
  lowercase: rotations about the measuring frame's fixed axes, applied in that order; uppercase:
  about the rotating axes), unit `deg` or `rad`. Roll-pitch-yaw R = Rz(yaw) Ry(pitch) Rx(roll),
  as URDF and pinocchio write it, is `euler_xyz_rad_1..3` = roll, pitch, yaw.

No other column may start with `quat_`, `rot_` or `euler_`: a misspelt orientation column is
refused rather than read as an auxiliary signal.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable

import numpy as np

from gecgen.model.validation import ModelError, excerpt, require

QUATERNION = ("quat_w", "quat_x", "quat_y", "quat_z")
MATRIX = tuple(f"rot_{i}{j}" for i in "123" for j in "123")
EULER = re.compile(r"euler_([xyz]{3}|[XYZ]{3})_(deg|rad)_([123])")
#: prefixes no other column may take
PREFIXES = ("quat_", "rot_", "euler_")
#: a quaternion's norm, and R^T R, may differ from 1 and I by this much (digits a file rounds away)
UNIT_TOL = 1e-3


@dataclass(frozen=True)
class Convention:
    """How three, four or nine numbers give an orientation. kind: "quaternion" (w, x, y, z),
    "matrix" (R row by row) or "euler" (angles about the axes of `seq`, scipy's spelling, in
    degrees when `degrees`)."""

    kind: str
    seq: str = ""
    degrees: bool = False

    @property
    def width(self) -> int:
        return {"quaternion": 4, "matrix": 9, "euler": 3}[self.kind]

    def columns(self) -> tuple[str, ...]:
        """The measurement file's column names for this convention."""
        if self.kind == "quaternion":
            return QUATERNION
        if self.kind == "matrix":
            return MATRIX
        return tuple(f"euler_{self.seq}_{'deg' if self.degrees else 'rad'}_{k}" for k in (1, 2, 3))


def parse_convention(name, unit, where: str) -> Convention:
    """A mapping's `convention` (quaternion, matrix, rpy or euler_<seq>) and `unit` (deg or rad,
    angles only)."""
    require(isinstance(name, str), f"{where}.convention: expected quaternion, matrix, rpy or euler_<seq> "
                                   f"(such as euler_xyz), got {excerpt(name)}")
    if name in ("quaternion", "matrix"):
        require(unit is None, f"{where}.unit: a {name} has no unit; remove the key")
        return Convention(name)
    seq = "xyz" if name == "rpy" else name[len("euler_"):] if name.startswith("euler_") else None
    require(seq is not None and _valid_seq(seq),
            f"{where}.convention: {excerpt(name)}; use quaternion, matrix, rpy (R = Rz(yaw) Ry(pitch) Rx(roll)) or "
            f"euler_<seq> with three of xyz (extrinsic) or XYZ (intrinsic), no axis twice in a row")
    require(unit in ("deg", "rad"), f"{where}.unit: {excerpt(unit)}; angles need unit deg or rad")
    return Convention("euler", seq, unit == "deg")


def _valid_seq(seq: str) -> bool:
    from scipy.spatial.transform import Rotation  # in the functions: a command's help needs this module, not scipy

    try:
        Rotation.from_euler(seq, [0.0, 0.0, 0.0])
    except ValueError:
        return False
    return len(seq) == 3


def file_convention(header: list[str], where: str) -> Convention | None:
    """The orientation convention of a measurement file's header, None when it has no orientation
    columns; a header mixing conventions, missing one of a set's columns or holding a column that
    only starts like one is refused."""
    found = [h for h in header if h.startswith(PREFIXES)]
    if not found:
        return None
    conventions = []
    for h in found:
        m = EULER.fullmatch(h)
        require(h in QUATERNION or h in MATRIX or m,
                f"{where}: row 1: column {excerpt(h)} starts like an orientation column but is none; orientation "
                f"columns are {' '.join(QUATERNION)}, rot_11..rot_33 or euler_<seq>_<deg|rad>_1..3 (docs/reference.md, "
                f"\"Pose measurements\"): rename it")
        conventions.append(Convention("quaternion") if h in QUATERNION else Convention("matrix") if h in MATRIX
                           else Convention("euler", m.group(1), m.group(2) == "deg"))
    conv = conventions[0]
    other = next((h for h, c in zip(found, conventions) if c != conv), None)
    require(other is None, f"{where}: row 1: columns {excerpt(found[0])} and {excerpt(other)} give the orientation in "
                           f"two conventions; keep one set")
    require(conv.kind != "euler" or _valid_seq(conv.seq),
            f"{where}: row 1: column {excerpt(found[0])}: {conv.seq} is not an Euler sequence (no axis twice in a row)")
    missing = [c for c in conv.columns() if c not in header]
    require(not missing, f"{where}: row 1: missing column {excerpt(missing[0]) if missing else ''}; an orientation "
                         f"needs all of {', '.join(conv.columns())}")
    return conv


def rotations(values: np.ndarray, conv: Convention, row_name: Callable[[int], str]) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of orientations given as values (N, conv.width), finite. A
    quaternion whose norm, or a matrix whose R^T R, is off by more than UNIT_TOL (or with
    det < 0) is refused, `row_name(i)` naming where row i came from; within it they are
    normalised (the nearest rotation)."""
    from scipy.spatial.transform import Rotation

    values = np.asarray(values, float).reshape(-1, conv.width)
    if not len(values):
        return np.zeros((0, 3, 3))
    if conv.kind == "quaternion":
        with np.errstate(over="ignore"):  # a cell near the largest float: its norm is inf, refused below
            norm = np.linalg.norm(values, axis=1)
        bad = np.nonzero(~(np.abs(norm - 1) <= UNIT_TOL))[0]
        if len(bad):
            raise ModelError(f"{row_name(bad[0])}: quaternion of norm {norm[bad[0]]:.6g}; give a unit quaternion "
                             f"(norm 1 within {UNIT_TOL:g}), scalar first (w, x, y, z)")
        return Rotation.from_quat(values[:, [1, 2, 3, 0]]).as_matrix()  # scipy writes the scalar last
    if conv.kind == "matrix":
        M = values.reshape(-1, 3, 3)
        with np.errstate(over="ignore", invalid="ignore"):  # huge entries: inf or NaN, refused below
            off = np.abs(np.einsum("nki,nkj->nij", M, M) - np.eye(3)).max(axis=(1, 2))
            det = np.linalg.det(M)
        bad = np.nonzero(~(off <= UNIT_TOL) | ~(det > 0))[0]
        if len(bad):
            raise ModelError(f"{row_name(bad[0])}: not a rotation matrix (R^T R - I up to {off[bad[0]]:.3g}, det "
                             f"{det[bad[0]]:.6g}); give R row by row, orthonormal within {UNIT_TOL:g}, det +1")
        return Rotation.from_matrix(M).as_matrix()
    return Rotation.from_euler(conv.seq, values, degrees=conv.degrees).as_matrix()


def quaternions(R: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions, scalar first, of rotation matrices R (N, 3, 3)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]] if len(R) else np.zeros((0, 4))
