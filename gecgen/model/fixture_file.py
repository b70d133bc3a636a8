"""The fixtures a tracker-free design plans for (`gecgen design --fixtures FILE.csv`).

One row per fixture, where it stands in the robot's world frame, as well as it is known before
measuring (a few millimetres is plenty: the design only needs configurations that reach it):

| column | meaning |
|---|---|
| `name` | the socket's or plane's id, as the measurement file will name it (`point` or `plane`) |
| `x, y, z` | a socket's centre, or a point of a plane near where it will be touched (m) |
| `nx, ny, nz` | a plane's normal (any length); empty on a socket's row |
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.table import at, read_table
from gecgen.model.validation import excerpt, require

NORMAL = ("nx", "ny", "nz")
#: coordinates beyond this (m) are millimetres or an export error: no robot reaches that far
MAX_COORDINATE_M = 100.0


@dataclass(frozen=True)
class Fixture:
    """A socket (normal None) or a plane through `point` (3,) m with unit `normal` (3,)."""

    name: str
    point: np.ndarray
    normal: np.ndarray | None = None

    @property
    def is_plane(self) -> bool:
        return self.normal is not None

    @property
    def tangents(self) -> np.ndarray:
        """(2, 3) two unit vectors across a plane's normal, at right angles."""
        return np.linalg.svd(self.normal[None, :])[2][1:]


def read_fixtures(path) -> tuple[Fixture, ...]:
    """The fixtures of a CSV (see the module docstring); each bad cell refused with its row."""
    table = read_table(path, "fixtures file", "name, x, y, z[, nx, ny, nz]", text=("name", *NORMAL))
    missing = [c for c in ("name", "x", "y", "z") if c not in table.header]
    require(not missing, f"{table.where}: no column {missing[0] if missing else ''}; the header needs name, x, y, z "
                         f"(and nx, ny, nz for planes)")
    names = [str(n).strip() for n in table.cells("name")]
    xyz = np.column_stack([table.numbers(c, "give the position in m", MAX_COORDINATE_M) for c in "xyz"])
    has_normal = all(c in table.header for c in NORMAL)
    require(has_normal or not any(c in table.header for c in NORMAL),
            f"{table.where}: a plane's normal needs all of nx, ny, nz; add the missing columns")
    out = []
    for r, name in enumerate(names):
        require(name, f"{at(table.where, r + 2, 'name')}: empty; give the socket's or plane's id")
        require(name not in names[:r], f"{at(table.where, r + 2, 'name')}: {excerpt(name)} is already the name of "
                                       f"row {names.index(name) + 2}; give every fixture its own id")
        normal = None
        if has_normal:
            cells = [str(table.cells(c)[r]).strip() for c in NORMAL]
            if any(cells):
                try:
                    normal = np.array([float(c) for c in cells])
                except ValueError:
                    normal = np.full(3, np.nan)
                bad = next((c for c, v in zip(NORMAL, normal) if not np.isfinite(v)), "nx")
                ok = np.isfinite(normal).all() and np.abs(normal).max() > 0
                require(ok, f"{at(table.where, r + 2, bad)}: the normal ({', '.join(cells)}) is not a nonzero "
                            f"direction; give three numbers, or leave all three empty for a socket")
                # scaled to its largest component first: the norm of (1e300, 1e300, 0) overflows
                normal = normal / np.abs(normal).max()
                normal = normal / np.linalg.norm(normal)
        out.append(Fixture(name, xyz[r], normal))
    _check_apart(out, table.where)
    return tuple(out)


#: two sockets closer than this (m), or two planes, one within this of the other, are one fixture
SAME_PLACE_M = 1e-3


def _check_apart(fixtures: list[Fixture], where: str) -> None:
    """Two rows that describe one socket or one plane would have the design plan one fixture twice
    and say nothing; a copied row is the usual cause."""
    for k, f in enumerate(fixtures):
        for j, g in enumerate(fixtures[:k]):
            if f.is_plane != g.is_plane:
                continue
            if f.is_plane:
                same = abs(f.normal @ g.normal) > 1 - 1e-9 and abs(f.normal @ (f.point - g.point)) < SAME_PLACE_M
                what = "the same plane"
            else:
                same = np.linalg.norm(f.point - g.point) < SAME_PLACE_M
                what = f"sockets {1e3 * np.linalg.norm(f.point - g.point):.3g} mm apart"
            require(not same, f"{where}: rows {j + 2} and {k + 2}: {excerpt(g.name)} and {excerpt(f.name)} are {what}; "
                              f"give each fixture its own position (m), or drop one of the rows")
