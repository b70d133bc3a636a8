"""Relative rows in the least squares: sockets and planes whose positions are not measured.

A point (socket) or plane of `model.relative` is a nuisance unknown. It is eliminated rather than
carried (variable projection): at the current coefficients its best value follows in closed form
from the modelled targets of its rows - the weighted mean of a point's rows, the total
least-squares plane of a plane's - so the measured position of a relative row is that point, or
the foot of the target on that plane (`fill`), and y - p is its residual as for any other row.
The coefficients' columns are projected off what the nuisance unknowns absorb (`project`): within a
point's rows a change common to all of them (3 columns), within a plane's a change of offset or
tilt (3 columns). A coefficient that only moves a whole point set - the base placement, a scale
without a known distance - projects to nothing and the redundancy analysis sees it as unobservable.

A known distance between points a and b is one more row: L - |m_a - m_b| for the fitted points m.
Carrying the points instead would give it the variance std^2 + sigma^2 (1/n_a + 1/n_b) (the
points' means have sigma^2 / n along the line), so that is its weight against the rows' sigma; the
eliminated and the carried problem then have the same minimum (to first order).
"""
from __future__ import annotations

import numpy as np
from scipy.linalg import eigh, qr
from scipy.special import fdtrc

from gecgen.model.relative import RELATIONS, Relative


def _centres(relative: Relative, p: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per group: the weighted centre of its rows' modelled targets (G, 3) m, the plane's unit
    normal and two unit tangents (G, 3, 3: rows n, t1, t2; the identity for a point), and the
    summed weight (G,). p (R, 3) and w (R,) over the rows of `relative`."""
    centre, frame, W, _ = _planes(relative, p, w)
    return centre, frame, W


def _planes(relative: Relative, p: np.ndarray, w: np.ndarray):
    """`_centres`, and the weighted spread of each plane's rows along n, t1, t2 (G, 3) m^2 (the
    eigenvalues of their scatter; zeros for a point)."""
    G = len(relative.names)
    rows = relative.rows
    g = relative.group[rows]
    W = np.bincount(g, w[rows], G)
    centre = np.column_stack([np.bincount(g, w[rows] * p[rows, k], G) for k in range(3)])
    centre /= np.maximum(W, 1e-300)[:, None]
    frame, spread = np.tile(np.eye(3), (G, 1, 1)), np.zeros((G, 3))
    for k in np.nonzero(relative.is_plane())[0]:
        on = relative.group == k
        d = p[on] - centre[k]
        values, vectors = np.linalg.eigh(np.einsum("n,ni,nj->ij", w[on], d, d))
        frame[k] = vectors[:, [0, 2, 1]].T  # the normal is the direction of least spread
        spread[k] = values[[0, 2, 1]]
    return centre, frame, W, spread


def fill(relative: Relative, y: np.ndarray, p: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """y (R, 3) with its relative rows replaced by where the fitted point or plane puts each one's
    target: the point itself, or the foot of the modelled target p (R, 3) on the plane; point
    weights w (R,) (default 1)."""
    w = np.ones(len(p)) if w is None else w
    centre, frame, _ = _centres(relative, p, w)
    out = y.copy()
    rows = relative.rows
    g = relative.group[rows]
    plane = relative.is_plane()[g]
    foot = p[rows] - np.einsum("ni,nj,nj->ni", frame[g, 0], frame[g, 0], p[rows] - centre[g])
    out[rows] = np.where(plane[:, None], foot, centre[g])
    return out


def project(relative: Relative, H: np.ndarray, p: np.ndarray, w: np.ndarray) -> np.ndarray:
    """H (R, 3, k): the columns of every row projected off what its point's or plane's unknowns
    absorb, in the metric of the weights w (R,) (absolute rows unchanged). A point's rows lose their
    weighted mean; a plane's rows keep their normal component, less its weighted fit by an offset
    and two tilts over the plane's rows."""
    out = H.copy()
    centre, frame, W = _centres(relative, p, w)
    for k in range(len(relative.names)):
        on = np.nonzero(relative.group == k)[0]
        if not len(on):
            continue
        wk = w[on]
        if relative.kinds[k] == "point":
            out[on] = H[on] - np.einsum("n,nij->ij", wk, H[on]) / max(W[k], 1e-300)
            continue
        n, t = frame[k, 0], frame[k, 1:]
        h = np.einsum("i,nij->nj", n, H[on])  # the normal component (rows, k)
        N = np.column_stack([np.ones(len(on)), (p[on] - centre[k]) @ t.T])  # offset, two tilts
        coef = np.linalg.lstsq(N * np.sqrt(wk)[:, None], h * np.sqrt(wk)[:, None], rcond=None)[0]
        out[on] = n[None, :, None] * (h - N @ coef)[:, None, :]
    return out


def scale_rows(relative: Relative) -> np.ndarray:
    """(n_known,) True for the rows of `known_rows` that measure a length (a distance, an offset's
    distance): the only ones that can see a scaling; angles between planes see no similarity."""
    out = [True] * len(relative.distances)
    for x in relative.relations:
        out += [False] * (RELATIONS[x.kind] - (x.kind == "offset")) + [True] * (x.kind == "offset")
    return np.array(out, bool)


def known_rows(relative: Relative, H: np.ndarray | None, p: np.ndarray, w: np.ndarray,
               sigma_m: float) -> tuple[np.ndarray | None, np.ndarray]:
    """The rows of the known distances and plane relations, (K, k) and (K,) with K = relative.n_known:
    each one's residual (declared less modelled) and its columns (None without H), weighted against
    rows of per-coordinate noise sigma_m (module docstring). H (R, 3, k) the rows' columns, p (R, 3)
    their modelled targets, w (R,) their weights. A distance: L - |m_a - m_b| for the points' fitted
    positions m. A relation of planes a and b (normals n, tangents t, centres m): parallel, the two
    tilts t_a.n_b; perpendicular, n_a.n_b; offset, both tilts and L - |n_a.(m_b - m_a)|; each weighted
    by its variance, the declared std^2 and what the planes' own fits leave (sigma^2 over their
    rows' spread)."""
    centre, frame, W, spread = _planes(relative, p, w)
    A, r = None if H is None else np.zeros((relative.n_known, H.shape[-1])), np.zeros(relative.n_known)
    mean = {}

    def mean_H(g: int) -> np.ndarray:  # how the group's centre moves per coefficient (3, k)
        if g not in mean:
            on = relative.group == g
            mean[g] = np.einsum("n,nij->ij", w[on], H[on]) / W[g]
        return mean[g]

    def turn(g: int) -> np.ndarray:  # how the plane's normal turns per coefficient (3, k), to first order
        on = relative.group == g
        d = p[on] - centre[g]
        along = np.einsum("i,nij->nj", frame[g, 0], H[on] - mean_H(g)[None])  # n.(dp_i - dm)
        out = np.zeros((3, H.shape[-1]))
        for j in (1, 2):
            gap = max(spread[g, j] - spread[g, 0], 1e-300)
            out -= np.outer(frame[g, j], (w[on] * (d @ frame[g, j])) @ along) / gap
        return out

    i = 0
    for d in relative.distances:
        n_rows = 1
        if W[d.a] > 0 and W[d.b] > 0:  # else a subset of the data without the point: it says nothing
            between = centre[d.a] - centre[d.b]
            length = np.linalg.norm(between)
            weight = sigma_m / np.sqrt(d.std_m ** 2 + sigma_m ** 2 * (1 / W[d.a] + 1 / W[d.b]))
            r[i] = weight * (d.length_m - length)
            if H is not None:
                A[i] = weight * (between / max(length, 1e-300)) @ (mean_H(d.a) - mean_H(d.b))
        i += n_rows
    counts = relative.counts()
    for x in relative.relations:
        n_rows = RELATIONS[x.kind]
        if counts[x.a] > 3 and counts[x.b] > 3:  # else a plane not yet fixed by this data: it says nothing
            sign_b = 1.0 if frame[x.a, 0] @ frame[x.b, 0] >= 0 else -1.0  # the normals' signs are arbitrary
            na, nb = frame[x.a, 0], sign_b * frame[x.b, 0]
            values, rows_A = [], []
            if x.kind == "perpendicular":
                # each normal's tilt towards the other, as its plane's fit leaves it: sigma^2 / spread
                tilt = sum(sigma_m ** 2 * np.sum((frame[g, 1:] @ u) ** 2 / np.maximum(spread[g, 1:], 1e-300))
                           for g, u in ((x.a, nb), (x.b, na)))
                values.append((-(na @ nb), x.std ** 2 + tilt))
                if H is not None:
                    rows_A.append(nb @ turn(x.a) + sign_b * na @ turn(x.b))
            else:  # parallel, and the offset's tilts: each about its own tangent, as both fits leave it
                for j, t in enumerate(frame[x.a, 1:]):
                    var = (x.std ** 2 if x.kind == "parallel" else 0.0) + sigma_m ** 2 * (
                        1 / max(spread[x.a, 1 + j], 1e-300)
                        + np.sum((frame[x.b, 1:] @ t) ** 2 / np.maximum(spread[x.b, 1:], 1e-300)))
                    values.append((-(t @ nb), var))
                    if H is not None:
                        rows_A.append(t @ (sign_b * turn(x.b) - turn(x.a)))
            if x.kind == "offset":
                gap = centre[x.b] - centre[x.a]
                s = na @ gap
                values.append((x.offset_m - abs(s), x.std ** 2 + sigma_m ** 2 * (1 / W[x.a] + 1 / W[x.b])))
                if H is not None:
                    rows_A.append(np.sign(s) * (na @ (mean_H(x.b) - mean_H(x.a)) + gap @ turn(x.a)))
            for k, (value, var) in enumerate(values):
                weight = sigma_m / np.sqrt(max(var, 1e-300))
                r[i + k] = weight * value
                if H is not None:
                    A[i + k] = weight * rows_A[k]
        i += n_rows
    return A, r


def measures(relative: Relative, p: np.ndarray) -> dict:
    """What relative rows say about modelled targets p (R, 3), m: `consistency_mm`, the RMS distance
    of the points' rows from their point's mean (mm); `flatness_mm`, the RMS distance of the planes'
    rows from their total least-squares plane; `distances`, each known distance's error (the
    distance between the two points' means less the declared length, mm), and its largest
    magnitude `distance_error_mm`. Groups without rows, and their distances, are left out."""
    w = np.ones(len(p))
    centre, frame, W = _centres(relative, p, w)
    y = fill(relative, np.zeros_like(p), p, w)
    plane = relative.is_plane()
    rows, g = relative.rows, relative.group
    gap = np.linalg.norm(y - p, axis=1)
    out = {}
    on_plane = rows & plane[np.maximum(g, 0)]
    for name, on in (("consistency_mm", rows & ~on_plane), ("flatness_mm", on_plane)):
        if on.any():
            out[name] = float(1e3 * np.sqrt(np.mean(gap[on] ** 2)))
    errors = [{"between": [relative.names[d.a], relative.names[d.b]], "length_mm": 1e3 * d.length_m,
               "error_mm": float(1e3 * (np.linalg.norm(centre[d.a] - centre[d.b]) - d.length_m))}
              for d in relative.distances if W[d.a] > 0 and W[d.b] > 0]
    if errors:
        out["distances"] = errors
        out["distance_error_mm"] = max(abs(e["error_mm"]) for e in errors)
    counts = relative.counts()
    relations = [_relation_error(x, centre, frame, relative.names) for x in relative.relations
                 if counts[x.a] > 3 and counts[x.b] > 3]
    if relations:
        out["relations"] = relations
    return out


#: a placement's rows stand out when their mean square about their points and planes is beyond this
#: many times the other placements' (twice their RMS), and beyond what noise gives such a ratio with
#: probability STRAY_P (F test, over all placements)
STRAY_RATIO = 4.0
STRAY_P = 1e-3


def stray_placements(relative: Relative, p: np.ndarray) -> list[str]:
    """A warning for each fixture placement (`Relative.placements`) whose rows scatter about their
    fitted points and planes far beyond the other placements' rows, at modelled targets p (R, 3) m:
    a plate that moved, or balls that did not seat, while it was recorded; or, with the same signature,
    an effect the error model misses that is largest where that placement sits (a constant model of a
    Panda whose joints twist under gravity names a clean plate), so the warning names both. Each row's scatter counts
    with the degrees of freedom its group leaves (`Relative.row_dof`)."""
    placements = relative.placements()
    if len(placements) < 2:
        return []
    gap = np.sum((fill(relative, np.zeros_like(p), p) - p) ** 2, axis=1)
    dof = np.nan_to_num(relative.row_dof())
    of = np.full(len(relative.names), -1)
    for k, (_, members) in enumerate(placements):
        of[list(members)] = k
    on = np.where(relative.rows, of[np.maximum(relative.group, 0)], -1)
    squares = np.bincount(on[on >= 0], gap[on >= 0], len(placements))
    dofs = np.bincount(on[on >= 0], dof[on >= 0], len(placements))
    out = []
    for k, (name, members) in enumerate(placements):
        rest, rest_dof = squares.sum() - squares[k], dofs.sum() - dofs[k]
        if dofs[k] <= 0 or rest_dof <= 0 or rest <= 0:
            continue
        ratio = (squares[k] / dofs[k]) / (rest / rest_dof)
        if ratio > STRAY_RATIO and fdtrc(dofs[k], rest_dof, ratio) < STRAY_P / len(placements):
            ids = ", ".join(relative.names[g] for g in members)
            mine = 1e3 * np.sqrt(np.mean(gap[on == k]))
            theirs = 1e3 * np.sqrt(np.mean(gap[(on >= 0) & (on != k)]))
            out.append(f"placement {name} ({ids}) stands out: its rows lie {mine:.3g} mm rms from their fitted "
                       f"sockets or planes against {theirs:.3g} mm for the other placements' rows, beyond what "
                       f"noise gives, and pulls the whole fit: it was recorded badly (the fixture moved, or the ball "
                       f"or probe did not seat), or the error model misses an effect that is largest where it sits; "
                       f"re-record placement {name} or drop its rows, and if a clean recording stands out again, "
                       f"run gecgen diagnose on the data to find the effect")
    return out


def _relation_error(x, centre: np.ndarray, frame: np.ndarray, names) -> dict:
    """How far the fitted planes a and b are from their declared relation: the angle from parallel or
    from perpendicular (mrad), and for an offset the offset's error (mm) too."""
    na, nb = frame[x.a, 0], frame[x.b, 0]
    cos = abs(float(na @ nb))
    angle = np.arccos(min(cos, 1.0)) if x.kind != "perpendicular" else np.arcsin(min(cos, 1.0))
    out = {"between": [names[x.a], names[x.b]], "relation": x.kind, "angle_mrad": float(1e3 * angle)}
    if x.kind == "offset":
        out["offset_error_mm"] = float(1e3 * (abs(na @ (centre[x.b] - centre[x.a])) - x.offset_m))
    return out


#: a direction of the coefficients keeps less than this share of its motion of the measured points
#: once each point's and plane's unknowns absorb what they can: relative data cannot see it. A rigid
#: motion or a scaling of the whole set keeps only what the rows of one socket scatter over their
#: lever arm (about 4e-4 for 0.2 mm at 0.5 m, once fitted); a coefficient the configurations of a
#: socket tell apart keeps a good part of it (0.1 and more)
UNSEEN = 1e-2


#: a known distance sees a direction of the coefficients when it moves the distance by more than this
#: share of the direction's motion of the rows
DISTANCE_SEES = 1e-6


def unseen(projected: np.ndarray, absolute: np.ndarray, distances: np.ndarray) -> np.ndarray:
    """Directions of the coefficients (k, u) that relative rows cannot see, orthonormal in the
    metric of `absolute`: those the projected rows (`projected`, R factor or rows, (m, k), with
    what a motion of the whole set does taken out, `rigid`) keep less than UNSEEN of, against the
    same rows as absolute measurements (`absolute`, (m', k), of full column rank), and that no
    known distance (`distances`, (D, k)) sees either."""
    if not absolute.shape[1]:
        return np.zeros((0, 0))
    norm = np.linalg.norm(absolute, axis=0)
    P, A = projected / norm, absolute / norm
    M = A.T @ A
    share, V = eigh(P.T @ P, M)  # share of each direction's squared motion the projection keeps
    V = V[:, share < UNSEEN ** 2]
    if V.shape[1] and len(distances):
        # a distance (or an offset between planes) sees a scaling (a share of about 0.01 to 0.1: its
        # rows weigh like a socket's mean) and no rigid motion (rounding): one direction at most, its
        # view of it against the direction's motion of the rows, which V normalises to 1
        _, s, Wt = np.linalg.svd((distances / norm) @ V)
        V = V @ Wt[int(s[:1].sum() > DISTANCE_SEES):].T
    return V / norm[:, None]


def rigid(relative: Relative, p: np.ndarray) -> np.ndarray:
    """(R, 3, 7): how a small motion of the whole measured set moves the relative rows' modelled
    targets p (R, 3): translations along x y z, rotations about x y z through the origin, and a
    scaling about it (zero on absolute rows). Relative rows see none of these: a socket moved with
    every other keeps its rows together."""
    G = np.zeros((len(p), 3, 7))
    on = relative.rows
    G[on, :, :3] = np.eye(3)
    x = p[on]
    G[on, :, 3:6] = np.stack([np.cross(np.eye(3)[k], x) for k in range(3)], axis=2)
    G[on, :, 6] = x
    return G


def spanning(V: np.ndarray, norm: np.ndarray) -> np.ndarray:
    """The coefficients (indices, u of them) that span the directions V (k, u) best: column-pivoted
    QR of V's rows in the coefficients scaled by their columns' norms (k,). The rank analysis drops
    these, not better-seen coefficients that a direction touches a little (a turn of the whole set
    is frame 1's rotation about joint 1, not a mix of wrist errors)."""
    if not V.shape[1]:
        return np.zeros(0, int)
    _, _, pivots = qr((V * norm[:, None]).T, pivoting=True, mode="economic")
    return pivots[:V.shape[1]]


def blind(R: np.ndarray, V: np.ndarray, M: np.ndarray) -> np.ndarray:
    """R (m, k) with the directions V (k, u) (orthonormal in the metric M (k, k)) taken out of its
    columns' span: R (I - V V^T M), so those directions move nothing and the rank analysis drops a
    coefficient for each."""
    return R - (R @ V) @ (V.T @ M)
