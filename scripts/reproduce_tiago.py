"""Calibrate the real TIAGo from motion capture and write docs/real-data-tiago.md.

    python scripts/reproduce_tiago.py                   # the data: tests/data/tiago-mocap
    python scripts/reproduce_tiago.py --calibrate-only  # only the `gecgen calibrate` section

Every number comes from the `gecgen` commands printed in the document; the validation file is
only ever passed to `gecgen evaluate` and, for reporting, to `--val` of diagnose (which chooses
nothing on it).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import warnings

import numpy as np

from gecgen.loop.diagnose import diagnose
from gecgen.model import load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.measurements import Measurements, read_measurements
from gecgen.runtime.compiled import CompiledModel
from gecgen.fit.identify import RANK_TOL_GRID, RIDGE_GRID, choose, identify, position_errors

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "tiago-mocap"
OUT = ROOT / "out" / "tiago"
ROBOT = "robots/tiago.yaml"
FIGAROH = {"base": (3.37, 4.87, 9), "offsets": (2.88, 4.23, 14), "full": (1.68, 3.22, 30)}
FIGAROH["elastic"] = FIGAROH["full"]  # figaroh has no elastic model: its full geometric one is the reference
#: identify options per variant
VARIANTS = {"plain": (), "ridge": ("--ridge", "auto"), "rank_tol": ("--rank-tol", "auto")}
MODELS = {"base": "robots/tiago.base.errors.yaml", "offsets": "robots/tiago.offsets.errors.yaml",
          "full": "robots/tiago.errors.yaml", "elastic": "robots/tiago.elastic.errors.yaml"}
#: the variants fitted per model: the reduced models plainly, the larger ones also with CV-chosen priors
FITS = {"base": ("plain",), "offsets": ("plain",), "full": ("plain", "ridge", "rank_tol"), "elastic": ("plain", "ridge")}
NAMES = {"base": "base registration + marker point", "offsets": "+ joint offsets",
         "full": "full geometric (6 per frame)", "elastic": "full geometric + gravity compliance"}
#: the arm joints whose gravity torque changes with the posture (arm_1 turns about the vertical)
LOADED = ",".join(f"arm_{k}_joint" for k in range(2, 8))
commands: list[str] = []


def gecgen(*args) -> dict:
    commands.append("gecgen " + " ".join(os.path.relpath(a, ROOT) if isinstance(a, Path) else str(a) for a in args))
    run = subprocess.run([sys.executable, "-m", "gecgen.cli", *map(str, args), "--json"], capture_output=True,
                         text=True, cwd=ROOT)
    if run.returncode:
        raise SystemExit(run.stderr)
    return json.loads(run.stdout)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    files = {}
    for day, name in (("train", "train_2021-11-30"), ("val", "validation_2021-11-26")):
        for pts, keep in (("all", None), ("m1", "m1")):
            out, joints = OUT / f"{name}_{pts}.csv", OUT / f"{name}_{pts}.joints.csv"
            extra = ["--targets", keep] if keep else []
            imp = gecgen("import", ROBOT, DATA / f"{name}.csv", "--mapping", "robots/tiago.import.yaml", *extra,
                         "-o", joints)
            files[(day, "gravity")] = gecgen("gravity", ROBOT, joints, "--joints", LOADED, "-o", out)
            files[(day, pts)] = out
            files[(day, "outside")] = imp["outside_limits"]
    rows, determined = [], {}
    for label, errors in MODELS.items():
        for pts in ("m1", "all"):
            for variant in FITS[label]:
                calib = OUT / f"{label}_{pts}_{variant}.calib.json"
                # every identifiable coefficient carried, as figaroh fits; then gecgen's default, which holds
                # at zero what the data do not determine
                fit = gecgen("identify", ROBOT, files[("train", pts)], "--errors", errors, *VARIANTS[variant], "-o",
                             calib, "--keep-insignificant")
                ev = gecgen("evaluate", calib, files[("val", "m1")])
                rows.append((label, pts, variant, fit, ev))
                held = OUT / f"{label}_{pts}_{variant}.determined.calib.json"
                fit_d = gecgen("identify", ROBOT, files[("train", pts)], "--errors", errors, *VARIANTS[variant], "-o",
                               held)
                determined[(label, pts, variant)] = (fit_d, gecgen("evaluate", held, files[("val", "m1")]))
    # every tolerance of the grid, so the document can show what the cross-validation chose from
    by_tol = {}
    for pts in ("m1", "all"):
        auto = next(fit for label, p, variant, fit, ev in rows if (label, p, variant) == ("full", pts, "rank_tol"))
        for row in auto["cv"]:
            calib = OUT / f"full_{pts}_rank_tol{row['rank_tol']:g}.calib.json"
            fit = gecgen("identify", ROBOT, files[("train", pts)], "--errors", MODELS["full"], "--rank-tol",
                         f"{row['rank_tol']:g}", "-o", calib, "--keep-insignificant")
            by_tol[(pts, row["rank_tol"])] = (row["cv_rms_mm"], fit, gecgen("evaluate", calib, files[("val", "m1")]))
    diags = {}
    for label in ("offsets", "full", "elastic"):
        for pts in ("m1", "all"):
            new = OUT / f"{label}_{pts}.diagnosed.errors.yaml"
            d = gecgen("diagnose", ROBOT, files[("train", pts)], "--val", files[("val", pts)], "--errors",
                       MODELS[label], "-o", new, "--report", OUT / f"report_{label}_{pts}")
            calib = OUT / f"{label}_{pts}.diagnosed.calib.json"
            fit = gecgen("identify", ROBOT, files[("train", pts)], "--errors", new, "-o", calib)
            ev = gecgen("evaluate", calib, files[("val", "m1")])
            diags[(label, pts)] = (d, fit, ev)

    robot = load_robot(ROOT / ROBOT)
    train = read_measurements(files[("train", "m1")], robot)
    # fold split 0 is the rule's; 1..3 show how much the choice depends on the split
    pipelines = {seed: {} for seed in SPLITS}
    for pts in ("m1", "all"):
        data = read_measurements(files[("train", pts)], robot)
        for label, variant in PIPELINES:
            for seed in SPLITS:
                pipelines[seed][(label, pts, variant)] = pipeline_cv(robot, label, variant, data, train, seed)
    val = read_measurements(files[("val", "m1")], robot)
    lo, hi = train.q.min(0), train.q.max(0)
    outside = ((val.q < lo - 0.05) | (val.q > hi + 0.05)).any(1)
    wide = [f"{robot.joint_names[j]} {val.q[:, j].min():.2f}..{val.q[:, j].max():.2f} rad (training "
            f"{lo[j]:.2f}..{hi[j]:.2f})" for j in range(robot.n)
            if val.q[:, j].min() < lo[j] - 0.05 or val.q[:, j].max() > hi[j] + 0.05]

    lines = ["# Real data: the TIAGo arm from motion capture", "",
             "Data: `tests/data/tiago-mocap` (figaroh-examples, 37 training postures of 2021-11-30, 62 validation "
             "postures of 2021-11-26; four markers of one rigid body on the hand, in the frame of a body fixed to the "
             "base). Robot: `robots/tiago.yaml` (the URDF's torso lift and seven arm joints, base_footprint to "
             "arm_7_link; the marker body is a rigid tool whose placement frame 8's errors absorb). Regenerate "
             "everything with `python scripts/reproduce_tiago.py`; the commands it runs are listed at the end.", "",
             "## Reading the data", "",
             "`gecgen import` turns the wide layout (four points per row, joint names as headers) into the contract's "
             "measurement CSV through `robots/tiago.import.yaml`; every column is mapped, kept as an auxiliary signal "
             "(`marker_std_mm`) or listed as ignored. Joint readings outside the URDF limits: "
             + "; ".join(f"{day} row {o['row']}: {o['joint']} {o['value']:.5f}" for day in ("train", "val")
                         for o in files[(day, "outside")])
             + " (inside the reader's 1 mm / 1 mrad tolerance; reported, not clipped). "
             "The motion-capture-to-base transform is registered (closed form on the nominal model, then frame 0's "
             "errors); the marker points start from gecgen's placement estimate on the training file (`gecgen/fit/placement.py`, nominal model) "
             "and frame 8's errors refine them. `gecgen gravity` then appends the static gravity torque on arm_2..arm_7 "
             "(`tau_<joint>`, N m: the URDF's link masses at the measured joints, nominal kinematics), the load "
             "signal of the elastic model and of diagnose; over the training postures: "
             + "; ".join(f"{c} {files[('train', 'gravity')]['min'][c]:.2f}..{files[('train', 'gravity')]['max'][c]:.2f}"
                         for c in files[("train", "gravity")]["columns"]) + ".", "",
             "## Identification, next to figaroh", "",
             "Position RMS / max in mm. Training on the training file only; validation = marker 1 of the validation "
             "file (figaroh's figure). Point 1 = fit on marker 1 alone; all = fit on the four markers (the full hand "
             "pose). Every identifiable coefficient carried (`--keep-insignificant`), as figaroh fits; the last "
             "column is gecgen's default, which holds at zero the coefficients the data do not determine "
             "(|value| / std below 2) and refits the rest.", "",
             "| model | fitted on | identifiable | training RMS | validation RMS (marker 1) | validation max | figaroh "
             "(params, train / val) | default: carried, training / validation RMS |",
             "|---|---|---|---|---|---|---|---|"]
    for label, pts, variant, fit, ev in rows:
        fg = FIGAROH[label]
        name = NAMES[label] + {"plain": "", "ridge": f" + ridge (CV: {fit.get('ridge', 0):g})",
                 "rank_tol": f" + rank tolerance (CV: {fit.get('rank_tol', 0):g})"}[variant]
        fit_d, ev_d = determined[(label, pts, variant)]
        lines.append(f"| {name} | {'point 1' if pts == 'm1' else 'all 4 points'} | {fit['n_identifiable']} | "
                     f"{fit['train']['rms_mm']:.2f} | {ev['after']['rms_mm']:.2f} | {ev['after']['max_mm']:.2f} | "
                     f"{fg[2]}: {fg[0]:.2f} / {fg[1]:.2f} | {fit_d.get('n_carried', fit_d['n_identifiable'])}: "
                     f"{fit_d['train']['rms_mm']:.2f} / {ev_d['after']['rms_mm']:.2f} |")
    full_m1 = next(fit for label, pts, variant, fit, ev in rows if (label, pts, variant) == ("full", "m1", "plain"))
    lines += ["", "The two reduced models reproduce figaroh's figures to the printed digit with the same parameter "
                  "counts (9 and 14): registration, redundancy analysis and fit agree with an independent "
                  f"implementation on real data. For the full geometric model gecgen keeps {full_m1['n_identifiable']} "
                  "parameters with one point (4R + 2P + 3 for 7 revolute joints and one prismatic) where figaroh keeps "
                  f"30; the larger model fits the training data better ({full_m1['train']['rms_mm']:.2f} against "
                  f"{FIGAROH['full'][0]} mm) and the validation data worse.", ""] + _weak_section(by_tol) + ["",
              "## Why validation is harder than training", "",
              f"{int(outside.sum())} of the {val.n_poses} validation postures leave the joint ranges of the training "
              f"file by more than 0.05 rad or m: {'; '.join(wide)}. A calibration extrapolates there, and those "
              "postures carry most of the validation error (below).", ""]
    for label in ("full", "elastic"):
        per = _errors_by_range(OUT / f"{label}_all_plain.calib.json", files[("val", "m1")], outside)
        lines += [f"{NAMES[label].capitalize()}, fitted on all four points: validation RMS "
                  f"{per[0]:.2f} mm on the {int((~outside).sum())} postures inside the training ranges, "
                  f"{per[1]:.2f} mm on the {int(outside.sum())} outside.", ""]
    lines += ["## What is left in the residual: gecgen diagnose", "",
              "Decisions on the training file only (chi-square with multiplicity correction and 5-fold "
              "cross-validation over the training postures); `--val` only reports.", "",
              "| start | fitted on | training CV RMS before -> after | validation RMS (marker 1) after refit | effects added |",
              "|---|---|---|---|---|"]
    for (label, pts), (d, fit, ev) in diags.items():
        effects = "; ".join(f"{e['error']}: {', '.join(e['terms'])}" for e in d["effects"]) or "none"
        lines.append(f"| {label} | {'point 1' if pts == 'm1' else 'all 4 points'} | "
                     f"{d['rounds'][0]['cv_rms_mm']:.2f} -> {d['rounds'][-1]['cv_rms_mm']:.2f} | "
                     f"{ev['after']['rms_mm']:.2f} | {effects} |")
    lines += ["", "Joint numbering: q1 torso_lift, q2..q8 arm_1..arm_7; frame i sits after joint i, so `7.er` is a "
                  "rotation about arm_6's axis, i.e. an arm_6 angle error. Upstream reports an encoder problem on "
                  "arm_5 (q6) and free play in arm_6 (q7)."] + _traced(diags) + [""] + _compliance_section(files) + ["",
              "## Against the target", ""] + _target_verdict(rows, by_tol, diags, pipelines) + [""] \
        + calibrate_section() + ["## Commands", "", "```"] + commands + ["```"]
    (ROOT / "docs" / "real-data-tiago.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


#: every way of fitting a model that the training file may choose among (start model, identify variant
#: or diagnose), each run whole inside every fold of the pipeline cross-validation
#: seeds of the pipeline CV's fold split: the first is the rule's
SPLITS = (0, 1, 2, 3)
PIPELINES = [("base", "plain"), ("offsets", "plain"), ("full", "plain"), ("full", "ridge"), ("full", "rank_tol"),
             ("offsets", "diagnose"), ("full", "diagnose"), ("elastic", "plain"), ("elastic", "ridge")]


def fitted(robot, label: str, variant: str, data: Measurements):
    """(compiled model, fit) of one pipeline on `data`: what the commands above do, in process."""
    model = load_error_model(ROOT / MODELS[label], robot)
    if variant == "diagnose":
        final = diagnose(robot, model, data, data).final  # the second `data` is only reported on
        return final.cm, final.fit
    cm = CompiledModel(robot, model)
    grids = {"ridge": {"ridge": RIDGE_GRID}, "rank_tol": {"rank_tol": RANK_TOL_GRID}}.get(variant)
    options = choose(cm, data, grids)[0] if grids else {}
    return cm, identify(cm, data, **options)


def pipeline_cv(robot, label: str, variant: str, data: Measurements, m1: Measurements, seed: int = 0,
                folds: int = 5) -> float:
    """5-fold cross-validated RMS (mm) on marker 1 of the training postures of a whole pipeline: in
    each fold every choice the pipeline makes (CV-chosen ridge or tolerance, diagnose's terms) is
    made again on the other folds' postures alone, so the score is that of the procedure, not of a
    model already shaped by the postures it is scored on. `data` and `m1` hold the same postures."""
    fold = np.random.default_rng(seed).permutation(data.n_poses) % folds
    sq, n = 0.0, 0
    for f in range(folds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # conditioning warnings of the fold fits; the score says it all
            cm, fit = fitted(robot, label, variant, data.subset(np.nonzero(fold != f)[0]))
        test = m1.subset(np.nonzero(fold == f)[0])
        e = position_errors(cm, test, fit.registration.to_world(test.xyz), fit.c)
        sq, n = sq + float(e @ e), n + len(e)
    return 1e3 * float(np.sqrt(sq / n))


def _weak_section(by_tol) -> list[str]:
    """The weakly determined parameters of the full model, and what a rank tolerance chosen by
    cross-validation on the training file does with them (validation shown, never used)."""
    tols = sorted({t for _, t in by_tol})
    ranked = sorted((e for e in by_tol[("m1", tols[-1])][1]["eliminated"] if e["reason"] == "weak"),
                    key=lambda e: e["share"])
    weakest = "; ".join(f"{e['param']} {e['share']:.3f}" for e in ranked[:6])
    lines = ["## Weakly determined parameters", "",
             "Column-pivoted QR of the column-normalised H_e on the training file (marker 1) orders the full "
             "model's 33 identifiable parameters from best to worst determined; the share of each normalised "
             f"column outside the better-determined ones, weakest first: {weakest}. Held at zero by "
             "`identify --rank-tol T` when below T; `--rank-tol auto` picks T by 5-fold cross-validation over "
             "the training postures. Every T of the grid (the validation column is measured after the fact, for "
             "reading only; the choice is the lowest training CV):", "",
             "| fitted on | rank tolerance | parameters | training RMS | training CV RMS | validation RMS (marker 1) |",
             "|---|---|---|---|---|---|"]
    for (pts, tol), (cv, fit, ev) in by_tol.items():  # point 1 first, tolerances ascending
        best = min(by_tol[(p, t)][0] for p, t in by_tol if p == pts)
        mark = " (chosen)" if cv == best else ""
        lines.append(f"| {'point 1' if pts == 'm1' else 'all 4 points'} | {tol:g}{mark} | {fit['n_identifiable']} | "
                     f"{fit['train']['rms_mm']:.2f} | {cv:.2f} | {ev['after']['rms_mm']:.2f} |")
    return lines


def _traced(diags) -> list[str]:
    """What diagnose traced to a joint's gravity load, and to arm_5 or arm_6, in words."""
    loads = {}
    for (label, pts), (d, fit, ev) in diags.items():
        for e in d["effects"]:
            for v in e["variables"]:
                if v.startswith("tau_") or v in ("q6", "q7"):
                    loads.setdefault(f"`{e['error']}: {', '.join(e['terms'])}`", []).append(
                        f"{label} ({'point 1' if pts == 'm1' else 'all 4 points'})")
    if not loads:
        return ["Nothing traced to a joint's gravity load or to q6, q7 survives diagnose's selection-aware "
                "cross-validation on these 37 training postures."]
    text = ["Traced to a joint's gravity load, or to q6 and q7: " + "; ".join(
        f"{effect} from {', '.join(starts)}" for effect, starts in loads.items()) + "."]
    if any(k.startswith("`7.er: tau_arm_6_joint") for k in loads):
        text.append("That is arm_6's angle error growing with the gravity torque on arm_6: the free play upstream "
                    "reports shows as a load-dependent angle (a joint with play settles on the side its load "
                    "pushes it to).")
    if not any("q6" in k or "tau_arm_5_joint" in k for k in loads):
        text.append("Nothing is traced to arm_5 (q6 or its load): the encoder problem upstream reports does not show "
                    "in these postures above what the other effects explain.")
    return [" ".join(text)]


def _compliance_section(files) -> list[str]:
    """The gravity compliances of the elastic model fitted on all four points, with their significance."""
    calib = json.loads((OUT / "elastic_all_plain.calib.json").read_text())
    grav = files[("train", "gravity")]
    robot = load_robot(ROOT / ROBOT)
    tau6 = read_measurements(files[("train", "m1")], robot).aux_columns(("tau_arm_6_joint",))[:, 0]
    lines = ["## Gravity load: the joint compliance the geometric model lacks", "",
             "`robots/tiago.elastic.errors.yaml` is the full geometric model plus one compliance per loaded arm "
             "joint: the joint's angle error (er of the frame after it) grows linearly with the gravity torque on "
             "it, the seed paper's elastic error with the load computed from the URDF instead of measured. Fitted "
             "on all four points of the training file:", "",
             "| joint | compliance, mrad per N m | std | value / std | training torque, N m | angle swing, mrad |",
             "|---|---|---|---|---|---|"]
    for c in calib["coefficients"]:
        if ":tau_" not in c["name"]:
            continue
        col = c["name"].split(":")[1]
        lo, hi = grav["min"][col], grav["max"][col]
        if c["std"] is None:  # held at zero: the data do not determine it (or it is eliminated)
            lines.append(f"| {col[4:]} | 0 (not determined, held) | - | - | {lo:.2f}..{hi:.2f} | 0 |")
            continue
        lines.append(f"| {col[4:]} | {1e3 * c['value']:.3f} | {1e3 * c['std']:.3f} | {abs(c['value']) / c['std']:.1f} | "
                     f"{lo:.2f}..{hi:.2f} | {1e3 * abs(c['value']) * (hi - lo):.2f} |")
    lines += ["", f"{int((tau6 < 0).sum())} of the {len(tau6)} training postures load arm_6 the same way (negative "
                  "torque), so free play (an angle set by the sign of the load) and compliance (an angle proportional "
                  "to it) cannot be told apart on them; the linear term is the simpler of the two and the one the "
                  "data supports."]
    return lines


def _target_verdict(rows, by_tol, diags, by_split) -> list[str]:
    """The model the training file chooses (lowest pipeline CV on marker 1) against figaroh's 3.22 mm;
    every pipeline's validation is listed after the choice, for reading only; then the choice
    under the other fold splits."""
    pipelines = by_split[SPLITS[0]]
    target = FIGAROH["full"][1]
    val = {(label, pts, variant): ev["after"]["rms_mm"] for label, pts, variant, fit, ev in rows}
    val.update({(label, pts, "diagnose"): ev["after"]["rms_mm"] for (label, pts), (d, fit, ev) in diags.items()})
    names = {"plain": "", "ridge": " + ridge (auto)", "rank_tol": " + rank tolerance (auto)",
             "diagnose": " + diagnose"}
    chosen = min(pipelines, key=pipelines.get)
    text = [f"Target: validation RMS on marker 1 below figaroh's {target} mm with a model chosen on the training "
            "file alone. The rule: every way of fitting a model above is run whole inside each of 5 folds of the 37 "
            "training postures (its cross-validated ridge or tolerance, and diagnose's terms, chosen again on the "
            "other four folds), and scored on marker 1 of the held-out postures; the pipeline with the lowest score "
            "is the choice. It is the same for every pipeline and reads nothing of the validation file, but it was "
            "written after the validation figures of earlier revisions of this study had been seen (git history). "
            "The two elastic pipelines were added afterwards, for the free play upstream reports in arm_6 and the "
            "seed paper's elastic errors; their training CV, and the choice the rule then makes, were recorded in "
            "the commit that added `robots/tiago.elastic.errors.yaml` (4b0dbe3) before any validation figure of "
            "them was computed.", "",
            "| pipeline | fitted on | training CV RMS, marker 1 (the choice) | validation RMS, marker 1 (read after) |",
            "|---|---|---|---|"]
    for key in sorted(pipelines, key=pipelines.get):
        label, pts, variant = key
        mark = " **(chosen)**" if key == chosen else ""
        text.append(f"| {label}{names[variant]}{mark} | {'point 1' if pts == 'm1' else 'all 4 points'} | "
                    f"{pipelines[key]:.2f} | {val[key]:.2f} |")
    label, pts, variant = chosen
    got = val[chosen]
    text += ["", f"The training file chooses {label}{names[variant]} fitted on "
                 f"{'point 1' if pts == 'm1' else 'all four points'}: validation RMS {got:.2f} mm on marker 1, "
                 + (f"below figaroh's {target} mm by {target - got:.2f} mm. A margin that small says the target is "
                    "met as written, not that the model is decisively better than figaroh's on the other day: "
                    "most of the validation error sits in the postures outside the training ranges (above)."
                    if got < target else f"not below figaroh's {target} mm.")]
    text += ["", "The same rule with the 37 postures split into folds differently (seed of the split; 0 is the "
                 "rule's). Each row is a whole re-run of every pipeline above:", "",
             "| split | chosen pipeline | fitted on | training CV RMS | runner-up (training CV) | validation RMS of the choice |",
             "|---|---|---|---|---|---|"]
    for seed, scores in by_split.items():
        first, second = sorted(scores, key=scores.get)[:2]
        text.append(f"| {seed} | {first[0]}{names[first[2]]} | {'point 1' if first[1] == 'm1' else 'all 4 points'} | "
                    f"{scores[first]:.2f} | {second[0]}{names[second[2]]}, "
                    f"{'point 1' if second[1] == 'm1' else 'all 4 points'} ({scores[second]:.2f}) | {val[first]:.2f} |")
    choices = list(dict.fromkeys(min(scores, key=scores.get) for scores in by_split.values()))
    worst = max(val[c] for c in choices)
    text += ["", "Under every split the rule chooses " + " or ".join(
        f"{c[0]}{names[c[2]]} fitted on {'point 1' if c[1] == 'm1' else 'all four points'}" for c in choices)
        + f"; the worst of these on the validation day is {worst:.2f} mm, "
        + ("below" if worst < target else "not below") + f" figaroh's {target} mm."]
    return text


def _errors_by_range(calib_path: Path, val_csv: Path, outside: np.ndarray) -> tuple[float, float]:
    from gecgen.fit import calibration
    from gecgen.runtime.compiled import CompiledModel
    from gecgen.fit.identify import position_errors

    calib = calibration.load(calib_path)
    val = read_measurements(val_csv, calib.robot)
    e = 1e3 * position_errors(CompiledModel(calib.robot, calib.model), val, calib.registration.to_world(val.xyz),
                              calib.c)
    return float(np.sqrt(np.mean(e[~outside] ** 2))), float(np.sqrt(np.mean(e[outside] ** 2)))


CALIBRATE_HEADING = "## The whole pipeline in one command: gecgen calibrate"


def calibrate_section() -> list[str]:
    """`gecgen calibrate` on the four points of the training file (joint columns only: the elastic
    candidate takes its gravity torques from the URDF's masses), validation on marker 1."""
    OUT.mkdir(parents=True, exist_ok=True)
    files = {}
    for day, name, keep in (("train", "train_2021-11-30", None), ("val", "validation_2021-11-26", "m1")):
        files[day] = OUT / f"{name}_{keep or 'all'}.joints.csv"
        gecgen("import", ROBOT, DATA / f"{name}.csv", "--mapping", "robots/tiago.import.yaml",
               *(["--targets", keep] if keep else []), "-o", files[day])
    start = len(commands)
    out = gecgen("calibrate", ROBOT, files["train"], "--val", files["val"], "-o", OUT / "calibrate")
    rows = [f"| {c['model']}{' **(chosen)**' if c['model'] == out['model'] else ''} | "
            + (f"{c['cv_rms_mm']:.2f}" if c["cv_rms_mm"] is not None else f"not fitted: {c['refused']}") + " |"
            for c in out["candidates"]]
    target = FIGAROH["full"][1]
    return [CALIBRATE_HEADING, "",
            "What a user without this study would run: import the two files, then one command that chooses the model "
            "on the training file alone (pipeline cross-validation over its 37 postures, gecgen/loop/calibrate.py) "
            "among the candidates that apply to this robot and data, fits it on all four points and scores the "
            "validation file's marker 1. The robot's default model is the full geometric one, so it is not a "
            "separate candidate; the elastic candidate's gravity torques come from the URDF's masses.", "",
            "| candidate | training CV RMS, all points (mm) |", "|---|---|", *rows, "",
            f"Chosen: {out['model']}, {out['n_identifiable']} identifiable coefficients; training RMS "
            f"{out['train']['rms_mm']:.2f} mm; validation RMS on marker 1 {out['val']['rms_mm']:.2f} mm "
            f"(max {out['val']['max_mm']:.2f} mm, uncalibrated {out['val_before']['rms_mm']:.2f} mm), against "
            f"figaroh's {target} mm for its full geometric model.", "", "```", *commands[start - 2:], "```", ""]


def calibrate_only():
    """Rewrite only the calibrate section of the existing document."""
    doc = ROOT / "docs" / "real-data-tiago.md"
    text = doc.read_text()
    head = text.split(CALIBRATE_HEADING)[0] if CALIBRATE_HEADING in text else text.split("## Commands")[0]
    tail = "## Commands" + text.split("## Commands")[1]
    doc.write_text(head + "\n".join(calibrate_section()) + "\n" + tail)


if __name__ == "__main__":
    calibrate_only() if sys.argv[1:] == ["--calibrate-only"] else main()
