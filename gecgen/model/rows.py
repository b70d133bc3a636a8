"""The measured rows of point data: what one measurement is, once pose data are points.

A measured point is one row; a measured frame, turned into the four vertices of a tetrahedron
around its target (`model.pose_targets`), is one row of four points. The robust weights, the
residual degrees of freedom and the reported position and orientation errors all count rows, so
the grouping is derived once from the data (`Measurements.rows`) and read wherever it is needed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: unit vertices of a regular tetrahedron: they sum to zero, and sum(v v^T) = 4/3 I
VERTICES = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]]) / np.sqrt(3.0)
#: weight of each vertex point in the fit, and the degrees of freedom its three coordinates carry
WEIGHT = 0.25
DOF = 1.5


def vertex_radius(length_m: float) -> float:
    """r (m): the distance of the vertices from the target for the length scale L (m)."""
    return float(length_m) * np.sqrt(1.5)


@dataclass(frozen=True)
class Vertices:
    """Which measured points are vertices of a measured frame (`pose_targets.as_points`): origin (R,)
    the index of the frame's own target (a plain point's own target), number (R,) the vertex number
    0..3 (-1: a measured point), radius the vertices' distance r from their target (m)."""

    origin: np.ndarray
    number: np.ndarray
    radius: float

    def take(self, index: np.ndarray) -> "Vertices":
        """The points at `index` (a boolean mask or point indices)."""
        return Vertices(self.origin[index], self.number[index], self.radius)


@dataclass(frozen=True)
class Rows:
    """The measured rows of point data: G rows, each one measured point or the four vertices of one
    measured frame. group (R,) the row of each point; first (G,) its first point; vertex (R,) the
    vertex number of each point (-1: a measured point); weight (R,) and dof (R,) per point (1 and 3,
    or WEIGHT and DOF for a vertex); radius the vertices' distance r (m)."""

    group: np.ndarray
    first: np.ndarray
    vertex: np.ndarray
    weight: np.ndarray
    dof: np.ndarray
    radius: float

    @property
    def row_dof(self) -> np.ndarray:
        """(G,) degrees of freedom of each row: 3 for a point, 6 for a frame."""
        return np.bincount(self.group, self.dof, len(self.first))

    @property
    def oriented(self) -> np.ndarray:
        """(G,) True for a row that measures a frame."""
        return self.vertex[self.first] >= 0

    def signed(self, y: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per row, for measured points y and modelled points p (R, 3): the position error
        measured - modelled (G, 3) m, and the orientation error as a rotation vector in the
        measuring frame (G, 3) rad (NaN for a position-only row)."""
        G = len(self.first)
        d = y - p
        rotation = np.full((G, 3), np.nan)
        if G == len(d):  # one point per row (no frames): nothing to sum
            mean = np.empty((G, 3))
            mean[self.group] = d
            return mean, rotation
        mean = _sums(self.group, self.weight[:, None] * d, G)
        at = self.vertex >= 0
        if at.any():
            from scipy.spatial.transform import Rotation  # here: reading a file of points needs no scipy

            v = VERTICES[self.vertex[at]]
            My, Mp = (_sums(self.group[at], np.einsum("ni,nj->nij", x[at], v).reshape(-1, 9), G).reshape(G, 3, 3)
                      for x in (y, p))
            rows = self.oriented
            scale = 3 / (4 * self.radius)
            rotation[rows] = Rotation.from_matrix(scale ** 2 * My[rows] @ np.swapaxes(Mp[rows], 1, 2)).as_rotvec()
        return mean, rotation

    def errors(self, y: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per row, for measured points y and modelled points p (R, 3): the position error (G,) m,
        the orientation error angle (G,) rad (NaN for a position-only row) and the residual length
        sqrt(sum of weight |y - p|^2) (G,) m, which is sqrt(|e|^2 + L^2 (2 sin(theta/2))^2) for a frame."""
        mean, rotation = self.signed(y, p)
        e = np.linalg.norm(mean, axis=1)
        if len(self.first) == len(y):
            return e, rotation[:, 0], e
        d = y - p
        length = np.sqrt(np.bincount(self.group, self.weight * np.einsum("ni,ni->n", d, d), len(self.first)))
        return e, np.linalg.norm(rotation, axis=1), length


def _sums(group: np.ndarray, values: np.ndarray, G: int) -> np.ndarray:
    """(G, k) sums of values (R, k) over the rows of each group (R,); bincount, which is many
    times faster than np.add.at."""
    return np.column_stack([np.bincount(group, values[:, k], G) for k in range(values.shape[1])])


def point_rows(pose: np.ndarray, target: np.ndarray, vertices: Vertices | None,
               relative_dof: np.ndarray | None) -> Rows:
    """The rows of points measured at pose (R,) of target (R,): one per pose and frame when
    `vertices` says which points are a frame's vertices, else one per pose and target; relative_dof
    (R,) the degrees of freedom a relative point keeps once its socket or plane is fitted (NaN for an
    absolute point; None when there are none)."""
    origin = target if vertices is None else vertices.origin
    vertex = np.full(len(target), -1) if vertices is None else vertices.number
    span = int(origin.max()) + 1 if len(origin) else 1
    _, first, group = np.unique(pose.astype(np.int64) * span + origin, return_index=True, return_inverse=True)
    dof = np.where(vertex >= 0, DOF, 3.0)
    if relative_dof is not None:
        dof = np.where(np.isnan(relative_dof), dof, relative_dof)
    return Rows(group.ravel(), first, vertex, np.where(vertex >= 0, WEIGHT, 1.0), dof,
                np.nan if vertices is None else vertices.radius)
