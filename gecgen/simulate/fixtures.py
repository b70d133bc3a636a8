"""Simulated calibration without a tracker: a ball seated in the sockets of a plate, a probe touching
planes (`model.relative`).

The robot is moved until its target (the ball's centre, the probe's tip) truly sits in the socket or
on the plane: the configurations come from inverse kinematics of the truth robot, from random
starts within the joint limits, so each socket is reached in many different ways as a person
guiding the arm by hand would. The true contact point scatters by the seating noise (a ball does not
seat twice at the same micrometre; a probe's tip along the plane's normal), and the controller
records the joints with the encoder noise.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.kinematics import target_positions
from gecgen.model.measurements import Measurements
from gecgen.model.relative import PLANE, POINT, Distance, Relation, Relative
from gecgen.model.robot import Robot
from gecgen.model.validation import ModelError, require
from gecgen.fit.relative import measures
from gecgen.simulate.designs import approach_directions
from gecgen.simulate.truth import Truth, thermal_profile, true_state

#: inverse kinematics: the true target within this of its goal (m) counts as reached
REACHED_M = 1e-10
#: restarts from new random configurations for goals a start did not reach
RESTARTS = 10
#: placements of the fixtures tried before giving up: a random spot may leave a socket or a corner of
#: a plane out of reach
PLACEMENTS = 20
#: joint limits are shrunk by this share of their range for starts, so IK has room to move
MARGIN = 0.1
#: half-width (m) of the square patch of a plane the probe touches, around its centre
PATCH_M = 0.1


@dataclass(frozen=True)
class Fixtures:
    """What to simulate: `plates` placements of a plate with two sockets `distance_m` apart (m),
    `per_socket` configurations each; `planes` planes (a table, then faces of a square standing on
    it, up to three), `touches` configurations each; the `target` that sits in the sockets or
    touches; seating_m (m, per coordinate of a seat; along the normal for a touch) and encoder_rad
    (rad or m per joint reading) noise; distance_std_m the stated uncertainty of the distance;
    `relations`: the planes' known perpendicularity is declared (the square's faces and the table);
    block_m: a block of that width (m) stands on the table, its far face a fourth plane parallel to
    the first face at that offset, declared; distance_known: the plates' distance is declared in the
    data (False: the sockets are measured without a known distance, and nothing fixes the scale)."""

    target: str
    plates: int = 0
    per_socket: int = 25
    distance_m: float = 0.05
    distance_std_m: float = 0.0
    planes: int = 0
    touches: int = 30
    seating_m: float = 1e-5
    encoder_rad: float = 1e-5
    relations: bool = False
    block_m: float | None = None
    distance_known: bool = True


def _goals(robot: Robot, truth: Truth, fixtures: Fixtures, rng: np.random.Generator):
    """The true contact points (N, 3) m, the group of each (N,), the groups' names and kinds, the
    plates' distances and the planes' relations."""
    lo, hi = _box(robot)
    up = -truth.gravity / np.linalg.norm(truth.gravity) if np.linalg.norm(truth.gravity) > 0 else np.array([0, 0, 1.0])
    t = list(robot.targets).index(fixtures.target)
    goals, group, names, kinds, distances = [], [], [], [], []

    def somewhere() -> np.ndarray:  # a point the target reaches: where it is at a random configuration
        return target_positions(robot, rng.uniform(lo, hi, (1, robot.n)))[0, t]

    for i in range(fixtures.plates):
        centre = somewhere()
        along = np.cross(up, rng.normal(size=3))  # the plate lies flat: its sockets apart across the vertical
        along /= np.linalg.norm(along)
        for k, sign in enumerate((0.5, -0.5)):
            socket = centre + sign * fixtures.distance_m * along
            goals.append(socket + rng.normal(0, fixtures.seating_m, (fixtures.per_socket, 3)))
            group += [len(names)] * fixtures.per_socket
            names.append(f"plate{i + 1}.{k}")
            kinds.append(POINT)
        if fixtures.distance_known:
            distances.append(Distance(len(names) - 2, len(names) - 1, fixtures.distance_m, fixtures.distance_std_m))
    require(fixtures.planes <= 3, f"{fixtures.planes} planes: simulated planes are a table and up to two faces of a "
                                  f"square on it; give at most 3")
    corner = somewhere() if fixtures.planes else None
    side = np.cross(up, rng.normal(size=3))
    side /= np.linalg.norm(side)
    faces = [(up, corner), (side, corner), (np.cross(up, side), corner)][:fixtures.planes]
    if fixtures.block_m:
        require(fixtures.planes >= 2, "a block's far face is parallel to the first face of the square: give "
                                      "--planes 2 or 3 with --block-width")
        faces.append((side, corner + fixtures.block_m * side))
    first = len(names)
    for i, (normal, through) in enumerate(faces):
        tangents = np.linalg.svd(normal[None, :])[2][1:]  # two unit vectors across the normal
        offsets = rng.uniform(-PATCH_M, PATCH_M, (fixtures.touches, 2)) @ tangents
        # the table below the corner, the square's faces through it: all within reach of one spot
        goals.append(through + offsets + rng.normal(0, fixtures.seating_m, (fixtures.touches, 1)) * normal)
        group += [len(names)] * fixtures.touches
        names.append(f"plane{i + 1}")
        kinds.append(PLANE)
    relations = []
    if fixtures.relations:
        relations = [Relation(first + a, first + b, "perpendicular", 0.0, 0.0)
                     for a in range(min(fixtures.planes, 3)) for b in range(a + 1, min(fixtures.planes, 3))]
    if fixtures.block_m:
        relations.append(Relation(first + 1, first + len(faces) - 1, "offset", fixtures.block_m, 0.0))
    require(goals, "give plates or planes to simulate (--plates N or --planes N)")
    return np.vstack(goals), np.array(group), tuple(names), tuple(kinds), tuple(distances), tuple(relations)


def _box(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = map(np.array, robot.sampling_box())
    return lo + MARGIN * (hi - lo), hi - MARGIN * (hi - lo)


def simulate_fixtures(robot: Robot, truth: Truth, fixtures: Fixtures,
                      rng: np.random.Generator) -> tuple[Measurements, dict]:
    """Measurements of the fixtures on the truth robot, one pose per configuration (in the order
    sockets and planes are listed), and what seating and encoder noise alone leave of the relative
    measures (consistency, flatness, distance errors in mm; `fit.relative.measures` of the true
    targets at the recorded joints): the floor a perfect calibration reaches."""
    require(fixtures.target in robot.targets, f"--target {fixtures.target}: not a target of {robot.name} "
                                              f"({', '.join(robot.targets)})")
    built = truth.robot or robot  # the robot as built: its couplings may differ from the file's
    t = list(built.targets).index(fixtures.target)
    for _ in range(PLACEMENTS):
        goals, group, names, kinds, distances, relations = _goals(built, truth, fixtures, rng)
        N = len(goals)
        aux = thermal_profile(truth, N)

        def reached(q: np.ndarray, rows: np.ndarray = slice(None)) -> np.ndarray:
            k = q[rows]  # each joint approaches a pose from the one before it in q, stepped or not
            q_true, eps = true_state(built, truth, k, np.zeros(len(k)), np.zeros(3),
                                     {a: v[rows] for a, v in aux.items()}, approach_directions(q)[rows])
            return target_positions(built, q_true, eps)[:, t]

        q, ok = reach(built, reached, lambda q: target_positions(built, q)[:, t], goals, rng)
        if ok.all():
            break
    else:
        raise ModelError(f"no placement of the fixtures in {PLACEMENTS} tries puts every socket and touch within the "
                         f"robot's reach; fewer or smaller fixtures, or another seed")
    recorded = q + rng.normal(0.0, fixtures.encoder_rad, q.shape)
    lo, hi = (np.array(v) for v in built.sampling_box())
    recorded = np.clip(recorded, lo, hi)  # an encoder never reads past the limit it stops at
    relative = Relative(group, names, kinds, distances, relations)
    aux_names = tuple(aux)
    data = Measurements(q=recorded, w=np.zeros((N, 6)),
                        aux=np.column_stack([aux[a] for a in aux_names]) if aux_names else np.zeros((N, 0)),
                        aux_names=aux_names, pose_ids=np.arange(N), pose=np.arange(N), target=np.full(N, t),
                        xyz=np.full((N, 3), np.nan), source="simulated", relative=relative)
    return data, measures(relative, reached(recorded))


def reach(robot: Robot, reached, nominal, goals: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Joint readings (N, n) at which `reached` (readings (N, n), row indices rows (k,) -> the true
    target positions of those rows, (k, 3)) meets each goal (N, 3) within REACHED_M, within the joint
    limits: damped Newton steps from random starts, restarted where a start does not get there; and
    which goals were reached (N,). Only the goals not yet reached are stepped: the truth's gravity
    and compliance are the simulator's dearest part. The steps take the Jacobian of the `nominal`
    kinematics (readings -> positions): a robot's errors change it by a part in a thousand, which
    slows no step noticeably, and it is far cheaper than the truth's."""
    lo, hi = _box(robot)
    full_lo, full_hi = (np.array(v) for v in robot.sampling_box())
    q = rng.uniform(lo, hi, (len(goals), robot.n))
    todo = np.arange(len(goals))
    h = 1e-7
    for _ in range(RESTARTS):
        for _ in range(60):
            err = goals[todo] - reached(q, todo)
            far = np.linalg.norm(err, axis=1) > REACHED_M
            todo, err = todo[far], err[far]
            if not len(todo):  # a joint's play may have moved a reached goal when the pose before it moved
                todo = np.flatnonzero(np.linalg.norm(goals - reached(q), axis=1) > REACHED_M)
                if not len(todo):
                    return q, np.ones(len(goals), bool)
                continue
            qt = q[todo]
            x0 = nominal(qt)
            J = np.stack([(nominal(qt + h * np.eye(robot.n)[j]) - x0) / h for j in range(robot.n)], axis=2)
            JJ = np.einsum("nij,nkj->nik", J, J) + 1e-8 * np.eye(3)
            step = np.einsum("nji,nj->ni", J, np.linalg.solve(JJ, err[..., None])[..., 0])
            q[todo] = np.clip(qt + step, full_lo, full_hi)
        q[todo] = rng.uniform(lo, hi, (len(todo), robot.n))
    ok = np.ones(len(goals), bool)
    ok[todo] = np.linalg.norm(goals[todo] - reached(q, todo), axis=1) <= REACHED_M
    return q, ok
