"""The human report of a diagnosis: Markdown with PNG plots (matplotlib, no display needed)."""
from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gecgen.files import write_atomically  # noqa: E402
from gecgen.loop.diagnose import Diagnosis, Round, verdict  # noqa: E402
from gecgen.model.measurements import Measurements  # noqa: E402
from gecgen.model.robot import WRENCH  # noqa: E402
from gecgen.model.pose_targets import measured_rows  # noqa: E402
from gecgen.runtime.identify import row_errors  # noqa: E402


def _variable(data: Measurements, name: str) -> np.ndarray:
    if name.startswith("q") and name[1:].isdigit():
        return data.q[:, int(name[1:]) - 1]
    if name in WRENCH:
        return data.w[:, WRENCH.index(name)]
    if name == "payload":
        return np.linalg.norm(data.w[:, :3], axis=1)
    return data.aux[:, data.aux_names.index(name)]


def _errors_by_pose(rnd: Round, data: Measurements) -> np.ndarray:
    """RMS position error (mm) of the measured points per pose."""
    rows = measured_rows(rnd.cm.robot, data)
    e = row_errors(rnd.cm, data, rnd.fit.to_world(data), rnd.fit.c, rows)[0]
    pose = data.pose[rows.first]
    sq = np.bincount(pose, e ** 2, minlength=data.n_poses) / np.maximum(np.bincount(pose, minlength=data.n_poses), 1)
    return 1e3 * np.sqrt(sq)


def residual_plot(diag: Diagnosis, data: Measurements, variable: str, path: Path):
    x = _variable(data, variable)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(x, _errors_by_pose(diag.initial, data), ".", ms=4, alpha=0.7, label="declared model")
    ax.plot(x, _errors_by_pose(diag.final, data), ".", ms=4, alpha=0.7, label="after diagnose")
    ax.set_xlabel(variable)
    ax.set_ylabel("residual per pose, rms (mm)")
    ax.set_title(f"{diag.robot.name}: residual against {variable} (training data)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    png = io.BytesIO()
    fig.savefig(png, format="png", dpi=110)
    plt.close(fig)
    write_atomically(path, png.getvalue())


def write_report(diag: Diagnosis, data: Measurements, outdir: str | Path, errors_out: str) -> Path:
    """Write report.md and one PNG per traced variable into outdir; returns the Markdown path."""
    outdir = Path(outdir)
    b, a = diag.before, diag.after
    lines = [f"# gecgen diagnose: {diag.robot.name}", "",
             f"Training data: {data.source} ({data.n_poses} poses). New error model: `{errors_out}`.", "",
             "| | training RMS (mm) | held-out RMS (mm) | held-out max (mm) |", "|---|---|---|---|",
             f"| declared model | {b['train_rms_mm']:.4f} | {b['val_rms_mm']:.4f} | {b['val_max_mm']:.4f} |",
             f"| after diagnose | {a['train_rms_mm']:.4f} | {a['val_rms_mm']:.4f} | {a['val_max_mm']:.4f} |", "",
             *([f"Orientation (mrad): held-out RMS {b['val_rot_rms_mrad']:.4f} declared, {a['val_rot_rms_mrad']:.4f} "
                f"after diagnose; max {b['val_rot_max_mrad']:.4f} and {a['val_rot_max_mrad']:.4f}.", ""]
               if "val_rot_rms_mrad" in a else []),
             f"{diag.candidates_tested} candidate effects screened in {diag.rounds} rounds; an effect is added only "
             "when it passes a Bonferroni-corrected chi-square test and lowers the 5-fold cross-validated RMS "
             "on the training data.", ""]
    if not diag.effects:
        lines += ["diagnose added nothing to the declared model.", ""]
    lines += [verdict(diag.remaining), ""]
    if diag.remaining["outliers"]:
        lines += [f"{diag.remaining['outliers']} training rows were outliers of the robust fit (down-weighted, "
                  f"listed by `gecgen identify`); they neither chose nor hid an effect.", ""]
    variables = []
    for k, eff in enumerate(diag.effects, 1):
        lines += [f"## Effect {k}: {eff.error} in {', '.join(eff.variables)} ({eff.family})", "",
                  f"Cross-validated gain {eff.gain_mm:.4f} mm, p = {eff.p_value:.2g}.", "",
                  "| coefficient | value | std |", "|---|---|---|"]
        lines += [f"| `{c['name']}` | {c['value']:.6g} | {'eliminated' if c['std'] is None else format(c['std'], '.2g')} |"
                  for c in eff.coefficients]
        if eff.alternatives:
            lines += ["", "Indistinguishable on this data (the same fitted effect):", ""]
            lines += [f"- {alt['error']}: {', '.join(alt['terms'])} (similarity {alt['similarity']:.4f})"
                      for alt in eff.alternatives]
        lines.append("")
        variables += [v for v in eff.variables if v not in variables]
    for v in variables:
        png = f"residual_{v}.png"
        residual_plot(diag, data, v, outdir / png)
        lines += [f"![residual against {v}]({png})", ""]
    lines += ["## Rounds", "", "| round | training RMS (mm) | CV RMS (mm) | candidates | accepted |", "|---|---|---|---|---|"]
    lines += [f"| {h['round']} | {h['train_rms_mm']:.4f} | {h['cv_rms_mm']:.4f} | {h['candidates']} | {h['accepted'] or '-'} |"
              for h in diag.history]
    return write_atomically(outdir / "report.md", "\n".join(lines) + "\n")


def write_calibrate_report(result: dict, outdir: str | Path) -> Path:
    """report.md of `gecgen calibrate` from its result (the command's JSON); returns the path."""
    outdir = Path(outdir)
    rows = ["| model | coefficients | training CV RMS (mm) |", "|---|---|---|"]
    for c in result["candidates"]:
        cv = f"{c['cv_rms_mm']:.4f}" if c["cv_rms_mm"] is not None else f"not fitted: {c['refused']}"
        size = f"{c['n_params']} + what diagnose adds" if c["diagnose"] else c["n_params"]
        rows.append(f"| {c['model']}{' **(chosen)**' if c['model'] == result['model'] else ''} | {size} | {cv} |")
    lines = [f"# gecgen calibrate: {result['robot']}", "",
             f"Training data: {result['train_data']}. The model is chosen on it alone: each candidate is fitted "
             "whole (diagnose's choices included) on four fifths of the training poses and scored on the fifth left "
             "out, in turn; the lowest cross-validated RMS wins, a tie within 1% going to the smaller model.", "",
             *rows, "",
             f"Chosen: **{result['model']}**, {result['n_identifiable']} identifiable of {result['n_params']} "
             f"coefficients.", "",
             "| | uncalibrated RMS / max (mm) | calibrated RMS / max (mm) |", "|---|---|---|",
             f"| training | {result['before']['rms_mm']:.4f} / {result['before']['max_mm']:.4f} | "
             f"{result['train']['rms_mm']:.4f} / {result['train']['max_mm']:.4f} |"]
    if "val" in result:
        lines.append(f"| validation ({result['validation']}) | {result['val_before']['rms_mm']:.4f} / "
                     f"{result['val_before']['max_mm']:.4f} | {result['val']['rms_mm']:.4f} / {result['val']['max_mm']:.4f} |")
    lines.append("")
    if result["effects"]:
        lines += ["Effects diagnose added to the geometric model:", ""]
        lines += [f"- {e['error']}: {', '.join(e['terms'])} ({e['family']}, cross-validated gain {e['gain_mm']:.4f} mm)"
                  for e in result["effects"]]
        lines.append("")
    if result["outliers"]:
        lines += [f"{len(result['outliers'])} training points were outliers of the robust fit (down-weighted; "
                  "`calibration.json` lists them).", ""]
    if result["placement"]:
        lines += ["Targets placed from the training data before the fit: " + ", ".join(
            f"{n} {list(map(lambda v: round(v, 4), xyz))} m" for n, xyz in result["placement"]["targets_m"].items()), ""]
    lines += ["Files: `calibration.json` (for `gecgen evaluate` and `gecgen compensate`), `errors.yaml` (the chosen "
              "error model), `generated/` (its C and CasADi code, `NAME_calibration.h` with the coefficients in the code's "
              "order, `NAME_example.c`: `gecgen export` says how to build it).", ""]
    return write_atomically(outdir / "report.md", "\n".join(lines) + "\n")
