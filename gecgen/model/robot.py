"""The robot: kinematics, targets and wrench frame of one robot (CONTRACTS.md section 1).

A robot is a chain, or a tree, of frames 0..m. Frame 0 is the base; frame i sits after link i and
hangs from frame p(i) (i - 1 on a chain; on a tree the frame its branch leaves from):

    W_0 = base * E_0,    W_i = W_p(i) * pre_i * M_i(v_i) * post_i * E_i,    tool_b = W_tip(b) * T_tool(b)

(one tool, after frame m, on a chain; one per branch b on a tree).

`M_i` is the joint motion (rotation about, or translation along, the unit `axis`), `pre_i` and
`post_i` are constant transforms and `E_i` the six generalized errors of frame i. The joint
variables q1..qn are the controller's joint readings, one per joint that has one, in chain order;
the value v_i of frame i's joint is its own reading, or for a coupled joint an affine map of
readings: v_i = sum_k a_ik q_k + b_i (`Coupling`). A coupling comes from the robot file's
`couplings` (a FANUC J3 that reads the forearm's angle to the horizontal: the chain's joint 3 is
J2 + J3; a parallelogram; gears between wrist axes; a passive joint tied to others) or from a URDF
`<mimic>` (one followed joint, no reading of its own). Frames and readings are counted apart:
`Robot.chain` holds the m moving joints (the frames 1..m of the error model), `Robot.joints` the n
that have a reading (the columns q1..qn of every file and of the generated code); without
couplings they are the same. A DH row
`Rz(theta+q) Tz(d+q) Tx(a) Rx(alpha)` becomes `pre = I`, `axis = z`,
`post = Rz(theta) Tz(d) Tx(a) Rx(alpha)`; a URDF joint becomes `pre = origin`, `post = I`.

Constant transforms are kept as exact numbers (`model.exact`: 90 degrees stays pi/2) so the symbolic
chain prunes exact zeros; `model.kinematics` evaluates them in floating point. The nouns live
here; `model.robot_file` reads and validates robot files into them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from fractions import Fraction

from gecgen.model.validation import excerpt, require

#: An elementary transform: ("Tx"|"Ty"|"Tz"|"Rx"|"Ry"|"Rz", value) or ("H", 4x4 rows).
Elementary = tuple

WRENCH = ("fx", "fy", "fz", "mx", "my", "mz")
ERROR_NAMES = ("ex", "ey", "ez", "es", "er", "ep")
#: the wrench component that acts on each generalized error of a frame, in ERROR_NAMES order: a
#: translation with the force along it, a rotation with the moment about its axis (es turns about y)
MATCHING = ("fx", "fy", "fz", "my", "mz", "mx")
#: the default length scale L (m) of pose measurements (`Robot.pose_length`, `model.pose_targets`): an
#: orientation error of 1 mrad counts as 0.1 mm of position, about the ratio of a laser tracker's
#: position noise to a 6-D probe's orientation noise
LENGTH_M = 0.1
#: standard gravity, m/s^2, in the robot file's world frame unless the file's `gravity` says otherwise
GRAVITY = (0, 0, -9.80665)
#: the controllers a robot file may name (`controller`), by the programs `gecgen filter` corrects:
#: KUKA KRL, ABB RAPID, FANUC TP, Universal Robots' script
CONTROLLERS = ("kuka", "abb", "fanuc", "ur")
#: names of the term language (functions, pi) and of the generated code's variables: neither a joint
#: nor an auxiliary signal may take them
RESERVED = {"pi", "sqrt", "sin", "cos", "sign", "abs", "poly", "fourier", "wrench_torque", "gravity",
            "gravity_torque", "gravity_load", "wrench_load", "q", "eps", "w", "aux", "c", "f", "p", "J", "T", "Jq",
            "H", "ca", "np"}


@dataclass(frozen=True)
class Coupling:
    """A joint whose value is an affine map of the controller's readings: the sum over `terms` of
    multiplier * reading, plus `offset`, in its own unit (m or rad) per the reading's unit.

    `own`: the joint has a reading of its own (then one of the terms; the FANUC J3), else it is
    passive (a URDF `<mimic>`, a humanoid torso joint that is -(q2 + q3)). `declared`: the robot
    file's `couplings` states it, and its multipliers are calibration parameters (`ratio_terms`);
    a URDF `<mimic>` read as it is keeps the model it has always had."""

    terms: tuple[tuple[str, object], ...]  # (reading joint's name, exact nonzero multiplier), chain order
    offset: object  # exact number (`model.exact`), m or rad
    own: bool = False
    declared: bool = False

    def text(self, robot: "Robot") -> str:
        """The value in the readings q<k> ("1.0*q2 + 1.0*q3 + 0.0"), as the generated header shows it."""
        parts = [(float(m), f"*q{robot.joint_names.index(name) + 1}") for name, m in self.terms]
        text = f"{parts[0][0]!r}{parts[0][1]}"
        for value, tail in parts[1:] + [(float(self.offset), "")]:
            text += f" {'-' if value < 0 else '+'} {abs(value)!r}{tail}"
        return text


@dataclass(frozen=True)
class Joint:
    """One moving joint and the link after it; lengths in m, angles in rad. An independent joint's
    limits include what its mimic joints' limits allow (see `urdf.urdf_chain`)."""

    name: str
    kind: str  # "R" revolute or "P" prismatic
    axis: tuple  # unit vector (exact numbers, `model.exact`) in the frame after `pre`
    pre: tuple[Elementary, ...]
    post: tuple[Elementary, ...]
    lower: float  # joint limits, m or rad (of its reading; a passive joint's are not checked)
    upper: float
    coupling: Coupling | None = None

    @property
    def reads(self) -> bool:
        """The controller reports this joint (it has a variable q<k>)."""
        return self.coupling is None or self.coupling.own


@dataclass(frozen=True)
class Branch:
    """One tip of a tree: the frame its tool hangs from and the tool transform; its targets sit in
    that tool frame (a two-armed robot has a branch per hand)."""

    name: str
    tip: int  # frame 1..m
    tool: tuple[Elementary, ...]
    tip_link: str = ""  # with urdf: the link the tool hangs from


@dataclass(frozen=True)
class Robot:
    """Nominal kinematics of one robot plus its measurement targets (tool-frame xyz, m).

    A serial chain, or a tree: frame i hangs from frame `parent(i)` (i - 1 on a chain), and each
    branch (`branches`) has its own tip, tool and targets. On a tree, `tool` and `tip_link` are the
    first branch's; frames are numbered so that a parent comes before its children."""

    name: str
    chain: tuple[Joint, ...]  # the moving joints, frames 1..m in order (passive joints included)
    base: tuple[Elementary, ...]
    tool: tuple[Elementary, ...]
    targets: dict[str, tuple[float, float, float]]
    wrench_frame: str = "tool"
    #: targets whose placement the robot file leaves to the data (`estimate`); they sit at the tool
    #: origin until `fit.placement` places them, and nothing is fitted or compensated before
    estimated: tuple[str, ...] = ()
    points: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    source: str = ""
    source_hashes: dict[str, str] = field(default_factory=dict)
    urdf: str = ""  # the URDF file a robot file names (its masses give gravity torques), else ""
    base_link: str = ""
    tip_link: str = ""  # with urdf: the link the tool hangs from
    gravity: tuple = tuple(Fraction(repr(v)) for v in GRAVITY)  # world, m/s^2, exact numbers
    #: virtual targets standing for measured orientations (`model.pose_targets`): name -> (the
    #: target whose frame they sample, vertex 0..3); none in a robot file
    vertex_of: dict[str, tuple[str, int]] = field(default_factory=dict)
    pose_length: float = 0.0  # m: 1 rad of orientation error counts as this much position error
    #: the frames pose measurements give, where they are not parallel to the tool frame: target ->
    #: rotation vector (rad) of the measured frame in the tool frame; estimated by
    #: `fit.placement` from the measured orientations, none in a robot file
    target_frames: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    #: trees: the parent frame of frames 1..m, the branches and each target's branch (index); all
    #: empty on a serial chain (one branch: the tool after frame m)
    parents: tuple[int, ...] = ()
    branches: tuple[Branch, ...] = ()
    target_branch: dict[str, int] = field(default_factory=dict)
    #: the robot file's unit of angles (deg or rad): reports show revolute joints in it (prismatic in m)
    angle_unit: str = "rad"
    #: the controller the robot runs on, as the robot file names it (`CONTROLLERS`), else "": program
    #: filters refuse a program written for another controller
    controller: str = ""

    def parent(self, i: int) -> int:
        """The frame that frame i (1..m) hangs from."""
        return self.parents[i - 1] if self.parents else i - 1

    def tips(self) -> list[tuple[int, tuple[Elementary, ...]]]:
        """(tip frame, tool transform) per branch; one on a serial chain."""
        return [(b.tip, b.tool) for b in self.branches] or [(self.n_frames, self.tool)]

    def branch_of(self, target: str) -> int:
        """The branch whose tool frame holds `target` (a measured frame's vertices: its target's)."""
        if target in self.vertex_of:
            target = self.vertex_of[target][0]
        return self.target_branch.get(target, 0)

    def branch_index(self, branch: str | None) -> int:
        """The index of the named branch: 0 on a serial robot, whose `branch` must be None."""
        names = [b.name for b in self.branches]
        if not names:
            require(branch is None, f"branch={excerpt(branch)}: robot {self.name} is a serial chain with one tool; "
                                    f"leave branch out")
            return 0
        require(branch in names, f"branch={excerpt(branch)}: robot {self.name} has branches {', '.join(names)}; "
                                 f"name the one whose tool to place")
        return names.index(branch)

    def branch_targets(self, branch: str) -> list[str]:
        """The targets on the named branch's tool."""
        k = [b.name for b in self.branches].index(branch)
        return [t for t in self.target_names if self.branch_of(t) == k]

    def own_frames(self, branch: int) -> set[int]:
        """The frames on branch `branch`'s (index) path that no other branch's path shares (0, the base,
        only on a chain): the joints of these place its tool alone."""
        tips = [tip for tip, _ in self.tips()]
        shared = {f for k, tip in enumerate(tips) if k != branch for f in self.path(tip)}
        return set(self.path(tips[branch])) - shared

    def moved_joints(self, branch: int) -> list[str]:
        """The names of the joints whose readings compensation moves to place branch `branch`'s (index)
        tool: those that turn a frame on its path alone (symbolic.chain.tool_jacobian_function)."""
        drives = self.drives()
        readings = {k for i in self.own_frames(branch) - {0} for k, _ in drives[i - 1][0]}
        return [self.joint_names[k] for k in sorted(readings)]

    def task_rows(self, branch: int) -> int:
        """The rows of branch `branch`'s tool pose compensation settles for: 6, its position and
        orientation, when at least six joints of its own move it; 3 when fewer do, whose compensation
        places the whole pose where those joints can and otherwise the position alone (a five-joint arm
        cannot turn its tool to every orientation, and held to it, its correction would never converge)."""
        return 6 if len(self.moved_joints(branch)) >= 6 else 3

    def sensor_frame(self) -> int:
        """The frame the wrench sensor rides on: `wrench_frame`, or the tool's (the first branch's tip)."""
        return self.tips()[0][0] if self.wrench_frame == "tool" else self.wrench_frame

    def path(self, i: int) -> list[int]:
        """The frames from the base to frame i, both included, in order."""
        out = [i]
        while out[-1] > 0:
            out.append(self.parent(out[-1]))
        return out[::-1]

    def subtree(self, i: int) -> list[int]:
        """Frame i and every frame that hangs from it, ascending: what joint i carries."""
        return [f for f in range(i, self.n_frames + 1) if i in self.path(f)]

    @property
    def joints(self) -> tuple[Joint, ...]:
        """The joints with a reading: joint variable k is q<k+1>."""
        return tuple(j for j in self.chain if j.reads)

    @property
    def n(self) -> int:
        """Number of joint variables q1..qn."""
        return len(self.joints)

    @property
    def n_frames(self) -> int:
        """Number of moving frames m (the last frame's number); n plus the passive joints."""
        return len(self.chain)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def drives(self) -> list[tuple[tuple[tuple[int, object], ...], object]]:
        """Per frame 1..m: ((variable k 0-based, multiplier), ...), offset); its joint's value is the
        sum of multiplier * q[k] plus the offset (((own k, 1),), 0 for a joint that is its reading)."""
        index = {name: k for k, name in enumerate(self.joint_names)}
        out = []
        for j in self.chain:
            if j.coupling is None:
                out.append((((index[j.name], 1),), 0))
            else:
                out.append((tuple((index[name], m) for name, m in j.coupling.terms), j.coupling.offset))
        return out

    def driven(self, k: int) -> list[tuple[int, object]]:
        """The frames (1-based, ascending) whose joint variable k (0-based) moves, with multipliers
        (dv_i/dq_k): its own frame and those of the joints coupled to it."""
        return [(i, m) for i, (terms, _) in enumerate(self.drives(), start=1) for v, m in terms if v == k]

    def frame_of(self, k: int) -> int:
        """The frame (1-based) of the joint whose reading is q<k+1> (k 0-based)."""
        return [i for i, j in enumerate(self.chain, start=1) if j.reads][k]

    def zero_offset_error(self, i: int) -> tuple[int, float] | None:
        """(eps index, sign) of the generalized error that is the zero offset of frame i's joint (i
        from 1), or None when its axis is not along an axis of the adjacent frame or constant
        transforms sit on both sides of its motion.

        The error adjacent to the motion that turns about (revolute) or moves along (prismatic) its
        axis: for a URDF joint (no constant transform after the motion) that of frame i, right after
        it; for a DH joint (none before it) that of frame i-1, right before it: `er` of frame i-1 for
        a revolute joint i (`ez` for a prismatic one), or with a URDF axis along -x, -y or -z the
        matching error with its sign turned. Alone, that error equals the joint value off by its
        value: M_i(v) Rot(u, d) = M_i(v + d) and Rz(d) Rz(v) = Rz(v + d)."""
        joint = self.chain[i - 1]
        u = [float(a) for a in joint.axis]
        frame = i if not joint.post else i - 1 if not joint.pre else None
        k = max(range(3), key=lambda a: abs(u[a]))
        if frame is None or abs(abs(u[k]) - 1) > 1e-12:
            return None
        name = ("ex", "ey", "ez")[k] if joint.kind == "P" else ("ep", "es", "er")[k]
        return 6 * frame + ERROR_NAMES.index(name), math.copysign(1.0, u[k])

    def ratio_terms(self) -> dict[int, list[str]]:
        """The coupling ratios that are calibration parameters: eps index -> terms ["q<k>", ...].

        A declared coupling's joint value moves with reading k by its multiplier; an error d in that
        multiplier turns the joint by d q_k, which is term q_k on the joint's zero-offset error
        (exactly: Rz(d q_k) Rz(v) = Rz(v + d q_k)), its coefficient d times the error's sign. Its own
        reading's multiplier is the joint's scale, left out as for every uncoupled joint; a joint
        with no single zero-offset error carries none (`load_robot` warns)."""
        out: dict[int, list[str]] = {}
        for i, (j, (terms, _)) in enumerate(zip(self.chain, self.drives()), start=1):
            found = self.zero_offset_error(i) if j.coupling is not None and j.coupling.declared else None
            own = self.joint_names.index(j.name) if j.reads else None
            for k, _ in terms if found else ():
                if k != own:
                    out.setdefault(found[0], []).append(f"q{k + 1}")
        return out

    def sampling_box(self) -> tuple[list[float], list[float]]:
        """Per reading, the range generic and random poses are drawn from (m or rad): the limits within
        one turn about zero (a continuous joint: -pi..pi), or for limits wholly outside it (190..300
        deg) the limits, at most one turn from the lower."""
        lo, hi = [], []
        for j in self.joints:
            a, b = max(j.lower, -math.pi), min(j.upper, math.pi)
            if a >= b:
                a, b = j.lower, min(j.upper, j.lower + 2 * math.pi)
            lo.append(a)
            hi.append(b)
        return lo, hi

    @property
    def target_names(self) -> tuple[str, ...]:
        return tuple(self.targets)

    @property
    def n_errors(self) -> int:
        """Number of generalized errors, 6(m+1)."""
        return 6 * (self.n_frames + 1)

    def require_placed(self):
        """Refuse (one line) to build anything on targets that still wait for measured data."""
        name = self.estimated[0] if self.estimated else ""
        require(not self.estimated, f"{self.source}: target '{name}' is left to estimate, so this needs measured data "
                                    f"(identify, diagnose and calibrate place it from theirs); to plan before "
                                    f"measuring, write a rough guess instead, targets: {{{name}: [x, y, z]}} in the "
                                    f"tool frame (m; a rough guess serves to plan the poses)")

    def error_names(self) -> list[str]:
        """Names like '3.ey' in the order of the generalized error vector eps."""
        return [f"{i}.{e}" for i in range(self.n_frames + 1) for e in ERROR_NAMES]
