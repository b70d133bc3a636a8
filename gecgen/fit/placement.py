"""Tool placement: where the measured points sit on the tool, estimated from the data.

A camera mount or a marker body is rarely where a drawing says, and a robot file may leave its
targets to the data (`targets: {m1: estimate}`). With the nominal kinematics, the tool pose
(R_i, p_i) of pose i and the unknown tracker frame (R, t) of each stationing, a target at m_k in
the tool frame is measured at

    y_ik = R (R_i m_k + p_i) + t.

The product R m_k makes this bilinear, but lifting W_k = R m_k^T (the 27 numbers R_ab m_kc) makes
it linear: row a of y_ik is  sum_bc W_k[a,b,c] (R_i)_bc + sum_b R_ab (p_i)_b + t_a,  the same
design for a = x, y, z. One least-squares solve gives W_k, R and t; R is projected onto the
rotations (SVD) and m_k = sum_ab R_ab W_k[a,b,c] / 3. That closed form starts a robust nonlinear
refinement over every stationing's frame and every target at once. The data determines the
placement only when the tool turns about at least two independent axes; otherwise the estimate
is refused, never guessed.

Pose data measures the target's frame too: R = R_s R_i X with R_s the stationing's tracker
rotation (from the positions, above) and X the measured frame's rotation in the tool frame, so X
is the rotation nearest to sum_i R_i^T R_s^T R (SVD). A frame far from the robot's is turned to it
(`Robot.target_frames`): the fit's linearisation then starts near the truth, however the probe is
mounted.

Identification then fits the generalized errors around the estimated targets: the placement is a
starting point (frame n's errors still absorb what the nominal kinematics got wrong), recorded in
the calibration so that evaluate and compensate use the same targets. Being a starting point, it
is estimated from at most PLACEMENT_ROWS rows spread through the data (`spread_sample`), so its
memory does not grow with the data.
"""
from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass

import numpy as np

from gecgen.model.kinematics import tool_poses
from gecgen.model.measurements import Measurements
from gecgen.model.robot import Robot
from gecgen.model.validation import ModelError, require
from gecgen.fit import robust
from gecgen.fit.registration import (FITS_M, HOLD_M, kabsch, nearest_rotation, rotation_angle, rotation_matrix,
                                     rotation_vector)

#: a given target this far from where the data puts it (m) is replaced by the estimate before the fit
FAR_M = 0.02
#: ... unless the data would move it further than HOLD_M while the given target already fits them within
#: FITS_M rms (the nominal model's residual with the tracker frames refitted): a robot's own errors leave
#: millimetres, and a tool that barely turns places its target only weakly, so such a move is what the
#: robot's errors pushed along the weak direction (a reflector "moved" by 643 mm on a constant-orientation
#: grid), not what the data determine; the given target is held, and the fit's last-frame errors take up
#: what is left (the registration holds its own weak directions by the same limits)
#: rad: the forward-difference step of a tracker frame's rotation vector (`estimate_placement`)
ROTATION_STEP = 1e-7
#: a measured frame (pose data) this far (rad) from the robot's is turned to the estimate before the fit
FAR_RAD = 0.02
#: singular values of the refinement's column-scaled Jacobian below this share of the largest leave a
#: direction of the placement undetermined
RANK_TOL = 1e-7
#: the refinement's damped Gauss-Newton steps (`_robust_refine`): at most REFINE_STEPS, starting from
#: REFINE_DAMPING (a share of the scaled normal matrix's unit diagonal), until a step lowers the robust
#: objective by less than REFINE_TOL of itself
REFINE_STEPS, REFINE_DAMPING, REFINE_TOL = 100, 1e-3, 1e-12
#: measured rows the placement is estimated from at most: it only starts the fit, which sees every
#: row, and its dense Jacobian would otherwise take memory in proportion to the data (330 MB at
#: 200,000 rows); spread evenly through each stationing and target, each keeping at least MIN_STATION_ROWS
PLACEMENT_ROWS, MIN_STATION_ROWS = 20_000, 500


@dataclass(frozen=True)
class Placement:
    """Targets (name -> tool-frame xyz, m) as the data places them, with the nominal kinematics.

    rms_mm: residual of the nominal model with these targets and the fitted tracker frames (what
    the generalized errors are left to explain); moved_mm: distance of each target from the robot
    file's (None for one the file leaves to estimate); held: the given targets the data would move
    further than they support (HOLD_M), kept where the robot file puts them, each with why.
    """

    targets: dict[str, tuple[float, float, float]]
    rms_mm: float
    moved_mm: dict[str, float | None]
    #: pose data: the measured frame of each target as a rotation vector (rad) in the tool frame, and
    #: its angle from the robot's (mrad)
    frames: dict[str, tuple[float, float, float]] = dataclasses.field(default_factory=dict)
    turned_mrad: dict[str, float] = dataclasses.field(default_factory=dict)
    held: dict[str, str] = dataclasses.field(default_factory=dict)

    def to_dict(self) -> dict:
        frames = {"frames_rotvec_rad": {k: list(v) for k, v in self.frames.items()},
                  "turned_mrad": self.turned_mrad} if self.frames else {}
        return {"targets_m": {k: list(v) for k, v in self.targets.items()}, "rms_mm": self.rms_mm,
                "moved_mm": self.moved_mm, **frames, **({"held": self.held} if self.held else {})}


def _closed_form(T: np.ndarray, data: Measurements, rows: np.ndarray, k_targets: int):
    """The lifted linear solve on the given rows (one stationing): (R, t, m (k_targets, 3)); T (rows of
    data, 4, 4) the nominal tool pose each row's target rides on."""
    target = data.target[rows]
    Ri, pi = T[rows, :3, :3].reshape(-1, 9), T[rows, :3, 3]
    A = np.zeros((len(rows), 9 * k_targets + 4))
    for k in range(k_targets):
        on = target == k
        A[on, 9 * k:9 * k + 9] = Ri[on]
    A[:, -4:-1], A[:, -1] = pi, 1.0
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    X = np.linalg.lstsq(A / scale, data.xyz[rows], rcond=None)[0] / scale[:, None]  # (9K + 4, 3): column a
    R = nearest_rotation(X[-4:-1].T)
    W = X[:-4].reshape(k_targets, 3, 3, 3)  # [k, b, c, a]
    m = np.einsum("ab,kbca->kc", R, W) / 3
    return R, X[-1], m


def estimate_placement(robot: Robot, data: Measurements, loss: str = "cauchy") -> Placement:
    """The targets the data measures, placed on the tool (see the module docstring); every
    stationing of the data gets its own tracker frame. Raises ModelError when the poses do not
    turn the tool enough to place them."""
    robust.check_loss(loss)
    tools = np.stack(tool_poses(robot, data.q))  # (branches, N, 4, 4)
    T = tools[[robot.branch_of(n) for n in robot.target_names]][data.target, data.pose]  # each row's tool
    measured = np.unique(data.target)
    index = np.searchsorted(measured, data.target)  # targets renumbered 0..K-1 over those measured
    stations = np.unique(data.station)
    sidx = np.searchsorted(stations, data.station)
    k = len(measured)
    local = dataclasses.replace(data, target=index)
    largest = np.argmax(np.bincount(sidx))
    R0, t0, m0 = _closed_form(T, local, np.nonzero(sidx == largest)[0], k)
    # the other stationings start from a Kabsch fit of their points to the first estimate
    p0 = np.einsum("nij,nj->ni", T[:, :3, :3], m0[index]) + T[:, :3, 3]
    frames = [(R0, t0) if s == largest else kabsch(p0[sidx == s], data.xyz[sidx == s]) for s in range(len(stations))]
    # unknowns: per stationing a rotation vector turning its starting rotation, and its translation; then the targets
    x0 = np.concatenate([np.concatenate([np.zeros(3), t]) for _, t in frames] + [m0.ravel()])
    Rp, pp = T[:, :3, :3], T[:, :3, 3]

    def rotation(x, s):
        return rotation_matrix(x[6 * s:6 * s + 3]) @ frames[s][0]

    def residual(x):
        m = x[6 * len(stations):].reshape(k, 3)
        p = np.einsum("nij,nj->ni", Rp, m[index]) + pp
        out = np.empty_like(data.xyz)
        for s in range(len(stations)):
            on = sidx == s
            out[on] = p[on] @ rotation(x, s).T + x[6 * s + 3:6 * s + 6] - data.xyz[on]
        return out

    coords = np.arange(3 * len(data.xyz)).reshape(-1, 3)[:, :, None]  # each row's three residuals

    def jacobian(x):
        """d residual / d x (3 rows per measured row): exact in the frames' translations and the targets
        (the residual is linear in them), forward differences in the rotation vectors: 3 residuals per
        station rather than one per unknown, which made this step a second of a PPS identify."""
        J = np.zeros((3 * len(data.xyz), len(x)))
        base = residual(x).ravel()
        for s in range(len(stations)):
            on = sidx == s
            J[coords[on], 6 * s + 3 + np.arange(3)] = np.eye(3)
            J[coords[on], 6 * len(stations) + 3 * index[on][:, None, None] + np.arange(3)] = rotation(x, s) @ Rp[on]
            for j in range(3):
                step = np.zeros_like(x)
                step[6 * s + j] = ROTATION_STEP
                J[:, 6 * s + j] = (residual(x + step).ravel() - base) / ROTATION_STEP
        return J

    x, J = _robust_refine(residual, jacobian, x0, loss)
    J = J / np.maximum(np.linalg.norm(J, axis=0), 1e-300)
    s = np.linalg.svd(J, compute_uv=False)
    names = [robot.target_names[t] for t in measured]
    # fewer residuals than unknowns leave directions without a singular value at all
    if not (np.isfinite(x).all() and len(s) == J.shape[1] and s[-1] > RANK_TOL * s[0]):
        raise ModelError(f"the data does not place target(s) {', '.join(names)} on the tool: the poses turn the "
                         f"tool about fewer than two independent axes; give the targets' positions in the robot "
                         f"file, or measure poses that turn the tool more")
    m = x[6 * len(stations):].reshape(k, 3)
    e = np.linalg.norm(residual(x), axis=1)
    placed = {n: tuple(float(v) for v in xyz) for n, xyz in zip(names, m)}
    moved = {n: None if n in robot.estimated else float(1e3 * np.linalg.norm(np.subtract(placed[n], robot.targets[n])))
             for n in names}
    turns = _measured_frames(T, data, index, sidx, [rotation(x, s) for s in range(len(stations))], names)
    turned = {n: float(1e3 * rotation_angle(rotation_matrix(np.array(x)) @ rotation_matrix(
        np.array(robot.target_frames.get(n, (0.0,) * 3))).T)) for n, x in turns.items()}
    return Placement(placed, float(1e3 * np.sqrt(np.mean(e ** 2))), moved, turns, turned)


#: the refinement's losses of a residual coordinate f at scale c, as functions of z = (f / c)^2: rho(z)
#: (the cost, in units of c^2) and rho'(z) (the weight of iteratively reweighted least squares); a
#: point's coordinates are scored one by one, and the scale is one robust sigma, not the fit's outlier
#: limit of ten: the nominal kinematics leaves the robot's own millimetres in every residual, so a
#: glitch is told from them only by a loss that gives up on a point soon
REFINE_LOSSES = {"l2": (lambda z: z, np.ones_like),
          "huber": (lambda z: np.where(z <= 1, z, 2 * np.sqrt(z) - 1), lambda z: np.where(z <= 1, 1.0, 1 / np.sqrt(z))),
          "cauchy": (np.log1p, lambda z: 1 / (1 + z))}


def _robust_refine(residual, jacobian, x0: np.ndarray, loss: str) -> tuple[np.ndarray, np.ndarray]:
    """x minimising sum rho((f / c)^2) over the coordinates f of residual(x) (R, 3) (`REFINE_LOSSES`), c the
    robust sigma of the residual lengths at x0, and the Jacobian (3R, len(x)) there with each row
    weighted as the last step weighted it: iteratively reweighted Gauss-Newton steps on column-scaled
    normal equations, damped (Levenberg-Marquardt) until a step lowers the cost. This is what
    scipy.optimize.least_squares does with these losses, but importing it takes a tenth of a second or
    more that every identify would pay for a starting point."""
    rho, weight = REFINE_LOSSES[loss]
    f = residual(x0).ravel()
    c = max(robust.scale(np.linalg.norm(f.reshape(-1, 3), axis=1)), robust.SCALE_FLOOR_M)
    x, cost, damping = x0, float(np.sum(rho((f / c) ** 2))), REFINE_DAMPING
    for _ in range(REFINE_STEPS):
        w = np.sqrt(weight((f / c) ** 2))
        J = jacobian(x) * w[:, None]
        scale = np.maximum(np.linalg.norm(J, axis=0), 1e-300)
        A = J / scale
        N, g = A.T @ A, A.T @ (w * f)
        while damping < 1e12:
            step = -np.linalg.solve(N + damping * np.eye(len(N)), g) / scale
            f_new = residual(x + step).ravel()
            cost_new = float(np.sum(rho((f_new / c) ** 2)))
            if cost_new <= cost:
                break
            damping *= 10
        else:
            return x, J  # no step lowers the cost: at its minimum to rounding
        x, f, done = x + step, f_new, cost - cost_new <= REFINE_TOL * cost
        cost, damping = cost_new, max(damping / 10, 1e-12)
        if done:
            break
    else:
        warnings.warn(f"the targets' placement on the tool did not settle in {REFINE_STEPS} steps: the fit starts "
                      f"from where it stopped (its own residual and checks judge the result)", stacklevel=2)
    return x, jacobian(x) * np.sqrt(weight((f / c) ** 2))[:, None]


def given_rms_mm(robot: Robot, data: Measurements) -> float:
    """The nominal model's residual (mm rms) with the targets where the robot file puts them, each
    stationing's tracker frame fitted (least squares, `kabsch`)."""
    tools = np.stack(tool_poses(robot, data.q))
    T = tools[[robot.branch_of(n) for n in robot.target_names]][data.target, data.pose]
    m = np.array([robot.targets[n] for n in robot.target_names])[data.target]
    p = np.einsum("nij,nj->ni", T[:, :3, :3], m) + T[:, :3, 3]
    sq = 0.0
    for s in np.unique(data.station):
        on = data.station == s
        R, t = kabsch(p[on], data.xyz[on])
        sq += float(np.sum((data.xyz[on] - p[on] @ R.T - t) ** 2))
    return 1e3 * float(np.sqrt(sq / max(len(p), 1)))


def _measured_frames(T, data: Measurements, index, sidx, rotations, names) -> dict[str, tuple[float, float, float]]:
    """Pose data: the rotation X_k of each target's measured frame in the tool frame, from every
    measured orientation R = R_s R_i X_k (R_s the station's tracker rotation, R_i the nominal tool
    rotation): X_k is the rotation nearest to sum R_i^T R_s^T R (SVD), as a rotation vector (rad)."""
    if data.orientation is None:
        return {}
    out = {}
    oriented = ~np.isnan(data.orientation[:, 0, 0])
    Rs = np.stack(rotations)[sidx]
    for k, name in enumerate(names):
        rows = oriented & (index == k)
        if rows.any():
            S = np.einsum("nji,nkj,nkl->il", T[rows, :3, :3], Rs[rows], data.orientation[rows])
            out[name] = tuple(float(v) for v in rotation_vector(nearest_rotation(S)))
    return out


def with_targets(robot: Robot, targets: dict[str, tuple[float, float, float]],
                 frames: dict[str, tuple[float, float, float]] | None = None) -> Robot:
    """The robot with the given targets placed (the rest as they were), none left to estimate, and
    the given measured frames (rotation vectors, rad, in the tool frame) for pose data."""
    placed = {n: tuple(float(v) for v in targets.get(n, xyz)) for n, xyz in robot.targets.items()}
    left = tuple(n for n in robot.estimated if n not in targets)
    turned = {**robot.target_frames, **{n: tuple(float(v) for v in x) for n, x in (frames or {}).items()}}
    return dataclasses.replace(robot, targets=placed, estimated=left, target_frames=turned)


def spread_sample(data: Measurements) -> Measurements:
    """At most about PLACEMENT_ROWS measured rows (and their poses), evenly spread in file order
    through the rows of each stationing and target, each keeping at least MIN_STATION_ROWS (all of
    fewer): every frame and every target keeps its share. data itself when it has fewer rows."""
    if len(data.xyz) <= PLACEMENT_ROWS:
        return data
    keep = np.zeros(len(data.xyz), bool)
    groups = np.unique(np.column_stack([data.station, data.target]), axis=0)
    for station, target in groups:
        rows = np.nonzero((data.station == station) & (data.target == target))[0]
        share = min(len(rows), max(MIN_STATION_ROWS, PLACEMENT_ROWS * len(rows) // len(data.xyz)))
        keep[rows[np.linspace(0, len(rows) - 1, share).astype(int)]] = True
    poses = np.unique(data.pose[keep])
    return data.subset(poses).rows_of(keep[np.isin(data.pose, poses)])


def place_targets(robot: Robot, data: Measurements, loss: str = "cauchy") -> tuple[Robot, Placement | None]:
    """The robot to fit `data` with: the targets the robot file leaves to the data are estimated,
    and given ones that the data puts more than FAR_M away start from where the data puts them; a
    measured frame (pose data) more than FAR_RAD from the robot's is turned to where the data puts it.
    (robot, None) when the given targets stand; a target left to estimate that `data` does not
    measure is refused."""
    measured = {robot.target_names[t] for t in np.unique(data.target)}
    missing = [n for n in robot.estimated if n not in measured]
    if missing:
        raise ModelError(f"{data.source}: target '{missing[0]}' is left to estimate (robot file) but the data never "
                         f"measures it; give its position in the robot file or remove it")
    if data.relative is not None:  # sockets and planes place no target: only measured positions do
        data = data.rows_of(~data.relative.rows)
        seen = {robot.target_names[t] for t in np.unique(data.target)}
        unplaced = [n for n in robot.estimated if n not in seen]
        require(not unplaced or not len(data.target),
                f"{robot.source}: target '{unplaced[0] if unplaced else ''}' is left to estimate, but only socket or "
                f"plane rows measure it; give its nominal position in the robot file (the fit corrects it)")
        if not len(data.target):
            require(not robot.estimated, f"{robot.source}: target '{robot.estimated[0] if robot.estimated else ''}' "
                                         f"is left to estimate, but the data has no measured positions to place "
                                         f"it; give its nominal position in the robot file (the fit corrects it)")
            return robot, None
    try:
        placement = estimate_placement(robot, spread_sample(data), loss)
    except ModelError:
        if robot.estimated:
            raise
        return robot, None  # the data cannot place the targets, and the robot file does
    far = {n: d for n, d in placement.moved_mm.items() if d is None or d > 1e3 * FAR_M}
    unsupported = [n for n, d in far.items() if d is not None and d > 1e3 * HOLD_M]
    if unsupported:
        given = given_rms_mm(robot, spread_sample(data))
        if given <= 1e3 * FITS_M:
            held = {n: f"the data would move it {far.pop(n):.0f} mm, further than they support (beyond "
                       f"{1e3 * HOLD_M:g} mm, while where the robot file puts it the nominal model already leaves "
                       f"only {given:.3g} mm rms): the poses barely turn the tool, so its position is weakly "
                       f"determined; held at the robot file's value (the fit's last-frame errors take up the rest)"
                    for n in unsupported}
            placement = dataclasses.replace(placement, held=held)
    turned = {n: placement.frames[n] for n, a in placement.turned_mrad.items() if a > 1e3 * FAR_RAD}
    if not far and not turned:
        return robot, placement if placement.held else None
    return with_targets(robot, {n: placement.targets[n] for n in far}, turned), placement
