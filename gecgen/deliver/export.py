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

from gecgen.model.kinematics import constant, error_transform
from gecgen.model.robot import ERROR_NAMES, WRENCH, Robot
from gecgen.model.validation import require
from gecgen.fit.calibration import Calibration, model_hash
from gecgen.runtime.compiled import OK, CompiledModel, rendered
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
        raise RuntimeError(f"{where}: compensation converges inside the joint limits at none of {len(X)} commands in "
                           f"the training ranges; the calibration cannot be used to compensate")
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


def urdf_copy(calib: Calibration, cm: CompiledModel, where: str) -> tuple[str, dict]:
    """The robot's URDF with the calibration's constant errors folded into its joint origins
    (`model.urdf.folded_copy`), and what the command reports about it. The tracker registration
    is the measurement frame, not the robot: it is not applied."""
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
    E = [error_transform(eps[6 * i:6 * i + 6]) for i in range(robot.n_frames + 1)]
    note = (f"calibrated by gecgen export from {Path(where).name}: the constant generalized errors are folded "
            f"into the joint origins, the last frame's into the measured tool points' links; the tracker "
            f"registration is not applied")
    tip_links = [b.tip_link for b in robot.branches] or [robot.tip_link]
    text, tips, tool_links, changed = folded_copy(robot.urdf, robot.base_link, tip_links, E, note, tool_points(robot))
    left = not_carried(calib, cm, where)
    carried = tool_offset_carried(calib)
    if carried:
        warnings.warn(f"the data cannot tell the measured tool's offset along {', '.join(carried['errors'])} from "
                      f"errors of the robot, and the calibration carries it in "
                      + ", ".join(f"{k} ({v:.3g} {'mm' if k.split('.')[1][:2] in ERRORS_MM else 'mrad'})"
                                  for k, v in carried["carried_by"].items())
                      + ": the links before the tool move with it (the tool point is right); measure a second point "
                        "on the tool to keep them apart (urdf.tool_offset_carried)")
    reg = calib.registration.to_dict()
    branch_tips = {"tip_links": {b.name: t for b, t in zip(robot.branches, tips)}} if robot.branches else {}
    return text, {"tip_link": tips[0], **branch_tips, "tool_links": tool_links, "changed_joints": changed,
                  "not_carried": left, "tool_offset_carried": carried,
                  "registration_applied": False, "registration": {k: reg[k] for k in ("angle_deg", "distance_mm")}}


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

