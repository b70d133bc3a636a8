"""Relative measurements: rows that place a target only relative to other rows (docs/reference.md,
"Sockets, distances and planes").

Without a tracker, a robot is calibrated against fixtures: a ball on the flange seated in a socket
of a plate, a probe touching a granite table. The measurement file then says, instead of where the
target is, what it coincides with:

* `point` - an id of a fixed but unknown point (a socket): every row with that id puts its target
  at the same place;
* `plane` - an id of an unknown plane: every row with that id puts its target on it;
* `distance_to`, `distance_m`, `distance_std_m` - on a row of a point, a known distance (m) from
  that point to another point (a plate's two sockets, a ball bar's ends) and its standard
  uncertainty (m; 0 or empty: exact). Any rows of the point may carry it; rows that do must agree.

Such a row leaves x y z empty. A file may mix relative rows with absolute ones. What relative
data cannot see (where the whole set of points is, a scale without a known distance, directions
a plane cannot see) is derived from the data by the redundancy analysis, not assumed here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.table import Table, at
from gecgen.model.validation import ModelError, excerpt, require

POINT, PLANE = "point", "plane"
DISTANCE_TO, DISTANCE, DISTANCE_STD = "distance_to", "distance_m", "distance_std_m"
#: the columns of relative measurements: never auxiliary signals
COLUMNS = (POINT, PLANE, DISTANCE_TO, DISTANCE, DISTANCE_STD)
#: rows a group needs before it says anything: a point seen twice, a plane touched four times
#: (three rows fix any plane)
MIN_ROWS = {POINT: 2, PLANE: 4}


@dataclass(frozen=True)
class Distance:
    """A known distance between points `a` and `b` (group indices): length_m and its standard
    uncertainty std_m (0: exact)."""

    a: int
    b: int
    length_m: float
    std_m: float


@dataclass(frozen=True)
class Relative:
    """The relative rows of R measured rows: group (R,) the index into `names` of each row's point
    or plane, -1 for an absolute row; names (G,) the ids as the file writes them; kinds (G,) POINT
    or PLANE; distances the known distances between points."""

    group: np.ndarray
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    distances: tuple[Distance, ...] = ()

    @property
    def rows(self) -> np.ndarray:
        """(R,) True for a relative row."""
        return self.group >= 0

    def is_plane(self) -> np.ndarray:
        """(G,) True for a plane group."""
        return np.array([k == PLANE for k in self.kinds], bool)

    def take(self, index: np.ndarray) -> "Relative":
        """The rows at `index` (a boolean mask or row indices, repeats allowed), every group and
        distance kept (a group may then have too few rows to say anything: it counts for nothing)."""
        return Relative(self.group[index], self.names, self.kinds, self.distances)

    def counts(self) -> np.ndarray:
        """(G,) rows per group."""
        return np.bincount(self.group[self.rows], minlength=len(self.names))

    def row_dof(self) -> np.ndarray:
        """(R,) degrees of freedom each relative row leaves once its group's unknowns are fitted:
        3 (n - 1) / n for a point seen n times (its three coordinates are estimated), (n - 3) / n
        for a plane touched n times (its offset and two tilts); NaN for an absolute row."""
        n = self.counts().astype(float)
        per_group = np.where(self.is_plane(), np.maximum(n - 3, 0) / np.maximum(n, 1),
                             3 * np.maximum(n - 1, 0) / np.maximum(n, 1))
        return np.where(self.rows, per_group[np.maximum(self.group, 0)], np.nan)

    def summary(self) -> dict:
        """What the file holds: {points, planes, distances, rows}."""
        plane = self.is_plane()
        return {"points": int((~plane).sum()), "planes": int(plane.sum()), "distances": len(self.distances),
                "rows": int(self.rows.sum())}


def read_relative(table: Table) -> Relative | None:
    """The relative rows of a measurement table (None when it has no point or plane column). Refuses
    a row with both a point and a plane, a group with too few rows to say anything, and a distance
    that is not positive, names an unknown point or disagrees with another row's."""
    header, where = table.header, table.where
    if POINT not in header and PLANE not in header:
        for col in (DISTANCE_TO, DISTANCE, DISTANCE_STD):
            require(col not in header, f"{where}: row 1: column {col} but no '{POINT}' column; a known distance is "
                                       f"between points: give each row's point id in a '{POINT}' column")
        return None
    empty = np.full(len(table), "", object)
    point = np.char.strip(table.cells(POINT).astype(str)) if POINT in header else empty.astype(str)
    plane = np.char.strip(table.cells(PLANE).astype(str)) if PLANE in header else empty.astype(str)
    both = np.nonzero((point != "") & (plane != ""))[0]
    require(not len(both), f"{at(where, both[0] + 2 if len(both) else 0, PLANE)}: the row names both a point and a "
                           f"plane; a target sits at one of them: give one per row")
    names, kinds, group = [], [], np.full(len(table), -1, np.int64)
    for kind, ids in ((POINT, point), (PLANE, plane)):
        for name in dict.fromkeys(ids[ids != ""].tolist()):
            rows = ids == name
            group[rows] = len(names)
            names.append(name)
            kinds.append(kind)
            n = int(rows.sum())
            require(n >= MIN_ROWS[kind], f"{at(where, int(np.argmax(rows)) + 2, kind)}: {kind} {excerpt(name)} has "
                                         f"{n} row{'s' if n > 1 else ''}: it says nothing about the robot below "
                                         f"{MIN_ROWS[kind]}; measure it more often or remove the row")
    return Relative(group, tuple(names), tuple(kinds), _distances(table, point, names, kinds))


def _distances(table: Table, point: np.ndarray, names: list[str], kinds: list[str]) -> tuple[Distance, ...]:
    """The known distances the rows of points declare (see the module docstring)."""
    header, where = table.header, table.where
    if DISTANCE_TO not in header:
        require(DISTANCE not in header, f"{where}: row 1: column {DISTANCE} but no {DISTANCE_TO}; name the other "
                                        f"point of each distance in a {DISTANCE_TO} column")
        return ()
    require(DISTANCE in header, f"{where}: row 1: column {DISTANCE_TO} but no {DISTANCE}; give each distance's "
                                f"length in m in a {DISTANCE} column")
    to = np.char.strip(table.cells(DISTANCE_TO).astype(str))
    length_cells = np.char.strip(table.cells(DISTANCE).astype(str))
    std_cells = (np.char.strip(table.cells(DISTANCE_STD).astype(str)) if DISTANCE_STD in header
                 else np.full(len(table), "", object).astype(str))
    index = {(k, n): g for g, (k, n) in enumerate(zip(kinds, names))}
    found: dict[tuple[int, int], tuple[float, float, int]] = {}
    for r in np.nonzero(to != "")[0]:
        row = int(r) + 2
        require(point[r] != "", f"{at(where, row, DISTANCE_TO)}: a distance on a row without a point; put it on a "
                                f"row of the point it starts from")
        other = index.get((POINT, str(to[r])))
        require(other is not None, f"{at(where, row, DISTANCE_TO)}: no point {excerpt(str(to[r]))} in the file; name "
                                   f"a point some rows measure")
        a = index[(POINT, str(point[r]))]
        require(other != a, f"{at(where, row, DISTANCE_TO)}: a distance from point {excerpt(str(point[r]))} to "
                            f"itself; name the other point")
        length = _number(length_cells[r], where, row, DISTANCE, positive=True)
        std = _number(std_cells[r], where, row, DISTANCE_STD) if std_cells[r] != "" else 0.0
        key = (min(a, other), max(a, other))
        if key in found and found[key][:2] != (length, std):
            raise ModelError(f"{at(where, row, DISTANCE)}: the distance between points {names[key[0]]} and "
                             f"{names[key[1]]} is {length:g} +- {std:g} m here but {found[key][0]:g} +- "
                             f"{found[key][1]:g} m on row {found[key][2]}; give one value")
        found.setdefault(key, (length, std, row))
    for r in np.nonzero((to == "") & (length_cells != ""))[0]:
        raise ModelError(f"{at(where, int(r) + 2, DISTANCE)}: a distance without {DISTANCE_TO}; name the other point")
    return tuple(Distance(a, b, length, std) for (a, b), (length, std, _) in found.items())


def _number(text: str, where: str, row: int, col: str, positive: bool = False) -> float:
    """A distance cell (m): finite, not negative (positive for a length), under a kilometre."""
    try:
        value = float(text)
    except ValueError:
        raise ModelError(f"{at(where, row, col)}: {excerpt(text)} is not a number; give it in m") from None
    require(np.isfinite(value) and (value > 0 if positive else value >= 0) and value < 1e3,
            f"{at(where, row, col)}: {excerpt(text)} is not a {'positive length' if positive else 'standard deviation'}"
            f" in m; give it in m" + (" (0 or empty: exact)" if not positive else ""))
    return value


def columns(relative: Relative, r: int) -> list[str]:
    """The cells of row r's relative columns, in COLUMNS order, as `write_measurements` writes them:
    a point's first row carries each distance from it (one per row: a point with several distances
    spreads them over its rows)."""
    g = int(relative.group[r])
    if g < 0:
        return [""] * len(COLUMNS)
    point, plane = (relative.names[g], "") if relative.kinds[g] == POINT else ("", relative.names[g])
    mine = [d for d in relative.distances if d.a == g]
    k = int(np.sum(relative.group[:r] == g))  # the row's number within its point
    if k < len(mine):
        d = mine[k]
        return [point, plane, relative.names[d.b], repr(d.length_m), repr(d.std_m)]
    return [point, plane, "", "", ""]
