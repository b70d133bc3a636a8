"""What each command's report shows, as sections of paragraphs, bullets, tables and figures.

Built from the objects a command already holds (Fit, Calibration, Diagnosis, Measurements): the
residuals are the modelled points at coefficients already fitted, never a new fit.
"""
from __future__ import annotations

import numpy as np

from gecgen.model.measurements import Measurements
from gecgen.model.robot import WRENCH, Robot
from gecgen.report.blocks import (Bullets, DataSet, Drawing, Figure, Report, Residuals, Section, Table, frame_label,
                                  joint_label, joint_scale, joint_unit, joint_values, term_unit, variable)
from gecgen.fit.identify import filled, fit_frames, summary, to_world
from gecgen.runtime.processes import mapped
from gecgen.fit.significance import rms_interval


def residuals(stage: str, cm, data: Measurements, y: np.ndarray, c: np.ndarray | None) -> Residuals:
    """Residuals of compiled model cm at coefficients c (None: nominal) against measured world points y (R, 3) m."""
    rows = data.rows
    p = cm.model_targets(data.q, data.w, data.aux_columns(cm.model.aux),
                         np.zeros(cm.dims.nc) if c is None else c)[data.pose, data.target]
    d, rot = rows.signed(filled(data, y, p), p)  # a socket's rows against their own mean
    return Residuals(stage, data.pose[rows.first], 1e3 * d, 1e3 * rot if rows.oriented.any() else None)


def drawn(report: Report) -> Report:
    """The report with every Drawing drawn (`runtime.processes`: side by side, each exactly as alone)."""
    sections = [Section(section.title, list(section.blocks)) for section in report.sections]
    at = [(section, k) for section in sections for k, block in enumerate(section.blocks) if isinstance(block, Drawing)]
    with mapped([(section.blocks[k].fn, section.blocks[k].args) for section, k in at]) as figures:
        for (section, k), figure in zip(at, figures):
            section.blocks[k] = figure
    return Report(report.title, report.intro, sections)


# -- sections every report shares ---------------------------------------------------------------

def headline(sets: list[DataSet], robot: Robot | None = None) -> Section:
    """Per stage, RMS and max point error on each data set (and orientation error when measured); on
    a tree, also per branch."""
    header = ["model"]
    for ds in sets:
        s = ds.stages[0].summary()
        header += [f"{ds.name} RMS (mm)", f"{ds.name} max (mm)"]
        if ds.name != "training":  # a held-out score says how well new poses will do: with its uncertainty
            header += [f"{ds.name} RMS, 95 % interval by pose (mm)"]
        if "rot_rms_mrad" in s:
            header += [f"{ds.name} orientation RMS (mrad)", f"{ds.name} orientation max (mrad)"]
    rows = []
    for k, st in enumerate(sets[0].stages):
        row = [st.stage]
        for ds in sets:
            stage = ds.stages[k]
            s = stage.summary()
            row += [f"{s['rms_mm']:.3g}", f"{s['max_mm']:.3g}"]
            if ds.name != "training":
                lo, hi = rms_interval(np.linalg.norm(stage.position_mm, axis=1), stage.pose)
                row += [f"{lo:.3g} to {hi:.3g}"]
            if "rot_rms_mrad" in s:
                row += [f"{s['rot_rms_mrad']:.3g}", f"{s['rot_max_mrad']:.3g}"]
        rows.append(tuple(row))
    counts = "; ".join(f"{ds.name}: {ds.data.n_poses} poses, {len(ds.stages[0].pose)} measured rows "
                       f"(`{ds.data.source or 'in memory'}`)" for ds in sets)
    what = "Point error: the distance between measured and modelled point."
    if any(ds.data.relative is not None for ds in sets):  # sockets and planes: no point was measured
        what = ("A row with a measured position: the distance between measured and modelled point; a socket's row: "
                "its target's distance from the socket's fitted place (how consistently the seatings agree); a "
                "plane's row: its distance from the fitted plane.")
    blocks = [Table(tuple(header), rows), f"{what} {counts}."]
    return Section("Summary", blocks + ([branch_table(robot, sets)] if robot is not None and robot.branches else []))


def _rms_max(position_mm: np.ndarray) -> str:
    e = np.linalg.norm(position_mm, axis=1)
    return f"{np.sqrt(np.mean(e ** 2)):.3g} / {e.max():.3g}" if len(e) else "-"


#: load cases are told apart by the measured force's size in steps of this (N: about 1 kg)
LOAD_STEP_N = 10.0
#: more distinct forces than this are a varying load, not load cases: no per-case errors
MAX_LOAD_CASES = 8


def measured_section(robot: Robot, sets: list[DataSet]) -> Section:
    """What was measured, per data set: poses and rows per target, orientations, tracker stations,
    load cases, the instrument noise when repeated poses give it, and how much of each joint's
    range the poses cover; then the point errors per target and per load case of every stage.
    robot: the robot the data is on (a measured frame as its vertex targets, `cm.robot`)."""
    from gecgen.fit.significance import noise_floor
    from gecgen.report import plots

    noise = noise_floor(sets[0].data, robot=robot)
    blocks = []
    for ds in sets:
        data, rows = ds.data, ds.data.rows
        target = np.array([robot.vertex_of.get(n, (n,))[0] for n in robot.target_names])[data.target[rows.first]]
        names, count = np.unique(target, return_counts=True)
        # a load case is a payload: the force's size in LOAD_STEP_N bins (its direction turns with the sensor)
        force = np.linalg.norm(data.w[data.pose[rows.first], :3], axis=1)
        loads, case = np.unique(np.round(force / LOAD_STEP_N), return_inverse=True)
        relative = data.relative
        absolute = np.ones(len(data.target), bool) if relative is None else ~relative.rows
        stations = np.unique(data.station[absolute])
        facts = [f"{data.n_poses} poses, {len(rows.first)} measured rows: "
                 + ", ".join(f"target `{n}` {c}" for n, c in zip(names, count)),
                 f"{int(rows.oriented.sum())} rows measure the orientation too" if rows.oriented.any() else
                 "positions only (no orientation measured)",
                 *([f"{len(stations)} tracker stationing{'s' if len(stations) > 1 else ''}"] if absolute.any() else []),
                 *([_fixtures_fact(relative)] if relative is not None else []),
                 *([f"{len(loads)} load case{'s' if len(loads) > 1 else ''} (the measured force's size, rounded to the nearest {LOAD_STEP_N:g} N)"]
                   if np.any(data.w[:, :3]) else ["no force measured"])]
        if noise is not None and ds is sets[0]:
            facts.append(f"instrument noise from repeated poses: {noise['noise_mm']:.3g} mm per coordinate")
        blocks += [f"**{ds.name.capitalize()} data** (`{data.source or 'in memory'}`):", Bullets(facts)]
        coverage = []
        for k, joint in enumerate(robot.joints):
            v = joint_values(robot, data, k)
            unit, scale = joint_unit(robot, k), joint_scale(robot, k)
            share = np.ptp(data.q[:, k]) / max(joint.upper - joint.lower, 1e-12)
            coverage.append((joint_label(robot, k), f"{v.min():.4g} to {v.max():.4g} {unit}",
                             f"{scale * joint.lower:.4g} to {scale * joint.upper:.4g} {unit}", f"{100 * share:.0f} %"))
        blocks.append(Table(("joint", "measured", "limits", "share of the range"), coverage))
        by = [(f"target `{n}`", *(_rms_max(st.position_mm[target == n]) for st in ds.stages)) for n in names]
        if relative is not None:  # each socket's and plane's rows: a ball that did not seat shows in one
            group = relative.group[rows.first]
            by += [(f"{kind} `{n}`", *(_rms_max(st.position_mm[group == g]) for st in ds.stages))
                   for g, (n, kind) in enumerate(zip(relative.names, relative.kinds)) if (group == g).any()]
        if 1 < len(loads) <= MAX_LOAD_CASES:
            by += [(f"force about {LOAD_STEP_N * loads[c]:g} N", *(_rms_max(st.position_mm[case == c])
                                                                   for st in ds.stages)) for c in range(len(loads))]
        blocks.append(Table(("rows", *(f"{st.stage}: RMS / max (mm)" for st in ds.stages)), by))
        blocks.append(Drawing(plots.per_pose, (robot, ds)))
    return Section("What was measured", blocks)


def _fixtures_fact(relative) -> str:
    """What the relative rows of a data set hold, in words."""
    n = relative.summary()
    return (f"{n['rows']} rows without a measured position: {n['points']} point(s) (sockets: a row's error is its "
            f"target's distance from the point's fitted position), {n['planes']} plane(s) (its distance from the "
            f"fitted plane), {n['distances']} known distance(s) between points")


def branch_figures(robot: Robot, sets: list[DataSet]) -> dict | None:
    """Point errors per branch of a tree: {data set name: {branch: {stage: {rms_mm, max_mm}}}} over
    each branch's measured points, the branches a set does not measure left out; {} on a chain, None
    for measured frames (rows are frames, not points)."""
    if not robot.branches:
        return {}
    if any(len(ds.stages[0].pose) != len(ds.data.target) for ds in sets):
        return None
    out = {}
    for ds in sets:
        side = np.array([robot.branch_of(robot.target_names[t]) for t in ds.data.target])
        out[ds.name] = {b.name: {st.stage: summary(1e-3 * np.linalg.norm(st.position_mm[side == k], axis=1))
                                 for st in ds.stages}
                        for k, b in enumerate(robot.branches) if (side == k).any()}
    return out


def branch_table(robot: Robot, sets: list[DataSet]) -> Table | str:
    """RMS point error per branch of a tree, per data set and stage (a hand's accuracy is its own)."""
    figures = branch_figures(robot, sets)
    if figures is None:
        return "Per branch: not shown for measured frames (rows are frames, not points)."
    header = ["model", *(f"{ds.name} {b.name} RMS (mm)" for ds in sets for b in robot.branches)]
    rows = [tuple([st.stage, *(f"{figures[ds.name][b.name][st.stage]['rms_mm']:.3g}" if b.name in figures[ds.name]
                               else "-" for ds in sets for b in robot.branches)])
            for st in sets[0].stages]
    return Table(tuple(header), rows)


def residual_sections(robot: Robot, sets: list[DataSet], compare: int = 2) -> list[Section]:
    """Error distributions of every stage, and signed residuals per axis against each joint of
    the last `compare` stages (each in its own figure and scale), per data set."""
    from gecgen.report import plots

    dist = Section("Distribution of point errors",
                   ["Histogram and cumulative distribution of the point errors of each model (log scale: the "
                    "uncalibrated errors are often a hundred times the calibrated ones), and of the orientation "
                    "errors where the data measures frames."])
    joints = Section("Residuals against each joint",
                     ["Signed residual (measured minus modelled) along the world x, y, z axes"
                      + (" and orientation error about them" if any(s.rotation_mrad is not None for ds in sets
                                                                    for s in ds.stages) else "")
                      + ", against each joint (one point per measured row). What a model lacks shows here as a "
                        "pattern: a sine against a joint is a periodic error of it (a gear, a bearing), a slope "
                        "a scale or compliance error. The figures of one data set share no scale between "
                        "models: compare shapes, and read the size on the axes."])
    for ds in sets:
        dist.blocks.append(Drawing(plots.error_distribution, (robot, ds)))
        if any(s.rotation_mrad is not None for s in ds.stages):
            dist.blocks.append(Drawing(plots.error_distribution, (robot, ds, True)))
        joints.blocks += [Drawing(plots.residuals_per_joint, (robot, ds, st)) for st in ds.stages[-compare:]]
    return [dist, joints]


def glossary(robot: Robot) -> Section:
    """What ex..ep mean and which frame is which, with the robot's joint names."""
    frames = ["frame 0: the base (after `base`, before the first joint)"]
    for i, j in enumerate(robot.chain, start=1):
        mimic = f", {j.name} = {j.coupling.text(robot)}" if j.coupling else ""
        tool = "; it also carries the tool" if i == robot.n_frames else ""
        frames.append(f"frame {i}: after joint {i}, `{j.name}` ({'revolute' if j.kind == 'R' else 'prismatic'}"
                      f"{mimic}){tool}")
    return Section("Glossary", [
        "Each frame i carries six generalized errors, applied right after its nominal transform: "
        "`E_i = Trans(ex, ey, ez) RotY(es) RotZ(er) RotX(ep)`.",
        Bullets(["`ex`, `ey`, `ez`: translations along the frame's x, y, z (reported in mm)",
                 "`es`, `er`, `ep`: rotations about the frame's y, z, x, in that order (reported in mrad)",
                 "a coefficient `3.ey:q2` is the error ey of frame 3 per unit of its term q2 (rad or m); "
                 "its value is in mm or mrad per unit of the term, and with the term `1` a constant"]),
        "Frames:", Bullets(frames)])


def coefficient_section(robot: Robot, calib) -> list[Section]:
    """The coefficients (mm, mrad) with std, and the eliminated ones with what they merge into."""
    names = calib.model.coefficient_names(robot)
    kept = set(calib.kept)
    eliminated = {e["param"]: e for e in calib.report.get("eliminated", [])}
    ratio_loads = calib.report.get("ratio_loads") or []
    loaded = {r["coefficient"] for r in ratio_loads}
    rows = []
    for j in sorted(kept):
        coef = calib.model.coefficients[j]
        frame, err = robot.error_names()[coef.error].split(".")
        unit = "mm" if err in ("ex", "ey", "ez") else "mrad"
        term = coef.term.label
        unit = unit if term == "1" else f"{unit} per {term_unit(robot, term)}"
        unit += " (a coupling ratio that depends on the loads: see below)" if names[j] in loaded else ""
        rows.append((frame_label(robot, int(frame)), err, f"`{term}`", f"{1e3 * calib.c[j]:.3g}",
                     f"{1e3 * calib.std[j]:.2g}", f"{abs(calib.c[j]) / calib.std[j]:.1f}", unit))
    out = [Section("Coefficients", [
        f"The {len(kept)} identified coefficients of {len(names)} (the others are eliminated: see below); std is "
        "the standard deviation from the fit's covariance and t = |value| / std. A term `1` is a constant error (the "
        "frame's geometry); any other term's coefficient is per unit of the term (rad or m for joints, N or N m for "
        "the wrench).",
        Table(("frame", "error", "term", "value", "std", "t", "unit"), rows)])]
    if ratio_loads:
        out.append(Section("Coupling ratios and loads", [
            "A coupling ratio's coefficient turns the coupled joint in proportion to a reading, and over the measured "
            "poses so may the load the joint carries. Each ratio below takes a value with the loads on its error "
            "modelled and another without them, further apart than the data's noise allows, so its value is not a "
            "gear-ratio error by itself: without the loads it absorbs them (model the load: calibrate's elastic model, "
            "or diagnose); with them it is as good as the load terms beside it. Values in mrad per rad of the reading.",
            Table(("coefficient", "with the loads", "without", "std", "apart (std)", "loads", "loads in the model"),
                  [(f"`{r['coefficient']}`", f"{1e3 * r['with_loads']:.3g}", f"{1e3 * r['without_loads']:.3g}",
                    f"{1e3 * r['std']:.2g}", f"{r['shift_std']:.1f}", ", ".join(f"`{n}`" for n in r["loads"]),
                    "yes" if r["in_model"] else "no") for r in ratio_loads])]))
    if eliminated:
        # what a coefficient merges into, else why it is held (a camera's pose it merges with, a weak
        # direction, an insignificant value), as the JSON's detail says
        rows = [(f"`{p}`", e["reason"], e["detail"] if e["reason"] in ("insignificant", "held") else
                 ", ".join(f"`{m['param']}` x {m['factor']:.3g}" for m in e["merged_into"])
                 or e.get("detail") or "nothing (not seen by the data)") for p, e in eliminated.items()]
        out.append(Section("Eliminated parameters", [
            "Held at zero. Structural, unexcited and weak ones: the data cannot tell them from others, and their "
            "effect is carried by the kept coefficients they merge into (the coefficient gains the factor times the "
            "eliminated value). Insignificant ones: identifiable, but the data did not determine them (|value| / std "
            "below 2 in backward elimination); the others were refitted without them.",
            Table(("parameter", "reason", "merged into, or why"), rows)]))
    return out


def extrapolation_section(robot: Robot, calib, counts: dict[str, int] | None, n_poses: int | None) -> Section:
    """The inputs' training ranges; with counts ({input: poses}, `calibration.extrapolation`) the
    poses of the reported data outside them."""
    ranges = calib.report.get("training_ranges") or {}
    label = {f"q{k + 1}": joint_label(robot, k) for k in range(robot.n)}
    unit = {**{n: "N" for n in WRENCH[:3]}, **{n: "N m" for n in WRENCH[3:]}}
    rows, constant = [], []
    for name, (lo, hi) in ranges.items():
        outside = (counts or {}).get(name, 0)
        if lo == hi and not outside:
            constant.append(f"{name} = {lo:g}")
            continue
        scale = joint_scale(robot, int(name[1:]) - 1) if name in label else 1.0
        rows.append((label.get(name, f"{name} ({unit[name]})" if name in unit else name), f"{scale * lo:.4g}",
                     f"{scale * hi:.4g}", str(outside) if counts is not None else "-"))
    blocks = ["Outside the span each input was fitted over the model extrapolates (a polynomial term can grow "
              "without bound); the calibration is not validated there."
              + (f" Of these {n_poses} poses, the table counts per input those outside." if counts is not None else "")]
    if counts is not None:
        blocks.append(f"**{max(counts.values())} or more of {n_poses} poses extrapolate.**" if counts
                      else f"All {n_poses} poses lie inside the training ranges.")
    blocks.append(Table(("input", "training min", "training max", "poses outside"), rows))
    if constant:
        blocks.append(f"Constant over the training data (any other value extrapolates): {', '.join(constant)}.")
    return Section("Extrapolation", blocks)


def effect_sections(robot: Robot, effects, cm, fit, y: np.ndarray, after: Residuals,
                    data: Measurements) -> list[Section]:
    """One section per effect diagnose added to compiled model cm (the final fit, training data
    with measured world points y; `after` its residuals): its coefficients as finally fitted, and
    against each of its variables the residual without it (its coefficients zeroed, all else held)
    and with it."""
    from gecgen.report import plots

    names = cm.model.coefficient_names(robot)
    q, w, aux = data.q, data.w, data.aux_columns(cm.model.aux)
    c = fit.c
    out = []
    for k, eff in enumerate(effects, 1):
        idx = [names.index(co["name"]) for co in eff.coefficients]
        zeroed = c.copy()
        zeroed[idx] = 0.0
        without = residuals("without the effect", cm, data, y, zeroed)
        error = cm.model.coefficients[idx[0]].error
        size = 1e3 * (cm.eps(q, w, aux, c) - cm.eps(q, w, aux, zeroed))[:, error]
        unit = "mm" if robot.error_names()[error].split(".")[1] in ("ex", "ey", "ez") else "mrad"
        p = f"p = {eff.p_value:.2g}" if eff.p_value > 1e-300 else "p < 1e-300"
        blocks = [f"Cross-validated gain {eff.gain_mm:.3g} mm when it was added, {p}.",
                  Table(("coefficient", f"value as finally fitted ({unit} per unit of the term)", "std", "t"),
                        [(f"`{names[j]}`", f"{1e3 * c[j]:.3g}", "eliminated" if np.isnan(fit.std[j]) else
                          f"{1e3 * fit.std[j]:.2g}", "-" if np.isnan(fit.std[j]) else
                          f"{abs(c[j]) / fit.std[j]:.1f}") for j in idx])]
        if eff.alternatives:
            blocks += ["Indistinguishable on this data (the same fitted effect): which error carries it is not "
                       "decided by the data, so the frame named above is one choice among these"
                       + (" (similarity 1.000: exactly the same effect)"
                          if max(a["similarity"] for a in eff.alternatives) > 0.9995 else "") + ":",
                       Bullets([f"{alt['error']}: {', '.join(alt['terms'])} (similarity {alt['similarity']:.3f})"
                                for alt in eff.alternatives])]
        still = [v for v in eff.variables if np.ptp(variable(data, v)) == 0]
        blocks += [Drawing(plots.effect, (robot, eff, size, v, without, after, data)) for v in eff.variables
                   if v not in still]
        if still:
            blocks.append(f"Not plotted against {', '.join(still)}: constant over the training data.")
        out.append(Section(f"Effect {k}: {eff.error} in {', '.join(eff.variables)} ({eff.family})", blocks))
    return out


# -- one report per command ----------------------------------------------------------------------

def verdict_sections(assessment, warnings: list[str] | None) -> list[Section]:
    """The verdict, what limits the result and the next step (`report.verdict.Assessment`), and the
    warnings the command printed, as printed: what a reader needs first."""
    out = []
    if assessment is not None:
        blocks = [f"**Verdict: {assessment.verdict}.** {assessment.statement}"]
        if assessment.limits:
            blocks += ["What limits it:", Bullets(assessment.limits)]
        blocks.append(f"**Next step:** {assessment.next_step}")
        out.append(Section("Verdict and next step", blocks))
    if warnings is not None:
        out.append(Section("Warnings", ["What the command warned on the terminal, word for word:", Bullets(warnings)]
                           if warnings else ["The command printed no warning."]))
    return out



def _nominal_world(cm, data: Measurements, loss: str, registration_mode: str) -> np.ndarray:
    """The measured points in the frame registered onto the nominal model, as `Fit.before` scores them."""
    return to_world(fit_frames(cm, data, None, loss, registration_mode), data)


def identify(robot: Robot, cm, data: Measurements, fit, calib, calib_path: str, registration_mode: str = "auto",
             assessment=None, warnings: list[str] | None = None) -> Report:
    y0 = _nominal_world(cm, data, fit.loss, registration_mode)
    train = DataSet("training", data, [residuals("uncalibrated", cm, data, y0, None),
                                       residuals("calibrated", cm, data, fit.to_world(data), fit.c)])
    return Report(f"gecgen identify: {robot.name}",
                  [f"Calibration `{calib_path}` fitted on `{data.source}` ({data.n_poses} poses). "
                   "Training data only: score it on new data with `gecgen evaluate --report`."],
                  [*verdict_sections(assessment, warnings), headline([train], robot),
                   measured_section(cm.robot, [train]), *residual_sections(robot, [train]),
                   *coefficient_section(robot, calib),
                   glossary(robot), extrapolation_section(robot, calib, None, None)])


#: the image is cut into COVERAGE x COVERAGE cells to say how much of it the points cover
COVERAGE = 4
#: rows of the pixel report's tables of images and points, the worst first
WORST = 10


def image_coverage(data, cameras: dict) -> dict[str, tuple[int, int]]:
    """Per camera of the pixel data: (cells of its image cut COVERAGE x COVERAGE that hold a point, cells)."""
    out = {}
    for k, n in enumerate(data.cameras):
        cam = cameras[n]
        cells = {(int(COVERAGE * u / cam.width), int(COVERAGE * v / cam.height)) for u, v in data.uv[data.camera == k]}
        out[n] = (len(cells), COVERAGE * COVERAGE)
    return out


def pixels(robot: Robot, data, fit, calib, calib_path: str, cameras: dict, warnings: list[str] | None = None,
           assessment=None, command: str = "identify", lead: tuple[Section, ...] = (), held_out: bool = False) -> Report:
    """The report of a calibration from image points (`fit.camera.PixelFit` on `model.pixels.Pixels`):
    reprojection residuals in px and in mm at the points, per camera, image and point; how much of each
    image the points cover; the coefficients with what the images left undetermined; first the verdict
    and next step (`verdict.pixels_next_step`) and the warnings the command printed. command: the
    command whose report it is; lead: its own sections, after the verdict (`pixel_choice`,
    `pixel_diagnosis`); held_out: whether those score held-out images (the rest is the training images')."""
    px, mm = fit.residuals[:, 0], fit.residuals[:, 1]
    names = data.cameras

    def rms(x):
        return f"{np.sqrt(np.mean(x ** 2)):.3g}"

    cams = [(n, fit.before["cameras"][n], fit.train["cameras"][n]) for n in names if n in fit.train["cameras"]]
    per_camera = Table(("camera", "points", "before rms px", "after rms px", "after max px", "after rms mm at target",
                        "distance m"),
                       [(f"`{n}`", str(int(np.sum(data.camera == k))), f"{b['rms_px']:.3g}", f"{a['rms_px']:.3g}",
                         f"{a['max_px']:.3g}", f"{a['rms_mm_at_target']:.3g}", f"{a['distance_m']:.3g}")
                        for k, (n, b, a) in enumerate(cams)])
    # on a tree, each branch over the points it carries (fixed cameras see the targets of every branch)
    branch_of = np.array([robot.branch_of(n) for n in data.points])[data.point] if robot.branches else None
    per_branch = () if branch_of is None else (Table(
        ("branch", "points", "before rms px", "after rms px", "after max px", "after rms mm at target", "distance m"),
        [(f"`{b.name}`", str(int(np.sum(branch_of == k))), f"{fit.before['branches'][b.name]['rms_px']:.3g}",
          f"{a['rms_px']:.3g}", f"{a['max_px']:.3g}", f"{a['rms_mm_at_target']:.3g}", f"{a['distance_m']:.3g}")
         for k, b in enumerate(robot.branches) if (a := fit.train["branches"].get(b.name)) is not None]),)
    images = []
    for p in range(data.n_poses):
        for k, n in enumerate(names):
            rows = (data.pose == p) & (data.camera == k)
            if rows.any():
                images.append((float(np.sqrt(np.mean(px[rows] ** 2))), int(data.pose_ids[p]), n, int(rows.sum()),
                               float(px[rows].max()), rms(mm[rows])))
    images.sort(key=lambda r: -r[0])
    points = []
    for j, n in enumerate(data.points):
        rows = data.point == j
        if rows.any():
            points.append((float(np.sqrt(np.mean(px[rows] ** 2))), n, int(rows.sum()), float(px[rows].max()),
                           rms(mm[rows])))
    points.sort(key=lambda r: -r[0])
    coverage = [f"`{n}`: {cells} of {total} cells of its {cameras[n].width} x {cameras[n].height} image "
                f"({COVERAGE} x {COVERAGE}) hold a point"
                for n, (cells, total) in image_coverage(data, cameras).items()]
    outliers = [f"row {o.row}: image of pose {o.pose}, camera `{o.camera}`, point `{o.point}`: {o.residual_px:.3g} px "
                f"(weight {o.weight:.2g})" for o in fit.outliers]
    sections = [
        *verdict_sections(assessment, warnings), *lead,
        Section("Residuals in pixels", [
            f"Reprojection residual of every image point, observed minus projected (a camera measures pixels, not "
            f"millimetres): before, the nominal model at the cameras' first poses; after, the calibration. The mm "
            f"at target are what a residual means across the camera's ray at the point's depth (px times depth over "
            f"the focal length); the median working distance is {fit.train['distance_m']:.3g} m. Over all "
            f"{len(px)} points: {fit.before['rms_px']:.3g} -> {fit.train['rms_px']:.3g} px rms "
            f"({fit.train['rms_mm_at_target']:.3g} mm at target), largest {fit.train['max_px']:.3g} px.",
            per_camera, *per_branch]),
        Section("Images with the largest residual", [
            f"The {min(WORST, len(images))} of {len(images)} images (one pose, one camera) with the largest RMS "
            f"residual after the calibration.",
            Table(("pose", "camera", "points", "rms px", "max px", "rms mm at target"),
                  [(str(p), f"`{n}`", str(c), f"{r:.3g}", f"{m:.3g}", t) for r, p, n, c, m, t in images[:WORST]])]),
        Section("Points with the largest residual", [
            f"The {min(WORST, len(points))} of {len(points)} points with the largest RMS residual over the images "
            f"that see them.",
            Table(("point", "images", "rms px", "max px", "rms mm at target"),
                  [(f"`{n}`", str(c), f"{r:.3g}", f"{m:.3g}", t) for r, n, c, m, t in points[:WORST]])]),
        Section("Coverage of the images", [
            "Where the points fall in each camera's image: the residuals speak for the lens only where points fall.",
            Bullets(coverage)]),
        Section("Outliers", [Bullets(outliers) if outliers else "No image point was flagged as an outlier."]),
        *camera_pose_section(calib.report.get("camera_uncertainty")),
        *coefficient_section(robot, calib), glossary(robot)]
    return Report(f"gecgen {command}: {robot.name} from image points",
                  [f"{'The diagnosed model' if command == 'diagnose' else 'Calibration'} `{calib_path}` fitted on "
                   f"`{data.source}` ({data.n_poses} poses, {len(names)} "
                   f"camera{'s' if len(names) > 1 else ''}, {len(px)} image points). "
                   + ("The held-out images are scored in the first sections; the residuals, images and points below "
                      "are the training images'." if held_out else "Training data only.")], sections)


def camera_pose_section(uncertainty: dict | None) -> tuple[Section, ...]:
    """How well the images fix each camera's pose (the calibration's `camera_uncertainty`), when stated."""
    if uncertainty is None:
        return ()
    rows = [(f"`{name}`", "the tool frame" if v["relative_to"] == "tool" else f"camera `{v['relative_to']}`",
             f"{v['translation_mm']:.3g}", ", ".join(f"{x:.3g}" for x in v["axes_mm"]), f"{v['rotation_mrad']:.3g}",
             ", ".join(f"{x:.3g}" for x in v["axes_mrad"])) for name, v in uncertainty["cameras"].items()]
    return (Section("How well the images place the cameras", [
        "One standard deviation of each camera's fitted pose, from the fit's covariance taken image by image: a "
        "camera on the tool in the tool frame (the camera-to-flange transform as the calibration carries it), a "
        "fixed camera against the first (where the robot's base sits against the cameras is what the images leave "
        "least determined). The length is the square root of the covariance's trace: the distance and angle the "
        "fitted pose is expected to be off.",
        Table(("camera", "relative to", "position mm", "x, y, z mm", "rotation mrad", "about x, y, z mrad"), rows)
        if rows else "One fixed camera: nothing to place it against."]),)


def pixel_choice(result: dict) -> tuple[Section, ...]:
    """calibrate --cameras's own section: every candidate's cross-validated error over the training images
    (mm at the target) and the one chosen; the validation images before and after, when given."""
    rows = [(f"`{r['model']}`", "not fitted" if r["cv_rms_mm"] is None else f"{r['cv_rms_mm']:.4g}",
             str(r.get("n_params_delivered", r["n_params"]))) for r in result["candidates"]]
    held = [f"Validation images ({result['validation']}): {result['val_before']['rms_px']:.3g} px rms with the nominal "
            f"model, {result['val']['rms_px']:.3g} px ({result['val']['rms_mm_at_target']:.3g} mm at target) "
            f"calibrated, seen from the cameras as the fit placed them."] if "val" in result else []
    return (Section("The model chosen", [
        f"Each candidate was fitted on four fifths of the training images and scored on the fifth it did not see "
        f"(5 folds over poses, RMS image-point error in mm at the target); the lowest wins, a tie within 1 % going "
        f"to the smaller model. Chosen: `{result['model']}`.",
        Table(("model", "cross-validated rms mm at target", "coefficients"), rows), *held]),)


def pixel_diagnosis(result: dict) -> tuple[Section, ...]:
    """diagnose --cameras's own section: the effects added, and the held-out images before and after."""
    before, after = result["before"], result["after"]
    added = [f"`{e['error']}` <- {', '.join(f'`{t}`' for t in e['terms'])} ({e['family']}; cross-validated gain "
             f"{e['gain_mm']:.3g} mm at target)" for e in result["effects"]]
    return (Section("What diagnose added", [
        f"Held out ({result['validation']}): {before['val_rms_px']:.3g} px rms ({before['val_rms_mm']:.3g} mm at "
        f"target) with the declared model, {after['val_rms_px']:.3g} px ({after['val_rms_mm']:.3g} mm) with the "
        f"diagnosed one. {result['verdict']}",
        Bullets(added) if added else "Nothing in the candidate dictionary passed the statistics: the model is "
                                     "unchanged."]),)


def evaluate(calib, cm, data: Measurements, y_before: np.ndarray, y: np.ndarray, outside: dict[str, int],
             calib_path: str, assessment=None, warnings: list[str] | None = None) -> Report:
    robot = calib.robot
    val = DataSet("validation", data, [residuals("uncalibrated", cm, data, y_before, None),
                                       residuals("calibrated", cm, data, y, calib.c)])
    return Report(f"gecgen evaluate: {robot.name}",
                  [f"Calibration `{calib_path}` scored on `{data.source}` ({data.n_poses} poses), data it was not "
                   "fitted on."],
                  [*verdict_sections(assessment, warnings), headline([val], robot), measured_section(cm.robot, [val]),
                   *residual_sections(robot, [val]),
                   *coefficient_section(robot, calib),
                   glossary(robot), extrapolation_section(robot, calib, outside, data.n_poses)])


def _scored(stage: str, cm, data: Measurements, c, frames, register: bool) -> Residuals:
    """Residuals of one stage on validation data, in the fit's tracker `frames`, or (`register`)
    in frames fitted on the data with the stage's coefficients c held."""
    return residuals(stage, cm, data, to_world(fit_frames(cm, data, c) if register else frames, data), c)


def diagnosed_sets(diag, data: Measurements, val: Measurements | None, register_val: bool,
                    registration_mode: str) -> list[DataSet]:
    """Uncalibrated, declared model and diagnosed model on the training and validation data, each
    scored as diagnose scored it."""
    init, final = diag.initial, diag.final
    sets = [DataSet("training", data, [
        residuals("uncalibrated", init.cm, data, _nominal_world(init.cm, data, init.fit.loss, registration_mode), None),
        residuals("calibrated (declared model)", init.cm, data, init.fit.to_world(data), init.fit.c),
        residuals("diagnosed", final.cm, data, final.fit.to_world(data), final.fit.c)])]
    if val is not None:
        sets.append(DataSet("validation", val, [
            _scored(label, rnd.cm, val, c, rnd.fit.registrations, register_val)
            for label, rnd, c in (("uncalibrated", init, None), ("calibrated (declared model)", init, init.fit.c),
                                  ("diagnosed", final, final.fit.c))]))
    return sets


def diagnose(diag, data: Measurements, val: Measurements | None, errors_out: str, register_val: bool = False,
             registration_mode: str = "auto", assessment=None, warnings: list[str] | None = None) -> Report:
    from gecgen.loop.diagnose import verdict
    from gecgen.fit.calibration import from_fit

    robot = diag.robot
    sets = diagnosed_sets(diag, data, val, register_val, registration_mode)
    calib = from_fit(robot, diag.final.model, diag.final.fit, diag.ratio_loads)
    found = [f"{diag.candidates_tested} candidate effects screened in {diag.rounds} rounds; an effect is added only "
             "when it passes a Bonferroni-corrected chi-square test and lowers the 5-fold cross-validated RMS on the "
             "training data.", verdict(diag.remaining)]
    if not diag.effects:
        found.insert(1, "diagnose added nothing to the declared model.")
    if diag.remaining.get("dropped"):
        found.append("Dropped at the end, no coefficient of theirs determined by the data once the others were in "
                     "(backward elimination, |value| / std below 2): " + "; ".join(
                         f"{d['error']}: {', '.join(d['terms'])} (t {d['t']:.2f})" for d in diag.remaining["dropped"])
                     + ".")
    if diag.remaining["outliers"]:
        found.append(f"{diag.remaining['outliers']} training rows were outliers of the robust fit (down-weighted, "
                     "listed by `gecgen identify`); they neither chose nor hid an effect.")
    rounds = Table(("round", "training RMS (mm)", "CV RMS (mm)", "candidates", "accepted"),
                   [(str(h["round"]), f"{h['train_rms_mm']:.3g}", f"{h['cv_rms_mm']:.3g}", str(h["candidates"]),
                     h["accepted"] or "-") for h in diag.history])
    return Report(f"gecgen diagnose: {robot.name}",
                  [f"Training data `{data.source}` ({data.n_poses} poses); validation "
                   f"{'`' + val.source + '`' if val is not None and val.source else 'held out'}, never used to choose "
                   f"terms. New error model: `{errors_out}`."],
                  [*verdict_sections(assessment, warnings), headline(sets, robot),
                   measured_section(diag.final.cm.robot, sets),
                   Section("What diagnose found", found),
                   *effect_sections(robot, diag.effects, diag.final.cm, diag.final.fit,
                                    diag.final.fit.to_world(data), sets[0].stages[2], data),
                   *residual_sections(robot, sets), *coefficient_section(robot, calib), glossary(robot),
                   extrapolation_section(robot, calib, None, None), Section("Rounds", [rounds])])


def calibrate(result: dict, choice, calib, data: Measurements, val: Measurements | None,
              register_val: bool = False, assessment=None) -> Report:
    """register_val: val was measured from another tracker stationing; each stage is scored in the
    frame fitted on it (its coefficients held), as calibrate's JSON scores it. The warnings shown are
    the result's (`warnings`), the extrapolation counts its `val_extrapolation`."""
    robot = calib.robot
    fit, cm = choice.fit, choice.cm
    diag = choice.diagnosis
    if diag is not None:
        sets = diagnosed_sets(diag, data, val, register_val, "auto")
    else:
        sets = [DataSet("training", data, [
            residuals("uncalibrated", cm, data, _nominal_world(cm, data, fit.loss, "auto"), None),
            residuals("calibrated", cm, data, fit.to_world(data), fit.c)])]
        if val is not None:
            sets.append(DataSet("validation", val, [_scored(label, cm, val, c, calib.frames, register_val)
                                                    for label, c in (("uncalibrated", None), ("calibrated", fit.c))]))
    rows = []
    for c in result["candidates"]:
        cv = f"{c['cv_rms_mm']:.3g}" if c["cv_rms_mm"] is not None else f"not fitted: {c['refused']}"
        size = str(c["n_params"])
        if c["diagnose"]:
            delivered = c.get("n_params_delivered")
            size = (f"{c['n_params']} + what diagnose adds" if delivered is None else
                    f"{delivered} ({c['n_params']} + {delivered - c['n_params']} diagnose added on all the training "
                    f"poses)")
        rows.append((c["model"] + (" (chosen)" if c["model"] == result["model"] else ""), size, cv))
    choose = Section("Model choice", [
        "The model is chosen on the training data alone: each candidate is fitted whole (diagnose's choices "
        "included) on four fifths of the training poses and scored on the fifth left out, in turn; the lowest "
        "cross-validated RMS wins, a tie within 1% going to the smaller model, counted as delivered (for diagnose, "
        "what it builds on all the training poses).",
        Table(("model", "coefficients", "training CV RMS (mm)"), rows),
        f"Chosen: **{result['model']}**, {result['n_identifiable']} identifiable of {result['n_params']} "
        f"coefficients, {result['n_carried']} of them determined by the data and carried (see \"Eliminated "
        "parameters\")." + (" On the whole training data diagnose added no effect: the model is the geometric one, "
                            "and its cross-validated score is that of the whole pipeline, whose folds may have added "
                            "effects." if result["model"] == "diagnosed" and not result["effects"] else "")])
    if result["outliers"]:
        choose.blocks.append(f"{len(result['outliers'])} training points were outliers of the robust fit "
                             "(down-weighted; `calibration.json` lists them).")
    if result["placement"]:
        choose.blocks.append("Targets placed from the training data before the fit: " + ", ".join(
            f"{n} {[round(v, 4) for v in xyz]} m" for n, xyz in result["placement"]["targets_m"].items()))
    effects = effect_sections(robot, diag.effects, cm, fit, fit.to_world(data), sets[0].stages[-1],
                              data) if diag is not None else []
    files = Section("Files", ["`calibration.json` (for `gecgen evaluate` and `gecgen compensate`), `errors.yaml` (the "
                              "chosen error model), `generated/` (its C and CasADi code, `NAME_calibration.h` with the "
                              "coefficients in the code's order, `NAME_example.c`: `gecgen export` says how to build "
                              "it)."])
    return Report(f"gecgen calibrate: {robot.name}",
                  [f"Training data `{result['train_data']}` ({data.n_poses} poses)"
                   + (f"; validation {result['validation']}, scored after the choice." if val is not None else ".")],
                  [*verdict_sections(assessment, result.get("warnings")), headline(sets, robot),
                   measured_section(cm.robot, sets), choose, *effects, *residual_sections(robot, sets),
                   *coefficient_section(robot, calib), glossary(robot),
                   extrapolation_section(robot, calib, result.get("val_extrapolation") if val is not None else None,
                                         val.n_poses if val is not None else None),
                   files])


def _iso_run(title: str, run: dict) -> Section:
    """One measured run of the ISO 9283 pose test: per target and point, and the distance P2 to P4."""
    orient = any(v.get("AP_a") is not None for t in run["points"].values() for v in t.values())
    keys = ["n", "AP_p", "AP_x", "AP_y", "AP_z", "RP_l"] + (["AP_a", "AP_b", "AP_c", "RP_a", "RP_b", "RP_c"]
                                                           if orient else [])
    rows = [(target, point, *(str(v[k]) if k == "n" else "-" if v[k] is None else f"{v[k]:.3g}" for k in keys))
            for target, points in run["points"].items() for point, v in points.items()]
    blocks = [f"Measurements `{run['measured']}`. Lengths in mm, angles in mrad; repeatabilities are the "
              f"half-width 3 S of the standard.",
              Table(("target", "point", *keys), rows),
              f"Worst over the points: pose accuracy AP_p {run['worst']['AP_p']:.3g} mm, pose repeatability RP_l "
              f"{run['worst']['RP_l']:.3g} mm."]
    if run["distance"]:
        blocks.append(Table(("target", "between", "cycles", "D_c (mm)", "D_bar (mm)", "AD_p (mm)", "RD_p (mm)"),
                            [(t, d["between"], str(d["n"]), f"{d['D_c']:.4g}", f"{d['D_bar']:.4g}",
                              f"{d['AD_p']:.3g}", f"{d['RD_p']:.3g}") for t, d in run["distance"].items()]))
    return Section(title, blocks)


def iso9283(result: dict, assessment=None, warnings: list[str] | None = None) -> Report:
    """The ISO 9283 pose test's report from `gecgen iso9283 --measured`'s result; first the verdict
    and next step (`verdict.iso9283_next_step`) and the warnings the command printed."""
    sections = [_iso_run("Before compensation" if "after" in result else "The test", result)]
    if "after" in result:
        sections.append(_iso_run("After compensation", result["after"]))
        sections.insert(0, Section("Summary", [Table(
            ("", "AP_p worst (mm)", "RP_l worst (mm)"),
            [(stage, f"{run['worst']['AP_p']:.3g}", f"{run['worst']['RP_l']:.3g}")
             for stage, run in (("before", result), ("after", result["after"]))])]))
    return Report(f"gecgen iso9283: {result['robot']}",
                  [f"ISO 9283 pose test of plan `{result['plan']}`, scored against the pose the nominal model gives "
                   f"each target at the plan's joints (what the robot was commanded to reach); measured in "
                   f"{result['frame']}."], [*verdict_sections(assessment, warnings), *sections])


def accuracy(result: dict, figure: Figure, assessment=None, warnings: list[str] | None = None) -> Report:
    """The accuracy statement over a volume from `gecgen accuracy`'s result and its map; first the
    verdict and next step (`verdict.accuracy_next_step`) and the warnings the command printed."""
    tol = result["tolerance_mm"]
    rows = [("bound on the worst compensated error", f"{result['bound_mm']:.3g} mm at {result['confidence']:.0%}"),
            ("from the coefficients' uncertainty alone", f"{result['parametric_bound_mm']:.3g} mm (its low "
                                                         f"quantile {result['lower_mm']:.3g} mm)"),
            ("unmodelled error, RMS per coordinate", f"{result['unmodelled_rms_mm']:.3g} mm, read as a "
                                                     f"{result['unmodelled_as']}"),
            ("residual it was read from, per coordinate", f"{result['residual_sigma_mm']:.3g} mm"),
            ("stated noise per coordinate", "not stated" if result["noise_mm"] is None else
             f"{result['noise_mm']:.3g} mm"),
            ("tolerance", "none given" if tol is None else f"{tol:.3g} mm")]
    m = result["measured"]
    if m is not None:
        rows.append(("measured at held-out poses inside the volume, without a model",
                     f"{m['share']:.0%} of the volume within {m['error_mm']:.3g} mm at {m['achieved_confidence']:.1%} "
                     f"({m['n']} poses)" if m["rank"] is not None else
                     f"{m['n']} poses inside the volume, {m['needed']} needed for {m['share']:.0%} at "
                     f"{m['confidence']:.0%}"))
    rows.append(("verdict", result["verdict"]))
    worst = result["worst_at"]
    at = ", ".join(f"{k} {v:.4g} {worst['joint_units'][k]}" for k, v in worst["joints"].items())
    where = (f"tool point {', '.join(f'{v:.3g}' for v in worst['tool_point_m'])} m" if "tool_point_m" in worst
             else f"target {worst['target']}")
    source = "held out from the fit" if result["held_out"] else "the data the calibration was fitted to"
    return Report(f"gecgen accuracy: {result['robot']}",
                  [f"The worst compensated error over the volume `{result['volume']}` ({result['samples']} samples, "
                   f"{result['draws']} Monte Carlo draws), its unmodelled part read from `{result['residual_from']}` "
                   f"({source})." + (f" From images: {result['meaning']}." if "meaning" in result else "")],
                  [*verdict_sections(assessment, warnings), Section("Statement", [Table(("", "value"), rows)]),
                   Section("Why, and what it assumes", [Bullets(result["reasons"]) if result["reasons"] else
                                                        "Nothing keeps it from being signed."]),
                   Section("Where it is worst", [f"Joints {at}; payload {worst['payload_kg']:.3g} kg; {where}. "
                                                 f"{worst['explanation']}.",
                                                 figure])])
