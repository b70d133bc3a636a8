"""Export a calibration into a controller: generated C with the coefficients as const data, a
URDF whose joint origins carry the constant errors, and a table of joint zero offsets and link
errors. Units: m and rad inside; the table and the effects reported in mm, mrad and mdeg.

Joint zero offsets. Joint i's zero offset is the generalized error adjacent to its motion that
turns about or moves along its axis (`Robot.zero_offset_error`).
Identification usually eliminates it (it acts like the joint and the next frame), and the next
frames' errors carry it; the table re-expresses the calibration with every zero offset kept,
each exchanged for the kept constant coefficient it merges into most (a rotation for a revolute
joint, a translation for a prismatic one, else the other kind), through the merge factors of the
redundancy analysis. Those are linear, so the re-expressed errors reproduce the calibration to
first order in the errors; `reexpressed_change_mm` measures the rest.
"""
from __future__ import annotations

import dataclasses
import itertools
import math
import warnings
from pathlib import Path

import numpy as np

from gecgen.model.kinematics import constant, error_transform, frames, target_positions
from gecgen.model.robot import ERROR_NAMES, WRENCH, Robot
from gecgen.model.validation import require
from gecgen.fit.calibration import Calibration, model_hash
from gecgen.runtime.compiled import OK, SINGULAR, STATUS_NAMES, CompiledModel, rendered
from gecgen.fit.redundancy import generic_design

#: the example program's compensation settings: `gecgen compensate`'s (Newton steps, residual m),
#: and how many random commands it tries when the middle of the training ranges is singular
EXAMPLE_MAX_ITER, EXAMPLE_TOL, EXAMPLE_TRIES = 50, 1e-11, 20
#: random poses in the training ranges over which the effect of a term the URDF cannot carry is
#: taken (with the corners of the ranges, when there are at most CORNERS_MAX)
EFFECT_SAMPLES, CORNERS_MAX = 2000, 4096
#: a merge factor below this is no link between a zero offset and a coefficient
FACTOR_TOL = 1e-9
MDEG_PER_RAD = 180e3 / math.pi


def _spans(calib: Calibration, where: str) -> np.ndarray:
    """The training span of every input (k, 2): q1..qn, fx..mz, the aux signals."""
    ranges = calib.report.get("training_ranges")
    names = [f"q{i + 1}" for i in range(calib.robot.n)] + list(WRENCH) + list(calib.model.aux)
    require(isinstance(ranges, dict) and all(n in ranges for n in names),
            f"{where}: training_ranges: the calibration does not record the span of every input (it was "
            f"written by an older gecgen); identify again")
    return np.array([ranges[n] for n in names], dtype=float)


def example_command(calib: Calibration, cm: CompiledModel, where: str) -> dict[str, list[float]]:
    """The example program's nominal command: the middle of each input's training span, or where
    compensation does not converge there (the middle of symmetric ranges can stretch an arm or line
    up two wrist axes: a singular pose), the first of EXAMPLE_TRIES uniform poses in the spans (seed
    0) where it does."""
    span = _spans(calib, where)
    rng = np.random.default_rng(0)
    X = np.vstack([span.mean(axis=1), rng.uniform(span[:, 0], span[:, 1], (EXAMPLE_TRIES, len(span)))])
    n = calib.robot.n
    _, status = cm.compensate(X[:, :n], X[:, n:n + 6], X[:, n + 6:], calib.c, EXAMPLE_MAX_ITER, EXAMPLE_TOL)
    ok = np.nonzero(status == OK)[0]
    if not len(ok):
        counts = np.bincount(status, minlength=len(STATUS_NAMES))
        why = ", ".join(f"{STATUS_NAMES[k].replace('_', ' ')} at {n}" for k, n in enumerate(counts) if n)
        hint = (": the training poses lie near a singular posture (a stretched elbow, two axes in line), where a "
                "correction would swing the joints; measure poses away from it too and identify again"
                if counts[SINGULAR] else "")
        raise RuntimeError(f"{where}: compensation converges inside the joint limits at none of {len(X)} commands in "
                           f"the training ranges ({why}); the calibration cannot be used to compensate{hint}")
    return {"q": X[ok[0], :n].tolist(), "w": X[ok[0], n:n + 6].tolist(), "aux": X[ok[0], n + 6:].tolist()}


def c_files(calib: Calibration, cm: CompiledModel, where: str) -> tuple[dict[str, str], dict[str, list[float]]]:
    """File name -> text: what `gecgen generate` writes for the calibration's robot and error model,
    NAME_calibration.h and NAME_example.c; and the example's command."""
    from gecgen.emit import render_calibration

    # the generated comments and manifest then name the calibration as the error model's source
    model = dataclasses.replace(calib.model, source=Path(where).name,
                                source_hash=model_hash(calib.robot, calib.model))
    files = rendered(calib.robot, model)
    command = example_command(calib, cm, where)
    reasons = {e["param"]: e["reason"] for e in calib.report.get("eliminated", [])}
    files.update(render_calibration(calib.robot, model, calib.c, calib.std, command, EXAMPLE_MAX_ITER, EXAMPLE_TOL,
                                    Path(where).name, reasons))
    return files, command


def compile_command(folder: str | Path, name: str) -> tuple[list[str], list[str]]:
    """(compile, run) argument lists for the example program in folder, from the current folder."""
    folder = Path(folder)
    exe = folder / f"{name}_example"
    run = f"./{exe}" if exe.parent == Path(".") else str(exe)
    return (["cc", "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe), str(folder / f"{name}_example.c"),
             str(folder / f"{name}.c"), "-lm"], [run])


def constant_errors(calib: Calibration, c: np.ndarray | None = None) -> np.ndarray:
    """The constant part of the generalized errors (ne,): the "1" coefficients of c (default the
    calibration's)."""
    c = calib.c if c is None else c
    eps = np.zeros(calib.robot.n_errors)
    for k, coef in enumerate(calib.model.coefficients):
        if coef.term.text == "1":
            eps[coef.error] += c[k]
    return eps


def _unit(error: int) -> str:
    return "mm" if error % 6 < 3 else "mrad"


def rigid_part(calib: Calibration) -> Calibration:
    """The calibration as a URDF carries it: the coefficients of the term "1" only, the others zero."""
    keep = np.array([coef.term.text == "1" for coef in calib.model.coefficients])
    return dataclasses.replace(calib, c=np.where(keep, calib.c, 0.0))


def not_carried(calib: Calibration, cm: CompiledModel, where: str) -> list[dict]:
    """The coefficients of terms other than "1" that are not zero, each with the largest value its
    term times it reaches over the training ranges (mm or mrad, the unit of its error), largest
    first: the corners of the ranges and EFFECT_SAMPLES uniform poses in them."""
    coefs = calib.model.coefficients
    ks = [k for k, coef in enumerate(coefs) if coef.term.text != "1" and calib.c[k] != 0]
    if not ks:
        return []
    span = _spans(calib, where)
    rng = np.random.default_rng(0)
    X = rng.uniform(span[:, 0], span[:, 1], (EFFECT_SAMPLES, len(span)))
    moving = np.nonzero(span[:, 1] > span[:, 0])[0]
    if 2 ** len(moving) <= CORNERS_MAX:
        corners = np.tile(span[:, 0], (2 ** len(moving), 1))
        for row, pick in zip(corners, itertools.product((0, 1), repeat=len(moving))):
            row[moving] = span[moving, pick]
        X = np.vstack([X, corners])
    n = calib.robot.n
    f = cm.basis(X[:, :n], X[:, n:n + 6], X[:, n + 6:])
    terms = [t.text for t in calib.model.unique_terms()]
    names = calib.model.coefficient_names(calib.robot)
    effect = [np.abs(calib.c[k] * f[:, terms.index(coefs[k].term.text)]).max() for k in ks]
    out = [{"coefficient": names[k], "max_effect": float(1e3 * e), "unit": _unit(coefs[k].error)}
           for k, e in zip(ks, effect)]
    return sorted(out, key=lambda e: -e["max_effect"])


def tool_points(robot: Robot) -> list[dict[str, np.ndarray]]:
    """Per branch (one on a chain), its measured points: name -> their frame in the last frame of the
    branch (4x4: the tool transform, then the point; the tool's axes)."""
    tools = [b.tool for b in robot.branches] or [robot.tool]
    out = [{} for _ in tools]
    for name, xyz in robot.targets.items():
        T = constant(tools[robot.branch_of(name)])
        T[:3, 3] += T[:3, :3] @ np.asarray(xyz, float)
        out[robot.branch_of(name)][name] = T
    return out


#: the translation errors, reported in mm (the rotations in mrad)
ERRORS_MM = ("ex", "ey", "ez")


def carried_cameras(calib: Calibration) -> list[dict[str, np.ndarray]] | None:
    """For a calibration from a camera on the tool (image points of a board): the camera's frame as
    the fit placed it, `camera_<name>` -> 4x4 in the last frame (the tool transform, then the camera:
    its z along the optical axis, its origin the optical centre), on the first branch, the one
    `tool_points` gives; None for any other calibration."""
    report = calib.report
    if report.get("measurement") != "pixels" or "board" not in report:
        return None
    out = {}
    for name, pose in report["cameras"].items():
        R, t = np.asarray(pose["rotation"], float), np.asarray(pose["translation"], float)
        camera = np.eye(4)  # the fit's pose maps the tool frame into the camera's: X_cam = R X_tool + t
        camera[:3, :3], camera[:3, 3] = R.T, -R.T @ t
        out[f"camera_{name}"] = constant(calib.robot.tips()[0][1]) @ camera
    return [out]


def tool_offset_carried(calib: Calibration) -> dict | None:
    """When a translation of a branch's last frame (the measured tool's offset from the flange) is
    eliminated as indistinguishable from other errors, and the kept coefficients it merges into hold
    values: {"errors": the eliminated ones, "carried_by": {kept coefficient: value, mm or mrad}};
    those values may be the tool's offset rather than the robot's. None otherwise."""
    robot = calib.robot
    last = {b.tip for b in robot.branches} or {robot.n_frames}
    eliminated = [e for e in calib.report.get("eliminated", []) if e["reason"] == "structural"
                  and e["param"].endswith(":1") and int(e["param"].split(".")[0]) in last
                  and e["param"].split(".")[1].split(":")[0] in ERRORS_MM]
    names = calib.model.coefficient_names(robot)
    by = {m["param"]: 1e3 * float(calib.c[names.index(m["param"])]) for e in eliminated for m in e["merged_into"]
          if int(m["param"].split(".")[0]) not in last and abs(m["factor"]) > FACTOR_TOL}
    by = {k: v for k, v in by.items() if v != 0.0}
    return {"errors": [e["param"] for e in eliminated], "carried_by": by} if by else None


#: the tool offset's re-expression: poses uniform in the training ranges (seed 0), Gauss-Newton
#: steps at most, and the singular value (relative to the largest) below which a direction of the
#: tool points' Jacobian is one the points cannot see at all (finite differences leave ~1e-9)
REEXPRESS_POSES, REEXPRESS_STEPS, REEXPRESS_NULL = 200, 30, 1e-6
#: a step below this (m, rad) is done: the finite-difference Jacobian's rounding turns the directions
#: the points cannot see by about 1e-9, which moves the smallest-norm point by ~1e-11
REEXPRESS_STEP = 1e-10
#: how far the re-expressed tool points may sit from the calibration's before it is not used (m)
REEXPRESS_TOL = 1e-9


def _error_index(name: str) -> int:
    """The generalized error index of a coefficient name "frame.error:term"."""
    frame, rest = name.split(".", 1)
    return 6 * int(frame) + ERROR_NAMES.index(rest.split(":")[0])


def _origin_moved(E: np.ndarray, O: np.ndarray) -> tuple[float, float]:
    """How far (mm, mrad) a joint's origin O (4x4) moves when the error transform E before it is folded in."""
    T = E @ O
    angle = math.acos(min(1.0, max(-1.0, (np.trace(O[:3, :3].T @ T[:3, :3]) - 1) / 2)))
    return float(1e3 * np.linalg.norm(T[:3, 3] - O[:3, 3])), float(1e3 * angle)


def reexpress_tool_offset(calib: Calibration, carried: dict, where: str) -> tuple[np.ndarray, dict]:
    """The constant errors (ne,) the URDF carries when the fit carries the measured tool's offset
    in frames before the tool (`tool_offset_carried`), and what changed.

    The fit's frames and the tool's own translations it eliminated (U) are exchanged where the tool
    points cannot tell them apart: the six errors of every frame that carries the offset and U are
    varied so that the tool points stay exactly where the calibration's constant errors put them
    (REEXPRESS_POSES poses in the training ranges), and among those choices the one whose frames'
    errors are smallest is taken (translations in m, rotations times the tool points' distance from
    the frame, so both are what they move the points by). That keeps only the exact symmetries: a
    translation along the last joint's axis commutes with the joint into the tool, and with one
    point on that axis any turn about the point does; what the points see even slightly stays with
    the fit. Solved by Gauss-Newton with the smallest-norm step in the directions the points cannot
    see, never to first order only; the result is used only when the points stay within
    REEXPRESS_TOL, else the fit's errors are kept and the returned dict says so."""
    robot = calib.robot
    eps0 = constant_errors(calib)
    frames_moved = sorted({int(k.split(".")[0]) for k in carried["carried_by"]})
    U = [_error_index(u) for u in carried["errors"]]
    free = [6 * f + e for f in frames_moved for e in range(6)] + U
    span = _spans(calib, where)[:robot.n]
    q = np.random.default_rng(0).uniform(span[:, 0], span[:, 1], (REEXPRESS_POSES, robot.n))
    goal = target_positions(robot, q, eps0)
    W0 = frames(robot, q[:1])
    reach = {f: float(np.sqrt(np.mean(np.sum((goal[0] - W0[f][0, :3, 3]) ** 2, axis=-1)))) for f in frames_moved}
    weight = np.array([1.0 if e < 3 else reach[f] for f in frames_moved for e in range(6)] + [0.0] * len(U))

    def points(x: np.ndarray) -> np.ndarray:
        eps = eps0.copy()
        eps[free] = x
        return (target_positions(robot, q, eps) - goal).ravel()

    x = eps0[free].copy()
    for _ in range(REEXPRESS_STEPS):
        r = points(x)
        J = np.column_stack([(points(x + 1e-7 * d) - points(x - 1e-7 * d)) / 2e-7 for d in np.eye(len(x))])
        _, s, Vt = np.linalg.svd(J, full_matrices=True)
        seen = int(np.sum(s > REEXPRESS_NULL * s[0]))
        N = Vt[seen:].T  # the directions the points cannot see
        step = -Vt[:seen].T @ ((Vt[:seen] @ J.T @ r) / s[:seen] ** 2)
        step += N @ np.linalg.lstsq(weight[:, None] * N, -weight * (x + step), rcond=None)[0]
        x += step
        if np.abs(step).max() < REEXPRESS_STEP:
            break
    off = float(np.abs(points(x)).max())
    eps = eps0.copy()
    if off <= REEXPRESS_TOL:
        eps[free] = x
    names = robot.error_names()
    moved = []
    for tip, _ in robot.tips():
        before = robot.parent(tip)
        if before in frames_moved:
            joint = robot.chain[tip - 1]
            fit, out = (_origin_moved(error_transform(e[6 * before:6 * before + 6]), constant(joint.pre))
                        for e in (eps0, eps))
            moved.append({"joint": joint.name, "fit_mm": fit[0], "fit_mrad": fit[1], "exported_mm": out[0],
                          "exported_mrad": out[1]})
    return eps, {"applied": off <= REEXPRESS_TOL, "max_point_change_mm": float(1e3 * off), "poses": REEXPRESS_POSES,
                 "tool": {names[u]: float(1e3 * (eps[u] - eps0[u])) for u in U},
                 "frames": {names[k]: float(1e3 * eps[k]) for k in free[:-len(U)] if eps[k] != 0.0},
                 "last_joint_origin": moved}


def urdf_copy(calib: Calibration, cm: CompiledModel, where: str) -> tuple[str, dict]:
    """The robot's URDF with the calibration's constant errors folded into its joint origins
    (`model.urdf.folded_copy`), and what the command reports about it. The tracker registration
    is the measurement frame, not the robot: it is not applied. Where the fit carries the measured
    tool's offset in the frames before it, the URDF gives it to the tool (`reexpress_tool_offset`)."""
    from gecgen.model.urdf import folded_copy

    robot = calib.robot
    require(robot.urdf, f"{where}: robot '{robot.name}' ({robot.source}) is a DH robot file with no URDF to copy, "
                        f"and six errors per frame do not fit DH's four parameters; use --c for the controller "
                        f"or --table for the errors per frame")
    declared = [j.name for j in robot.chain if j.coupling and j.coupling.declared]
    if declared:
        warnings.warn(f"the URDF keeps its own joints: the robot file's couplings of {', '.join(declared)} are not in "
                      f"it (a URDF cannot state a joint from several others); the controller applies them")
    eps = constant_errors(calib)
    carried = tool_offset_carried(calib)
    if carried:
        eps, carried["reexpressed"] = reexpress_tool_offset(calib, carried, where)
        warnings.warn(_carried_warning(carried))
    E = [error_transform(eps[6 * i:6 * i + 6]) for i in range(robot.n_frames + 1)]
    cameras = carried_cameras(calib)
    # the images measured the camera on the tool, not the robot file's targets: the camera is the tool
    measured, frame = (("the camera's link camera_<name> (z its optical axis, at its optical centre)",
                        "the board's pose in the world") if cameras else
                       ("the measured tool points' links", "the tracker registration"))
    note = (f"calibrated by gecgen export from {Path(where).name}: the constant generalized errors are folded "
            f"into the joint origins, the last frame's into {measured}; {frame} is not applied")
    tip_links = [b.tip_link for b in robot.branches] or [robot.tip_link]
    text, tips, tool_links, changed = folded_copy(robot.urdf, robot.base_link, tip_links, E, note,
                                                  cameras or tool_points(robot))
    left = not_carried(calib, cm, where)
    reg = calib.registration.to_dict()
    branch_tips = {"tip_links": {b.name: t for b, t in zip(robot.branches, tips)}} if robot.branches else {}
    return text, {"tip_link": tips[0], **branch_tips, "tool_links": tool_links, "changed_joints": changed,
                  "not_carried": left, "tool_offset_carried": carried,
                  "registration_applied": False, "registration": {k: reg[k] for k in ("angle_deg", "distance_mm")}}


def _carried_warning(carried: dict) -> str:
    """The one line that says how the fit carries the tool's offset and what the URDF does with it."""
    fit = ", ".join(f"{k} ({v:.3g} {_unit(_error_index(k))})" for k, v in carried["carried_by"].items())
    head = (f"the data cannot tell the measured tool's offset along {', '.join(carried['errors'])} from errors of the "
            f"robot, and the calibration carries it in {fit}")
    r = carried["reexpressed"]
    if not r["applied"]:
        return (f"{head}: the links before the tool move with it (the tool point is right; re-expressing it in the "
                f"tool left the points {r['max_point_change_mm']:.3g} mm off); measure a second point on the tool to "
                f"keep them apart (urdf.tool_offset_carried)")
    tool = ", ".join(f"{k} {v:.3g} mm" for k, v in r["tool"].items())
    joints = "; ".join(f"{m['joint']}'s origin is {m['exported_mm']:.3g} mm, {m['exported_mrad']:.3g} mrad from "
                       f"nominal (the fit's frames: {m['fit_mm']:.3g} mm, {m['fit_mrad']:.3g} mrad)"
                       for m in r["last_joint_origin"])
    return (f"{head}; the URDF gives the tool's link what the points cannot tell apart ({tool}): {joints}, the tool "
            f"points within {r['max_point_change_mm']:.2g} mm of the calibration's at {r['poses']} poses in the "
            f"training ranges; which part is the tool's is a choice the data cannot check: measure a second point on "
            f"the tool to tell them apart (urdf.tool_offset_carried)")


# -- the table ---------------------------------------------------------------------------------------
def _through_couplings(robot: Robot, readings: list[int]) -> list[dict[int, float]] | None:
    """Per reading, the frames whose joint zero offsets give its offset, with factors: dq = D^-1 dv,
    D[a, b] = dv_(frame of reading a) / dq_b. None when every reading is its own joint's value (D = I).
    A reading coupled into other joints (the FANUC J2 also turns joint 3) moves them all: its offset
    is not its own frame's error alone."""
    D = np.zeros((robot.n, robot.n))
    for a, i in enumerate(readings):
        for b, m in robot.drives()[i - 1][0]:
            D[a, b] = float(m)
    if np.array_equal(D, np.eye(robot.n)):
        return None
    require(abs(np.linalg.det(D)) > 1e-12, f"{robot.source}: couplings: the readings cannot be told from the coupled "
                                           f"joints' values (their map is singular); fix the couplings")
    Dinv = np.linalg.inv(D)
    return [{readings[b]: float(Dinv[a, b]) for b in range(robot.n) if abs(Dinv[a, b]) > 1e-15}
            for a in range(robot.n)]


def table(calib: Calibration, cm: CompiledModel) -> dict:
    """Joint zero offsets (mdeg, mm for a prismatic joint) and the other constant errors per frame
    (mm, mrad), with standard deviations, in the calibration re-expressed with every zero offset
    kept (see the module's docstring)."""
    robot, model = calib.robot, calib.model
    names = model.coefficient_names(robot)
    coefs = model.coefficients
    index = {(c.error, c.term.text): k for k, c in enumerate(coefs)}
    kept = list(calib.kept)
    pos = {k: a for a, k in enumerate(kept)}
    eliminated = {e["param"]: e for e in calib.report.get("eliminated", [])}

    zero, why = {}, {}  # by frame: the frames of joints with a reading (a passive joint's offset is its frame's error)
    for i in map(robot.frame_of, range(robot.n)):
        found = robot.zero_offset_error(i)
        k = index.get((found[0], "1")) if found else None
        if k is None:
            why[i] = ("its axis is not along an axis of the frame next to its motion" if not found
                      else f"the error model has no constant term for {robot.error_names()[found[0]]}")
        else:
            zero[i] = (k, found[1])
    # exchange each eliminated zero offset for a kept constant coefficient (Gaussian elimination on
    # the merge factors, pivots chosen as described in the module's docstring)
    reserved = {k for k, _ in zero.values()}
    swap, rows, pivots, reduced = [], [], [], []
    for i, (k, _) in list(zero.items()):
        if k in pos:
            continue
        e = eliminated.get(names[k], {})
        partners = [names.index(m["param"]) for m in e.get("merged_into", [])]
        if e.get("reason") != "structural" or not all(j in pos for j in partners):
            del zero[i]
            why[i] = (f"{names[k]} is held at zero ({e.get('reason', 'eliminated')}: {e.get('detail', '')}), and the "
                      f"data leaves what it merges into undetermined")
            continue
        row = np.zeros(len(kept))
        row[[pos[j] for j in partners]] = [m["factor"] for m in e["merged_into"]]
        r = row.copy()
        for p, rr in zip(pivots, reduced):
            r -= r[p] / rr[p] * rr
        candidates = [a for a in range(len(kept)) if coefs[kept[a]].term.text == "1" and kept[a] not in reserved
                      and a not in pivots and abs(r[a]) > FACTOR_TOL]
        same_kind = [a for a in candidates if (coefs[kept[a]].error % 6 >= 3) == (robot.chain[i - 1].kind == "R")]
        if not candidates:
            del zero[i]
            why[i] = (f"{names[k]} is eliminated ({e['detail']}) and merges into no other constant coefficient: "
                      f"the measured points cannot tell it")
            continue
        p = max(same_kind or candidates, key=lambda a: abs(r[a]))
        swap.append((i, k))
        rows.append(row)
        pivots.append(p)
        reduced.append(r)
    reserved = {k for k, _ in zero.values()}

    def reexpress(cK: np.ndarray) -> np.ndarray:
        c = np.zeros(len(coefs))
        c[kept] = cK
        if swap:
            F = np.array(rows)
            z = np.linalg.solve(F[:, pivots].T, cK[pivots])
            c[kept] = cK - F.T @ z
            c[[kept[p] for p in pivots]] = 0.0
            c[[k for _, k in swap]] = z
        return c

    A = np.column_stack([reexpress(e) for e in np.eye(len(kept))]) if kept else np.zeros((len(coefs), 0))
    c2 = A @ calib.c[kept]
    std2 = np.sqrt(np.maximum(np.diag(A @ calib.cov @ A.T), 0.0))
    determined = set(kept) - {kept[p] for p in pivots} | {k for _, k in swap}  # those with a std
    q, w, aux = generic_design(robot, cm.dims.naux, 100, np.random.default_rng(0))
    change = np.linalg.norm(cm.model_targets(q, w, aux, c2) - cm.model_targets(q, w, aux, calib.c), axis=-1).max()

    exchanged = dict(zip([i for i, _ in swap], [names[kept[p]] for p in pivots]))
    readings = [robot.frame_of(k) for k in range(robot.n)]
    through = _through_couplings(robot, readings)
    cov2 = A @ calib.cov @ A.T if through else None
    offsets = []
    for a, (i, joint) in enumerate(zip(readings, robot.joints)):
        scale = MDEG_PER_RAD if joint.kind == "R" else 1e3
        entry = {"joint": joint.name, "unit": "mdeg" if joint.kind == "R" else "mm"}
        needed = through[a] if through else {i: 1.0}
        if all(b in zero for b in needed):
            k, sign = zero[i] if i in zero else (None, 1.0)
            if through:  # the reading's offset from the chain joints' offsets it sets: dq = D^-1 dv
                g = np.zeros(len(coefs))
                for b, f in needed.items():
                    g[zero[b][0]] += f * zero[b][1]
                value, std = g @ c2, np.sqrt(max(g @ cov2 @ g, 0.0))
                entry["through_couplings"] = {names[zero[b][0]]: f * zero[b][1] for b, f in needed.items()}
            else:
                value, std = sign * c2[k], std2[k]
            entry |= {"coefficient": names[k] if k is not None else None, "value": float(scale * value),
                      "std": float(scale * std), "exchanged_for": exchanged.get(i)}
        else:
            missing = next(b for b in needed if b not in zero)
            reason = why[missing] if missing == i else (f"its reading also sets joint {robot.chain[missing - 1].name} "
                                                        f"(couplings), whose zero offset is not known: {why[missing]}")
            entry |= {"coefficient": None, "value": None, "std": None, "why": reason}
        offsets.append(entry)
    frames = []
    for f in range(robot.n_frames + 1):
        values, stds = {}, {}
        for e, err in enumerate(ERROR_NAMES):
            key = f"{err}_{_unit(e)}"
            k = index.get((6 * f + e, "1"))
            if k is None or k in reserved:
                values[key] = stds[key] = None  # not in the model, or a zero offset listed above
            else:
                values[key] = float(1e3 * c2[k])
                stds[key] = float(1e3 * std2[k]) if k in determined else None
        frames.append({"frame": f, **values, "std": stds})
    return {"zero_offsets": offsets, "frames": frames, "reexpressed_change_mm": float(1e3 * change)}

