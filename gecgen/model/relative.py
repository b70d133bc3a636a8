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
* `plane_to`, `relation`, `offset_m`, `relation_std` - on a row of a plane, a known relation to
  another plane: `parallel`, `perpendicular`, or `offset` (parallel, `offset_m` apart: a gauge
  block's faces, a step of known height), with its standard uncertainty (rad for the angle of
  parallel and perpendicular, m for an offset; 0 or empty: exact). Rows that give one must agree.

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
PLANE_TO, RELATION, OFFSET, RELATION_STD = "plane_to", "relation", "offset_m", "relation_std"
#: known relations between planes, and the rows each adds to the fit (two tilts, one angle, both and an offset)
RELATIONS = {"parallel": 2, "perpendicular": 1, "offset": 3}
#: the columns of relative measurements: never auxiliary signals
COLUMNS = (POINT, PLANE, DISTANCE_TO, DISTANCE, DISTANCE_STD, PLANE_TO, RELATION, OFFSET, RELATION_STD)
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
class Relation:
    """A known relation of plane b to plane a (group indices): `kind` (RELATIONS), offset_m (m, for
    an offset) and the standard uncertainty std (rad for an angle, m for an offset; 0: exact)."""

    a: int
    b: int
    kind: str
    offset_m: float
    std: float


@dataclass(frozen=True)
class Relative:
    """The relative rows of R measured rows: group (R,) the index into `names` of each row's point
    or plane, -1 for an absolute row; names (G,) the ids as the file writes them; kinds (G,) POINT
    or PLANE; distances the known distances between points, relations those between planes."""

    group: np.ndarray
    names: tuple[str, ...]
    kinds: tuple[str, ...]
    distances: tuple[Distance, ...] = ()
    relations: tuple[Relation, ...] = ()

    @property
    def n_known(self) -> int:
        """Rows the known distances and plane relations add to a fit."""
        return len(self.distances) + sum(RELATIONS[r.kind] for r in self.relations)

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
        return Relative(self.group[index], self.names, self.kinds, self.distances, self.relations)

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

    def seated_twice(self, q: np.ndarray, target: np.ndarray) -> tuple[int, int] | None:
        """The first two rows (indices) that seat one target at two points with the same joint
        readings, q (R, n) and target (R,) per row; None when there are none. One configuration
        cannot put a ball in two sockets: such rows are one recording given as two sockets, whose
        distance the fit would then be asked to make of nothing."""
        rows = np.nonzero(self.rows & ~self.is_plane()[np.maximum(self.group, 0)])[0]
        if not len(rows):
            return None
        _, first, same = np.unique(np.column_stack([q[rows], target[rows]]), axis=0, return_index=True,
                                   return_inverse=True)
        same = same.ravel()
        clash = np.nonzero(self.group[rows] != self.group[rows[first[same]]])[0]
        return (int(rows[first[same[clash[0]]]]), int(rows[clash[0]])) if len(clash) else None

    def placements(self) -> list[tuple[str, tuple[int, ...]]]:
        """The fixture placements, each its name and its groups: the points and planes a known
        distance or relation joins (a plate's sockets, a square's faces), together with those whose
        ids share a prefix before the last '/' or '.' (`front/hole_0`, `plate2.1`), the name being
        that prefix or, without one, the ids joined."""
        label = list(range(len(self.names)))

        def root(g: int) -> int:
            while label[g] != g:
                g = label[g]
            return g

        prefixes: dict[str, int] = {}
        links = [(x.a, x.b) for x in (*self.distances, *self.relations)]
        for g, name in enumerate(self.names):
            cut = max(name.rfind("/"), name.rfind("."), 0)
            if cut:
                links.append((prefixes.setdefault(name[:cut], g), g))
        for a, b in links:
            label[root(b)] = root(a)
        out: dict[int, list[int]] = {}
        for g in range(len(self.names)):
            out.setdefault(root(g), []).append(g)
        named = []
        for members in out.values():
            ids = [self.names[g] for g in members]
            stems = {n[:max(n.rfind("/"), n.rfind("."), 0)] for n in ids}
            named.append((stems.pop() if len(stems) == 1 and "" not in stems else " + ".join(ids), tuple(members)))
        return named

    def summary(self) -> dict:
        """What the file holds: {points, planes, distances, rows}, and relations when it has any."""
        plane = self.is_plane()
        return {"points": int((~plane).sum()), "planes": int(plane.sum()), "distances": len(self.distances),
                **({"relations": len(self.relations)} if self.relations else {}), "rows": int(self.rows.sum())}


def read_relative(table: Table) -> Relative | None:
    """The relative rows of a measurement table (None when it has no point or plane column). Refuses
    a row with both a point and a plane, a group with too few rows to say anything, and a distance
    that is not positive, names an unknown point or disagrees with another row's."""
    header, where = table.header, table.where
    if POINT not in header and PLANE not in header:
        for col in COLUMNS[2:]:
            require(col not in header, f"{where}: row 1: column {col} but no '{POINT}' or '{PLANE}' column; a known "
                                       f"distance or relation is between points or planes: give each row's id")
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
    return Relative(group, tuple(names), tuple(kinds), _distances(table, point, names, kinds),
                    _relations(table, plane, names, kinds))


def _relations(table: Table, plane: np.ndarray, names: list[str], kinds: list[str]) -> tuple[Relation, ...]:
    """The known relations the rows of planes declare (see the module docstring)."""
    header, where = table.header, table.where
    if PLANE_TO not in header:
        for col in (RELATION, OFFSET, RELATION_STD):
            require(col not in header, f"{where}: row 1: column {col} but no {PLANE_TO}; name the other plane of "
                                       f"each relation in a {PLANE_TO} column")
        return ()
    require(RELATION in header, f"{where}: row 1: column {PLANE_TO} but no {RELATION}; say how the planes relate "
                                f"({', '.join(RELATIONS)})")

    def cells(col: str) -> np.ndarray:
        return (np.char.strip(table.cells(col).astype(str)) if col in header
                else np.full(len(table), "", object).astype(str))

    to, kind, offset, std = cells(PLANE_TO), cells(RELATION), cells(OFFSET), cells(RELATION_STD)
    index = {(k, n): g for g, (k, n) in enumerate(zip(kinds, names))}
    found: dict[tuple[int, int], tuple[Relation, int]] = {}
    for r in np.nonzero(to != "")[0]:
        row = int(r) + 2
        require(plane[r] != "", f"{at(where, row, PLANE_TO)}: a relation on a row without a plane; put it on a row "
                                f"of one of its planes")
        b, a = index.get((PLANE, str(to[r]))), index[(PLANE, str(plane[r]))]
        require(b is not None, f"{at(where, row, PLANE_TO)}: no plane {excerpt(str(to[r]))} in the file; name a plane "
                               f"some rows touch")
        require(b != a, f"{at(where, row, PLANE_TO)}: a relation of plane {excerpt(str(plane[r]))} to itself; name "
                        f"the other plane")
        require(kind[r] in RELATIONS, f"{at(where, row, RELATION)}: {excerpt(str(kind[r]))} is no relation; give "
                                      f"{', '.join(RELATIONS)}")
        require((offset[r] != "") == (kind[r] == "offset"), f"{at(where, row, OFFSET)}: an offset goes with the "
                                                              f"relation offset, and only with it")
        length = _number(offset[r], where, row, OFFSET, positive=True) if kind[r] == "offset" else 0.0
        relation = Relation(min(a, b), max(a, b), str(kind[r]), length,
                            _number(std[r], where, row, RELATION_STD) if std[r] != "" else 0.0)
        key = (relation.a, relation.b)
        if key in found and found[key][0] != relation:
            raise ModelError(f"{at(where, row, RELATION)}: planes {names[key[0]]} and {names[key[1]]} are "
                             f"{relation.kind} here but {found[key][0].kind} (or another value) on row "
                             f"{found[key][1]}; give one relation per pair")
        found.setdefault(key, (relation, row))
    for r in np.nonzero((to == "") & ((kind != "") | (offset != "") | (std != "")))[0]:
        col = next(c for c, v in ((RELATION, kind[r]), (OFFSET, offset[r]), (RELATION_STD, std[r])) if v != "")
        raise ModelError(f"{at(where, int(r) + 2, col)}: a relation without {PLANE_TO}; name the other plane")
    return tuple(rel for rel, _ in found.values())


def _distances(table: Table, point: np.ndarray, names: list[str], kinds: list[str]) -> tuple[Distance, ...]:
    """The known distances the rows of points declare (see the module docstring)."""
    header, where = table.header, table.where
    if DISTANCE_TO not in header:
        for col in (DISTANCE, DISTANCE_STD):
            require(col not in header, f"{where}: row 1: column {col} but no {DISTANCE_TO}; name the other point of "
                                       f"each distance in a {DISTANCE_TO} column")
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
    for r in np.nonzero((to == "") & ((length_cells != "") | (std_cells != "")))[0]:
        col = DISTANCE if length_cells[r] != "" else DISTANCE_STD
        raise ModelError(f"{at(where, int(r) + 2, col)}: a distance without {DISTANCE_TO}; name the other point")
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
    a point's k-th row carries its k-th distance, a plane's its k-th relation (a group has at least as
    many rows as it has distances or relations: MIN_ROWS, and a pair is named once)."""
    g = int(relative.group[r])
    if g < 0:
        return [""] * len(COLUMNS)
    point, plane = (relative.names[g], "") if relative.kinds[g] == POINT else ("", relative.names[g])
    k = int(np.sum(relative.group[:r] == g))  # the row's number within its group
    distances = [d for d in relative.distances if d.a == g]
    relations = [x for x in relative.relations if x.a == g]
    distance = ([relative.names[distances[k].b], repr(distances[k].length_m), repr(distances[k].std_m)]
                if k < len(distances) else [""] * 3)
    relation = ([relative.names[relations[k].b], relations[k].kind,
                 repr(relations[k].offset_m) if relations[k].kind == "offset" else "", repr(relations[k].std)]
                if k < len(relations) else [""] * 4)
    return [point, plane, *distance, *relation]
