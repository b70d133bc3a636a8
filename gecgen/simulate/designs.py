"""Measurement designs: which joint configurations and payloads are measured.

A design is the sequence of poses in the order they are visited (backlash depends on it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gecgen.model.kinematics import target_positions
from gecgen.model.robot import Robot


@dataclass(frozen=True)
class Design:
    """q (P, n) read joints in visiting order; payload_kg (P,); payload_at (3,) tool-frame point;
    targets measured at every pose (names); group (P,) a label per pose (e.g. "a", "b")."""

    q: np.ndarray
    payload_kg: np.ndarray
    payload_at: np.ndarray
    targets: tuple[str, ...]
    group: np.ndarray

    @property
    def n_poses(self) -> int:
        return len(self.q)


def approach_directions(q: np.ndarray) -> np.ndarray:
    """Sign of each joint's last motion before each pose (+1 for the first pose and for no motion)."""
    d = np.sign(np.diff(q, axis=0, prepend=q[:1] - 1.0))
    for k in range(1, len(d)):
        still = d[k] == 0
        d[k, still] = d[k - 1, still]
    return np.where(d == 0, 1.0, d)


def _limits(robot: Robot):
    lo, hi = map(np.array, robot.sampling_box())
    return lo, hi


def joined(*designs: Design) -> Design:
    """The designs' poses one after the other (their payload_at and targets: the first's)."""
    first = designs[0]
    return Design(np.vstack([d.q for d in designs]), np.concatenate([d.payload_kg for d in designs]),
                  first.payload_at, first.targets, np.concatenate([d.group for d in designs]))


def with_payloads(q: np.ndarray, payloads_kg, group: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every configuration once per payload."""
    payloads_kg = list(payloads_kg)
    return (np.vstack([q] * len(payloads_kg)), np.repeat(payloads_kg, len(q)).astype(float),
            np.array([group] * (len(q) * len(payloads_kg))))


def random_design(robot: Robot, n_poses: int, rng: np.random.Generator, payloads_kg=(0.0,),
                  payload_at=(0, 0, 0), targets=None) -> Design:
    """Uniform within the joint limits (continuous joints within +-pi), a random payload per pose."""
    lo, hi = _limits(robot)
    q = rng.uniform(lo, hi, (n_poses, robot.n))
    payload = rng.choice(np.asarray(payloads_kg, float), n_poses)
    return Design(q, payload, np.asarray(payload_at, float), tuple(targets or robot.targets),
                  np.array(["random"] * n_poses))


def one_at_a_time(robot: Robot, steps: dict[int, float], payloads_kg=(0.0,), payload_at=(0, 0, 0),
                  targets=None) -> Design:
    """Each listed joint (1-based) moved alone from home over its limits in the given step; home is
    measured with every joint's sweep, as a sweep starts there."""
    lo, hi = _limits(robot)
    rows = []
    for j, step in steps.items():
        k = int(np.floor(hi[j - 1] / step + 1e-9))
        values = np.arange(-int(np.floor(-lo[j - 1] / step + 1e-9)), k + 1) * step
        for v in values:
            q = np.zeros(robot.n)
            q[j - 1] = v
            rows.append(q)
    q, payload, group = with_payloads(np.array(rows), payloads_kg, "b")
    return Design(q, payload, np.asarray(payload_at, float), tuple(targets or robot.targets), group)


def treatment_volume_vertices(size=(0.50, 0.40, 0.50)) -> np.ndarray:
    """The 8 vertices (tool frame, m) of the treatment volume: a 50 x 50 cm area on the couch
    centred on the treatment point and 40 cm above it (tool y is up at home)."""
    sx, sy, sz = size
    return np.array([[x, y, z] for x in (-sx / 2, sx / 2) for y in (0.0, sy) for z in (-sz / 2, sz / 2)])


def paper_pps(robot: Robot, payloads_kg=(0.0, 70.0), thetas_deg=range(-90, 91, 30), targets=("t1", "t2", "t3"),
              steps=(0.050, 0.020, 0.025, np.radians(5.0))) -> Design:
    """The seed paper's design for the PPS.

    Set a: each vertex of the treatment volume placed at the isocenter for theta (joint 4) from -90
    to 90 degrees in 30 degree steps, roll and pitch at 0; joints 1-3 translate the couch along
    world X, Y, Z, so they follow in closed form. Set b: d1, d2, d3 and theta each moved alone from
    home in 50 mm, 20 mm, 25 mm and 5 degree steps. Both with each payload (kg) at the treatment
    point (the tool origin).
    """
    iso = np.array(robot.points["isocenter"])
    rows = []
    for theta in np.radians(list(thetas_deg)):
        q0 = np.zeros(robot.n)
        q0[3] = theta
        for v in treatment_volume_vertices():
            probe = _with_target(robot, v)
            q = q0.copy()
            q[:3] = iso - target_positions(probe, q0)[0, -1]
            rows.append(q)
    qa, pa, ga = with_payloads(np.array(rows), payloads_kg, "a")
    b = one_at_a_time(robot, {1: steps[0], 2: steps[1], 3: steps[2], 4: steps[3]}, payloads_kg)
    return Design(np.vstack([qa, b.q]), np.concatenate([pa, b.payload_kg]), np.zeros(3), tuple(targets),
                  np.concatenate([ga, b.group]))


def _with_target(robot: Robot, point) -> Robot:
    from dataclasses import replace

    return replace(robot, targets={**robot.targets, "_probe": tuple(float(x) for x in point)})


def paper_split(design: Design, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Pose indices (train, validation): set b and a random half of set a's configurations (both
    payloads of a configuration stay together) for training, the other half for validation."""
    a = np.nonzero(design.group == "a")[0]
    n_cfg = len(a) // max(1, len(np.unique(design.payload_kg[a])))
    cfg = rng.permutation(n_cfg)[: n_cfg // 2]
    val = a[np.isin(a % n_cfg, cfg)]
    train = np.setdiff1d(np.arange(design.n_poses), val)
    return train, val


#: inverse kinematics of a pose design: the tool within this of its goal (m, and rad) counts as reached
POSE_REACHED = 1e-9


def pose_ik(robot: Robot, goals: np.ndarray, start: np.ndarray, iterations: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Joint readings (N, n) putting the nominal tool frame at each goal (N, 4, 4) within POSE_REACHED,
    by damped least-norm Newton steps from `start` (n,) (a redundant arm keeps its posture nearest the
    start), within the sampling box; and which goals were reached (N,)."""
    from scipy.spatial.transform import Rotation

    from gecgen.model.kinematics import tool_pose

    lo, hi = _limits(robot)
    n, N = robot.n, len(goals)
    q = np.tile(np.asarray(start, float), (N, 1))
    h = 1e-7

    def error(q):
        T = tool_pose(robot, q)
        turn = Rotation.from_matrix(goals[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2)).as_rotvec()
        return np.column_stack([goals[:, :3, 3] - T[:, :3, 3], turn])

    for _ in range(iterations):
        err = error(q)
        todo = np.linalg.norm(err, axis=1) > POSE_REACHED
        if not todo.any():
            break
        J = np.stack([(error(q) - error(q + h * np.eye(n)[j])) / h for j in range(n)], axis=2)  # d(-err)/dq
        JJ = np.einsum("nij,nkj->nik", J, J) + 1e-10 * np.eye(6)
        step = np.einsum("nji,nj->ni", J, np.linalg.solve(JJ, err[..., None])[..., 0])
        q = np.where(todo[:, None], np.clip(q + step, lo, hi), q)
    return q, np.linalg.norm(error(q), axis=1) <= POSE_REACHED


def constant_orientation(robot: Robot, home, spacing_m: float, counts=(6, 6, 6), targets=None, wobble_rad: float = 0.0,
                         rng: np.random.Generator | None = None, shift=(0.0, 0.0, 0.0)) -> Design:
    """A laser tracker's common design: the tool keeps the orientation it has at `home` (n,)
    (so that its reflector keeps facing the tracker) while its origin visits a grid of counts
    (3,) points spacing_m apart, centred where home puts it (counts (k, k, 1): a planar grid).
    Poses come from inverse kinematics of the nominal model (`pose_ik`, from home), visited in grid
    order; grid points out of reach are left out. The data then never determine the tool's
    orientation errors (one measured point) nor anything only a turn of the tool shows. shift (3,),
    m: the grid moved off that centre (half a spacing: held-out points between the grid's).

    wobble_rad: the orientation each pose holds is off by a random rotation of this size (rad per
    axis, drawn from rng), as when the controller's kinematics are not the robot file's: the nominal
    tool then turns a little, and the data determine what a turn shows only weakly."""
    from gecgen.model.kinematics import tool_pose

    home = np.asarray(home, float)
    T0 = tool_pose(robot, home[None])[0]
    axes = [(np.arange(k) - (k - 1) / 2) * spacing_m for k in counts]
    offsets = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3) + np.asarray(shift, float)
    goals = np.repeat(T0[None], len(offsets), 0)
    goals[:, :3, 3] += offsets
    if wobble_rad:
        from scipy.spatial.transform import Rotation

        turn = Rotation.from_rotvec(rng.normal(0.0, wobble_rad, (len(goals), 3))).as_matrix()
        goals[:, :3, :3] = turn @ goals[:, :3, :3]
    q, ok = pose_ik(robot, goals, home)
    q = q[ok]
    if not len(q):
        raise ValueError("no grid point is within reach: a smaller spacing or another home")
    return Design(q, np.zeros(len(q)), np.zeros(3), tuple(targets or robot.targets), np.array(["grid"] * len(q)))


def barely_moving(robot: Robot, n_poses: int, rng: np.random.Generator, joint: int, span: float,
                  targets=None, payloads_kg=(0.0,)) -> Design:
    """Random poses within the limits (`random_design`) except joint `joint` (1-based), which stays
    within `span` (m or rad) about the middle of its range: the data then hardly separate its errors."""
    design = random_design(robot, n_poses, rng, payloads_kg, targets=targets)
    lo, hi = _limits(robot)
    middle = (lo[joint - 1] + hi[joint - 1]) / 2
    q = design.q.copy()
    q[:, joint - 1] = middle + rng.uniform(-span / 2, span / 2, n_poses)
    return Design(q, design.payload_kg, design.payload_at, design.targets, np.array(["barely"] * n_poses))
