"""ISO 9283:1998 pose performance of a manipulator, planned: the test cube, its five points and the
readings that visit them (`verify.iso9283` scores a measured run). Inputs and results in m and rad.

Test geometry (the standard's test cube and poses to be tested, as implemented here). The test cube
is the largest cube, its edges along the world (base) axes or along the columns of a given rotation,
whose eight corners and centre - and the five test points - the tool frame's origin reaches with the
tool in one stated orientation, every joint reading within its limits. Its corners are
numbered, in the cube's axes u, v, w: C1 (-,-,-), C2 (+,-,-), C3 (+,+,-), C4 (-,+,-) round the
bottom face, counterclockwise seen from +w, and C5..C8 above C1..C4. With this numbering the four
diagonal planes the standard names (C1-C2-C7-C8, C2-C3-C8-C5, C3-C4-C5-C6, C4-C1-C6-C7) are each a
rectangle through two opposite edges. The default plane is C1-C2-C7-C8 (edge C1C2 along u at the
bottom, edge C7C8 along u at the top, opposite); the others are available (`PLANES`). P1 is the
centre; P2, P3, P4, P5 lie on the plane's diagonals (the cube's space diagonals C1-C7, C2-C8 on the
default plane) at 10 % of the diagonal's length from the plane's corners taken in the order named
(C1, C2, C7, C8 on the default plane): P = centre + 0.8 (C - centre). A cycle visits P1, P5, P4,
P3, P2 and returns to P1, so each point is approached from the same neighbour every cycle (the very
first P1 aside, see `command_table`); 30 cycles.

Finding the cube is a search, not a proof (`plan_cube`): inverse kinematics on the nominal chain
(damped least squares on position and orientation) decides whether a cube is reached, and a pattern
search over its centre and side climbs to a locally largest one; a different seed may find a larger
cube. Only the eight corners, the centre and the five points are checked, not the cube's edges and
faces.

What we were unsure of, and chose: the corner numbering of the standard's figure is reconstructed
from the four plane names above, and the 10 % is the middle of the standard's (10 +- 2) %.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.model.kinematics import constant, frames, tool_poses
from gecgen.model.robot import Robot
from gecgen.model.validation import require

#: the standard's number of cycles per point for pose accuracy and repeatability
CYCLES = 30
#: P2..P5 sit this share of the diagonal's length from their corners (the standard: (10 +- 2) %)
CORNER_SHARE = 0.10
#: corners C1..C8 as signs along the cube's axes u, v, w (see the module docstring)
CORNER_SIGNS = np.array([(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1),
                         (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)], float)
#: the standard's diagonal planes: their corners (1-based) in the order P2, P3, P4, P5 are taken from
PLANES = {"C1-C2-C7-C8": (1, 2, 7, 8), "C2-C3-C8-C5": (2, 3, 8, 5), "C3-C4-C5-C6": (3, 4, 5, 6),
          "C4-C1-C6-C7": (4, 1, 6, 7)}
#: one cycle's visiting order (the standard's P1 -> P5 -> P4 -> P3 -> P2 -> P1: the closing P1 is the
#: next cycle's first)
ORDER = (1, 5, 4, 3, 2)
#: inverse kinematics: the tool frame within these of its goal (m, rad) counts as reached
REACHED_M = 1e-11
REACHED_RAD = 1e-11
#: Levenberg-Marquardt damping (m^2 + rad^2 per unit joint motion squared): the start, the floor it is
#: lowered to while steps succeed (small enough to leave Gauss-Newton's convergence near the goal),
#: and the ceiling past which a start is stuck
DAMPING = 1e-2
MIN_DAMPING = 1e-12
GIVE_UP = 1.0
#: a step counts as progress when it leaves at most this share of the squared error; a start that
#: creeps along a limit or into a local minimum stops making progress and is started again
PROGRESS = 0.5
ITERATIONS = 60
#: the candidate centres' sides are bisected to this share of the workspace's extent only: they are
#: compared, and the pattern search refines the best
COARSE = 1 / 32
#: the pattern search's side increments, in multiples of its centre's move
GROWTH = (0.25, 0.5, 1.0, 2.0)
#: pattern searches run side by side, from the candidate centres with the largest coarse sides: each
#: climbs to the largest cube near its start, and the starts' arm configurations differ
SEARCHES = 4
#: random starts per candidate centre besides its own configuration: a random start reaches a pose in
#: a stated orientation only now and then
CENTRE_STARTS = 8
#: random configurations whose tool positions bound the workspace's extent (the bisection's upper end)
EXTENT_SAMPLES = 2000


@dataclass(frozen=True)
class CubePlan:
    """The ISO 9283 test: the cube (centre (3,) m in the world, side m, `cube_rotation` (3, 3) whose
    columns are its axes u, v, w in the world), the tool orientation (3, 3) at every point, the
    diagonal plane, the points P1..P5 (5, 3) m and the joint readings q (5, n) that reach them, the
    readings corner_q (8, n) that reach C1..C8 (the evidence that the cube is reached; the test does
    not visit them), and how the points are visited: `cycles` times in `order` (1-based numbers)."""

    centre: np.ndarray
    side_m: float
    cube_rotation: np.ndarray
    tool_rotation: np.ndarray
    plane: str
    points: np.ndarray
    q: np.ndarray
    corner_q: np.ndarray
    cycles: int = CYCLES
    order: tuple[int, ...] = ORDER

    @property
    def corners(self) -> np.ndarray:
        """C1..C8 (8, 3), m."""
        return cube_corners(self.centre, self.side_m, self.cube_rotation)

    def poses(self) -> np.ndarray:
        """The commanded tool poses at P1..P5, (5, 4, 4)."""
        return _poses(self.points, self.tool_rotation)


def cube_corners(centre: np.ndarray, side_m: float, cube_rotation: np.ndarray) -> np.ndarray:
    """The corners C1..C8 (8, 3) of the cube with centre (3,) m, side m and axes the columns of
    `cube_rotation` (3, 3)."""
    return np.asarray(centre, float) + 0.5 * side_m * CORNER_SIGNS @ np.asarray(cube_rotation, float).T


def plane_points(centre: np.ndarray, side_m: float, cube_rotation: np.ndarray,
                 plane: str = "C1-C2-C7-C8") -> np.ndarray:
    """The test points P1..P5 (5, 3), m: the centre, then on the plane's diagonals at CORNER_SHARE of a
    diagonal's length from its corners in the plane's order. A diagonal runs through the centre, so a
    point that far from its corner is 1 - 2 CORNER_SHARE of the way from the centre to it."""
    require(plane in PLANES, f"plane '{plane}': not one of the standard's diagonal planes ({', '.join(PLANES)})")
    centre = np.asarray(centre, float)
    corners = cube_corners(centre, side_m, cube_rotation)[[k - 1 for k in PLANES[plane]]]
    return np.vstack([centre, centre + (1 - 2 * CORNER_SHARE) * (corners - centre)])


def plan_cube(robot: Robot, tool_rotation: np.ndarray, *, cube_rotation: np.ndarray | None = None,
              plane: str = "C1-C2-C7-C8", cycles: int = CYCLES, branch: int = 0, candidates: int = 32,
              tolerance_m: float = 1e-3, rng: np.random.Generator | None = None) -> CubePlan:
    """The ISO 9283 test cube and points of `robot` (nominal kinematics) with the tool frame of branch
    `branch` in orientation `tool_rotation` (3, 3, world) at every point; the cube's axes along the
    world's, or the columns of `cube_rotation` (3, 3).

    The search: the tool positions of `candidates` random configurations (within the sampling box)
    that the tool also reaches in the stated orientation are candidate centres, and each one's
    largest side is bisected coarsely. From the SEARCHES best, pattern searches move the centre by
    `move` (a quarter of the side at first) along +-u, +-v, +-w or not at all, with sides larger by
    GROWTH times `move`, take the largest cube reached, and halve `move` when none is, down to
    `tolerance_m` (m); the largest cube of all is the plan. Each cube is solved from the
    configuration of the centre it grew from, without random restarts, so its points are reached by
    continuous motion from there: mostly in one arm configuration, as a test program runs. `rng`
    defaults to a fixed seed: the same robot gives the same plan. ModelError when no candidate
    centre, or no cube, is reached in the orientation."""
    rng = np.random.default_rng(0) if rng is None else rng
    tool_rotation = _rotation(tool_rotation, "tool_rotation")
    cube_rotation = np.eye(3) if cube_rotation is None else _rotation(cube_rotation, "cube_rotation")
    require(plane in PLANES, f"plane '{plane}': not one of the standard's diagonal planes ({', '.join(PLANES)})")
    require(cycles >= 2, f"cycles {cycles}: repeatability needs at least 2")
    tip = robot.tips()[branch][0]
    moving = {k for i in robot.path(tip) if i > 0 for k, _ in robot.drives()[i - 1][0]}
    which = f" of branch '{robot.branches[branch].name}'" if robot.branches else ""
    # one orientation at points spread in three directions takes six degrees of freedom, but for
    # arms built for it (a SCARA's tool pointing down): fewer joints are named when none is found
    which += f" (moved by {len(moving)} joints: fewer than 6 hold one orientation over a cube only by design)" \
        if len(moving) < 6 else ""
    search = _Search(robot, tool_rotation, cube_rotation, plane, branch, rng)

    lo, hi = (np.array(v) for v in robot.sampling_box())
    reach = tool_poses(robot, rng.uniform(lo, hi, (EXTENT_SAMPLES, robot.n)))[branch][:, :3, 3] @ cube_rotation
    upper = float(np.min(reach.max(axis=0) - reach.min(axis=0)))  # no side exceeds the reach along an axis
    centres = reach[:candidates] @ cube_rotation.T
    q_centres, reached = search.reach(_poses(centres, tool_rotation), rng.uniform(lo, hi, (len(centres), robot.n)),
                                      CENTRE_STARTS)
    require(reached.any(), f"{robot.name}: none of {candidates} candidate centres is reached with the tool{which} in "
                           f"the stated orientation; give another tool orientation")
    sides, q = search.bisect(centres[reached], q_centres[reached], upper, max(tolerance_m, COARSE * upper))
    top = np.argsort(-sides)[:SEARCHES]
    centre, side, q_best = centres[reached][top], sides[top], q[top]
    require(side[0] > 0, f"{robot.name}: no cube around {candidates} candidate centres is reached with the "
                         f"tool{which} in the stated orientation; give another tool orientation")

    move = 0.25 * side
    moves = np.vstack([np.zeros(3), cube_rotation.T, -cube_rotation.T])  # stay first: a tie keeps the centre
    growth = np.array(GROWTH)
    tries = len(moves) * len(growth)
    while (move >= tolerance_m).any():
        on = np.flatnonzero(move >= tolerance_m)  # the searches still going, each tries its own cubes
        tried = np.repeat(centre[on, None] + move[on, None, None] * moves, len(growth), axis=1)  # (S, tries, 3)
        tried_sides = np.tile(side[on, None] + move[on, None] * growth, (1, len(moves)))  # (S, tries)
        ok, q = search.check(tried.reshape(-1, 3), tried_sides.ravel(), q_best[on, 0].repeat(tries, axis=0))
        ok, q = ok.reshape(len(on), tries), q.reshape(len(on), tries, 13, -1)
        for i, k in enumerate(on):
            j = int(np.argmax(np.where(ok[i], tried_sides[i], -np.inf)))
            if ok[i, j]:
                centre[k], side[k], q_best[k] = tried[i, j], tried_sides[i, j], q[i, j]
            else:
                move[k] /= 2
    best = int(np.argmax(side))
    centre, side, q_best = centre[best], float(side[best]), q_best[best]
    return CubePlan(centre=centre, side_m=side, cube_rotation=cube_rotation, tool_rotation=tool_rotation, plane=plane,
                    points=plane_points(centre, side, cube_rotation, plane), q=q_best[:5], corner_q=q_best[5:],
                    cycles=cycles)


def command_table(plan: CubePlan) -> tuple[tuple[str, ...], np.ndarray]:
    """The plan as joint commands in visiting order: column names ("cycle", "point", "q1", .., "qn") and
    rows (cycles * 5, 2 + n), cycle 1..cycles and point 1..5 then the joint readings (rad or m). The
    first P1 is approached from wherever the robot stands; start it from P2 for that approach to match
    the others'."""
    n = plan.q.shape[1]
    rows = [[cycle, p, *plan.q[p - 1]] for cycle in range(1, plan.cycles + 1) for p in plan.order]
    return ("cycle", "point", *(f"q{k}" for k in range(1, n + 1))), np.array(rows, float)


def _rotation(R, name: str) -> np.ndarray:
    R = np.asarray(R, float)
    require(R.shape == (3, 3) and np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0,
            f"{name}: not a rotation matrix (3, 3)")
    return R


def _poses(points: np.ndarray, R: np.ndarray) -> np.ndarray:
    T = np.broadcast_to(np.eye(4), points.shape[:-1] + (4, 4)).copy()
    T[..., :3, :3], T[..., :3, 3] = R, points
    return T


class _Search:
    """Inverse kinematics of whole cubes for `plan_cube`: one robot, tool orientation, cube axes and plane."""

    def __init__(self, robot: Robot, tool_rotation, cube_rotation, plane: str, branch: int, rng: np.random.Generator):
        self.robot, self.tool_rotation, self.cube_rotation, self.plane = robot, tool_rotation, cube_rotation, plane
        self.branch, self.rng = branch, rng
        self.box = [np.array(v) for v in robot.sampling_box()]  # random starts
        self.lo, self.hi = (np.array([getattr(j, end) for j in robot.joints]) for end in ("lower", "upper"))
        self.pre = [constant(joint.pre) for joint in robot.chain]
        self.axes = [np.array([float(a) for a in joint.axis]) for joint in robot.chain]
        self.path = set(robot.path(robot.tips()[branch][0]))

    def bisect(self, centres, q_centres, upper: float, tolerance_m: float):
        """Per candidate centre (K, 3) with its configuration (K, n): the largest side (K,) found
        between 0 and `upper` to `tolerance_m`, and the readings (K, 13, n) at P1..P5 and the corners
        there (at a side of 0 every point is the centre)."""
        lo, hi = np.zeros(len(centres)), np.full(len(centres), upper)
        q = np.repeat(q_centres[:, None], 13, axis=1)
        while hi[0] - lo[0] > tolerance_m:
            mid = 0.5 * (lo + hi)
            ok, q_mid = self.check(centres, mid, q_centres)
            lo, hi, q[ok] = np.where(ok, mid, lo), np.where(ok, hi, mid), q_mid[ok]
        return lo, q

    def check(self, centres, sides, q_centres):
        """Whether each cube (centres (K, 3), sides (K,)) is reached at P1..P5 and its corners, and the
        readings (K, 13, n) there."""
        points = np.stack([np.vstack([plane_points(c, s, self.cube_rotation, self.plane),
                                      cube_corners(c, s, self.cube_rotation)]) for c, s in zip(centres, sides)])
        K = len(centres)
        q, ok = self.reach(_poses(points.reshape(-1, 3), self.tool_rotation), np.repeat(q_centres, 13, axis=0), 0)
        return ok.reshape(K, 13).all(axis=1), q.reshape(K, 13, -1)

    def reach(self, goals, seeds, starts: int):
        """Readings (N, n) that put the tool at each goal pose (N, 4, 4), and whether they do: solved
        from its seed (N, n) alone, or with `starts` random configurations too, restarted where they get
        stuck; the reached solution nearest the seed kept."""
        N, n = seeds.shape
        q0 = np.concatenate([seeds[:, None], self.rng.uniform(*self.box, (N, starts, n))], axis=1)
        q, ok = self.solve(np.repeat(goals, starts + 1, axis=0), q0.reshape(-1, n), restart=starts > 0)
        q, ok = q.reshape(N, -1, n), ok.reshape(N, -1)
        pick = np.argmin(np.where(ok, np.linalg.norm(q - seeds[:, None], axis=2), np.inf), axis=1)
        return q[np.arange(N), pick], ok.any(axis=1)

    def solve(self, goals, q, restart: bool):
        """Levenberg-Marquardt on the tool pose from readings q (N, n), kept within the joint limits: the
        readings and whether each reached its goal (N, 4, 4). A step that does not lower a row's squared
        error (m^2 + rad^2) enough is refused and that row's damping raised; a row whose damping passes
        GIVE_UP is stuck (mostly against a joint limit): it starts again from a random configuration
        when `restart`, else it has failed."""
        q, n, tool = q.copy(), q.shape[1], self.robot.n_frames + 1 + self.branch
        W = np.stack(frames(self.robot, q))  # (frames, N, 4, 4): kept per row for its Jacobian
        err = _pose_error(goals, W[tool])
        cost = np.sum(err ** 2, axis=1)
        damping = np.full(len(q), DAMPING)
        for _ in range(ITERATIONS):
            stuck = damping >= GIVE_UP
            if restart and stuck.any():
                q[stuck] = self.rng.uniform(*self.box, (int(stuck.sum()), n))
                W[:, stuck] = np.stack(frames(self.robot, q[stuck]))
                err[stuck] = _pose_error(goals[stuck], W[tool, stuck])
                cost[stuck], damping[stuck] = np.sum(err[stuck] ** 2, axis=1), DAMPING
            rows = np.flatnonzero(~_reached(err) & (damping < GIVE_UP))
            if not len(rows):
                break
            J, d, qr = self.jacobian(W[:, rows]), damping[rows], q[rows]
            step = _step(J, err[rows], d)
            # a joint at its limit that the step pushes further stays there, and the others do its share
            held = ((qr <= self.lo) & (step < 0)) | ((qr >= self.hi) & (step > 0))
            step = np.where(held.any(axis=1)[:, None], _step(J * ~held[:, None, :], err[rows], d), step)
            trial = np.clip(qr + step, self.lo, self.hi)
            W_t = np.stack(frames(self.robot, trial))
            err_t = _pose_error(goals[rows], W_t[tool])
            cost_t = np.sum(err_t ** 2, axis=1)
            better = cost_t < PROGRESS * cost[rows]
            kept = rows[better]
            q[kept], W[:, kept], err[kept], cost[kept] = trial[better], W_t[:, better], err_t[better], cost_t[better]
            damping[rows] = np.where(better, np.maximum(damping[rows] / 3, MIN_DAMPING), damping[rows] * 4)
        return q, _reached(err)

    def jacobian(self, W: np.ndarray) -> np.ndarray:
        """d(tool position, world turn)/d readings (N, 6, n) from the frames W (frames, N, 4, 4) of
        `kinematics.frames`: a revolute joint turns the tool about its axis, a prismatic one moves it
        along; a reading moves every joint coupled to it by its multiplier."""
        robot = self.robot
        p = W[robot.n_frames + 1 + self.branch][:, :3, 3]
        J = np.zeros((W.shape[1], 6, robot.n))
        for i, (joint, pre, axis, (terms, _)) in enumerate(zip(robot.chain, self.pre, self.axes, robot.drives()), 1):
            if i not in self.path:
                continue
            A = W[robot.parent(i)] @ pre  # the joint's motion acts in this frame
            u = A[:, :3, :3] @ axis
            col = (np.concatenate([u, np.zeros_like(u)], axis=1) if joint.kind == "P" else
                   np.concatenate([np.cross(u, p - A[:, :3, 3]), u], axis=1))
            for k, multiplier in terms:
                J[:, :, k] += float(multiplier) * col
        return J


def _step(J: np.ndarray, err: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """The damped least-squares step J^T (J J^T + damping I)^-1 err per row: J (N, 6, n), err (N, 6)."""
    JJ = J @ J.transpose(0, 2, 1) + damping[:, None, None] * np.eye(6)
    return np.einsum("nji,nj->ni", J, np.linalg.solve(JJ, err[..., None])[..., 0])


def _reached(err: np.ndarray) -> np.ndarray:
    return (np.linalg.norm(err[:, :3], axis=1) <= REACHED_M) & (np.linalg.norm(err[:, 3:], axis=1) <= REACHED_RAD)


def _pose_error(goals: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(N, 6): the position error (m) and the rotation vector (rad, world) that turns T onto the goal."""
    turn = goals[:, :3, :3] @ np.swapaxes(T[:, :3, :3], -1, -2)
    return np.concatenate([goals[:, :3, 3] - T[:, :3, 3], Rotation.from_matrix(turn).as_rotvec()], axis=1)
