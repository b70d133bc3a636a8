"""Reproduce the seed paper's PPS experiment on the simulated PPS and write docs/paper-reproduction.md.

    python scripts/reproduce_paper.py

1. Simulate the paper's design (robots/pps.truth.yaml): set a (treatment-volume vertices at the
   isocenter) and set b (one axis at a time), 0 and 70 kg; train on set b + half of set a.
2. Identify the default GEC model (robots/pps.errors.yaml) with all training poses and with 125.
3. Command the truth robot to the compensated joints of every validation configuration and
   measure again: the compensated error, as in the paper.
4. What the paper left open: residual error against the number of calibration poses (30 to all,
   several random subsets per size) and the observability index along it.
5. The closed loop (gecgen diagnose) on the same training data.
"""
from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gecgen.model import load_robot  # noqa: E402
from gecgen.symbolic.terms import load_error_model  # noqa: E402
from gecgen.model.kinematics import target_positions  # noqa: E402
from gecgen.model.measurements import Measurements, read_measurements  # noqa: E402
from gecgen.model.validation import read_yaml  # noqa: E402
from gecgen.runtime.compiled import FAILED, CompiledModel  # noqa: E402
from gecgen.fit.identify import identify, position_errors, summary  # noqa: E402
from gecgen.simulate import load_truth, simulate  # noqa: E402
from gecgen.simulate.designs import Design  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "paper"
FIG = ROOT / "docs" / "figures"
SIZES = (30, 50, 75, 100, 125, 150, 200, 300)
SUBSETS = 5


def gecgen(*args) -> dict:
    run = subprocess.run([sys.executable, "-m", "gecgen.cli", *map(str, args), "--json"], capture_output=True,
                         text=True, cwd=ROOT)
    if run.returncode:
        raise SystemExit(run.stderr)
    return json.loads(run.stdout)


def compensated_errors(robot, truth, cm, c, val: Measurements, rng) -> np.ndarray:
    """Command the truth robot to the compensated joints of every validation pose and measure the
    targets again (repeatability and tracker noise included): |measured - wanted| per point (m)."""
    q_cmp, status = cm.compensate(val.q, val.w, None, c)
    if np.isin(status, FAILED).any():
        raise RuntimeError("compensation failed (no convergence, or not finite) for some validation poses")
    payload = np.linalg.norm(val.w[:, :3], axis=1) / np.linalg.norm(truth.gravity)
    names = list(robot.targets)
    targets = tuple(names[k] for k in np.unique(val.target))
    again = simulate(robot, truth, Design(q_cmp, payload, np.zeros(3), targets, np.array(["a"] * val.n_poses)), rng)
    wanted = target_positions(robot, val.q)[again.pose, again.target]
    return np.linalg.norm(again.xyz - wanted, axis=1)


def fit(cm, data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return identify(cm, data)


def study(m, train, val, truth, robot, rng):
    """Fit on all training poses and on random subsets: compensated and predicted validation errors."""
    full = fit(m, train)
    comp_full = compensated_errors(robot, truth, m, full.c, val, rng)
    comp_125 = [summary(compensated_errors(robot, truth, m, fit(m, train.subset(
        np.sort(rng.choice(train.n_poses, 125, replace=False)))).c, val, rng)) for _ in range(SUBSETS)]
    curve = []
    for n in (*SIZES, train.n_poses):
        maxes, rmses, obs = [], [], []
        for _ in range(SUBSETS if n < train.n_poses else 1):
            f = fit(m, train.subset(np.sort(rng.choice(train.n_poses, n, replace=False))))
            e = position_errors(m, val, val.xyz, f.c)
            maxes.append(1e3 * e.max())
            rmses.append(1e3 * np.sqrt(np.mean(e ** 2)))
            obs.append(f.observability_index)
        curve.append((n, np.median(maxes), np.min(maxes), np.max(maxes), np.median(rmses), np.median(obs)))
    return full, comp_full, comp_125, curve


def plots(before_val, results):
    fig, ax = plt.subplots(figsize=(8, 4))
    order = np.argsort(before_val)
    ax.plot(1e3 * before_val[order], ".", label="measured, uncompensated")
    for label, (_, comp_full, _, _) in results.items():
        ax.plot(1e3 * comp_full[order], ".", label=f"measured after compensation, {label}")
    ax.axhline(0.5, color="k", ls="--", lw=1, label="specification 0.5 mm")
    ax.set_yscale("log")
    ax.set_xlabel("validation point (sorted by uncompensated error)")
    ax.set_ylabel("position error (mm)")
    ax.set_title("Simulated PPS, paper design: measured and residual errors (cf. the paper's Figure 4)", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(FIG / "paper-figure4.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax2 = ax.twinx()
    for (label, (_, _, _, curve)), colour in zip(results.items(), ("C0", "C1")):
        n, med, lo, hi, rms, obs = map(np.array, zip(*curve))
        ax.fill_between(n, lo, hi, color=colour, alpha=0.15)
        ax.plot(n, med, "o-", color=colour, label=f"{label}: max error (median; band: range over {SUBSETS} subsets)")
        ax.plot(n, rms, "s--", color=colour, label=f"{label}: RMS error (median)")
        ax2.plot(n, obs, "^:", color=colour, alpha=0.6)
    ax.axhline(0.5, color="k", ls="--", lw=1)
    ax.set_xlabel("calibration poses")
    ax.set_ylabel("validation error after calibration (mm)")
    ax2.set_ylabel("observability index O1 (triangles)")
    ax.set_yscale("log")
    ax.legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(FIG / "paper-poses-curve.png", dpi=110)
    plt.close(fig)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    FIG.mkdir(parents=True, exist_ok=True)
    robot_file = ROOT / "robots" / "pps.yaml"
    train_csv, val_csv = OUT / "train.csv", OUT / "val.csv"
    sim = gecgen("simulate", robot_file, "--design", "paper", "--seed", 1, "-o", train_csv, "--val-out", val_csv,
                 "--truth-out", OUT / "truth.yaml")
    robot = load_robot(robot_file)
    truth = load_truth(read_yaml(OUT / "truth.yaml", "truth"), robot)
    train, val = read_measurements(train_csv, robot), read_measurements(val_csv, robot)
    (OUT / "const.errors.yaml").write_text('default: ["1"]\n')
    diag = gecgen("diagnose", robot_file, train_csv, "--val", val_csv, "--errors", OUT / "const.errors.yaml",
                  "-o", OUT / "pps.diagnosed.errors.yaml", "--report", OUT / "diagnose")
    models = {"default GEC model": load_error_model(ROOT / "robots" / "pps.errors.yaml", robot),
              "diagnosed model": load_error_model(OUT / "pps.diagnosed.errors.yaml", robot)}
    rng = np.random.default_rng(3)
    results = {label: study(CompiledModel(robot, m), train, val, truth, robot, rng) for label, m in models.items()}
    before_val = position_errors(CompiledModel(robot, models["default GEC model"]), val, val.xyz, None)
    plots(before_val, results)

    b = summary(before_val)
    d, g = results["default GEC model"], results["diagnosed model"]

    def comp_cell(r):
        return f"{summary(r[1])['rms_mm']:.3f} mm RMS, {summary(r[1])['max_mm']:.3f} mm max"

    def c125_cell(r):
        mx = np.array([x["max_mm"] for x in r[2]])
        return (f"{np.mean([x['rms_mm'] for x in r[2]]):.3f} mm RMS, max {mx.min():.3f} to {mx.max():.3f} mm "
                f"(median {np.median(mx):.3f})")

    lines = [
        "# The seed paper's PPS experiment, reproduced on a simulated PPS", "",
        "Regenerate every number and figure here with `python scripts/reproduce_paper.py` (23 s on the 2-core benchmark machine when idle; "
        "it runs the commands named below and the library behind them). The robot is `robots/pps.yaml`, the "
        "truth `robots/pps.truth.yaml`: constant generalized errors (1.5 mm, 1 mrad std), joint offsets, 0.3 mm "
        "rail waviness on the lateral axis, a couch cantilever that droops as the longitudinal axis extends, "
        "roll/pitch compliance under the couch and patient weight, 0.05 mm (1 sigma, so 0.15 mm 3-sigma) "
        "repeatability and 0.04 mm tracker noise.", "",
        "## Design", "",
        "`gecgen simulate robots/pps.yaml --design paper --seed 1 -o train.csv --val-out val.csv`: set a (8 vertices "
        "of the 50 x 50 x 40 cm treatment volume at the isocenter for theta -90..90 deg in 30 deg steps, 0 and 70 kg) "
        "has 112 configurations as in the paper; set b (each of d1, d2, d3, theta alone in 50 mm, 20 mm, 25 mm, "
        "5 deg steps, 0 and 70 kg) has 340 here against the paper's 338 (home is measured once per sweep). "
        f"Training: set b and half of set a ({train.n_poses} poses, {len(train.xyz)} points of targets t1-t3); "
        f"validation: the other half of set a ({val.n_poses} poses). Uncompensated error of all data: "
        f"{sim['uncompensated']['rms_mm']:.2f} mm RMS, {sim['uncompensated']['max_mm']:.2f} mm max.", "",
        "## Results next to the paper", "",
        "Models: the default GEC model `robots/pps.errors.yaml` (constant base errors; every error of frames 1-6 "
        "quadratic in its joint and linear in the wrench, the paper's kind of model), and the model `gecgen diagnose` "
        "builds from constant errors on the training data alone (below). Compensated = the truth robot commanded "
        "to the corrected joints of each validation configuration (`gecgen compensate`) and measured again, "
        "repeatability and tracker noise included.", "",
        "| | paper | default GEC model | diagnosed model |", "|---|---|---|---|",
        f"| uncompensated, validation points | about 10 mm | {b['rms_mm']:.2f} mm RMS, {b['max_mm']:.2f} mm max | same |",
        f"| compensated, {train.n_poses} calibration poses | 0.38 mm max (under 400 poses) | {comp_cell(d)} | {comp_cell(g)} |",
        f"| compensated, 125 calibration poses ({SUBSETS} random subsets) | 0.49 mm max | {c125_cell(d)} | {c125_cell(g)} |",
        f"| identifiable coefficients | 16 geometric (roll and pitch never move) | {d[0].redundancy.n_identifiable} of "
        f"{d[0].redundancy.n_params} | {g[0].redundancy.n_identifiable} of {g[0].redundancy.n_params} |",
        f"| training fit | | {d[0].train['rms_mm']:.3f} mm RMS | {g[0].train['rms_mm']:.3f} mm RMS |", "",
        "With constant errors only, 16 coefficients are identifiable on this design: the paper's count. The noise "
        "floor of a re-measured point is about 0.11 mm RMS (repeatability and tracker together).", "",
        "![measured and residual errors](figures/paper-figure4.png)", "",
        "## What the paper left open: error against the number of calibration poses", "",
        f"Random subsets of the training poses ({SUBSETS} per size), fitted and evaluated on the validation points "
        "(prediction residual, no re-measurement), with the observability index O1 = (product of the singular "
        "values of the column-scaled H_e)^(1/k) / sqrt(m). A model with many coefficients needs many poses: the "
        "default model over-fits badly with few poses, the smaller diagnosed model much less. (The diagnosed "
        "model's terms were chosen on all training poses, so its small-subset figures are somewhat optimistic.)", ""]
    for label, (_, _, _, curve) in results.items():
        lines += [f"{label}:", "", "| poses | max error, median (mm) | max error, range (mm) | RMS, median (mm) | O1, median |",
                  "|---|---|---|---|---|"]
        lines += [f"| {int(r[0])} | {r[1]:.3f} | {r[2]:.3f} - {r[3]:.3f} | {r[4]:.3f} | {r[5]:.3g} |" for r in curve]
        lines.append("")
    lines += ["![error against poses](figures/paper-poses-curve.png)", "",
              "## The closed loop on the same data", "",
              "`gecgen diagnose robots/pps.yaml train.csv --val val.csv --errors const.errors.yaml` starting from "
              "constant errors only (the paper's 16 identifiable parameters), the training data alone deciding:", "",
              "| | training RMS (mm) | validation RMS (mm) | validation max (mm) |", "|---|---|---|---|",
              f"| constant errors | {diag['before']['train_rms_mm']:.3f} | {diag['before']['val_rms_mm']:.3f} | "
              f"{diag['before']['val_max_mm']:.3f} |",
              f"| after diagnose | {diag['after']['train_rms_mm']:.3f} | {diag['after']['val_rms_mm']:.3f} | "
              f"{diag['after']['val_max_mm']:.3f} |", "", "Effects added, in order:", ""]
    for e in diag["effects"]:
        others = list(dict.fromkeys(a["error"] for a in e["indistinguishable"] if a["error"] != e["error"]))
        lines.append(f"- `{e['error']}`: {', '.join(e['terms'])} (cross-validated gain {e['gain_mm']:.3f} mm)"
                     + (f"; on this data the same terms on {', '.join(others)} fit equally well" if others else ""))
    lines += ["", "The truth's rail waviness (0.45 m period on the lateral axis), the payload's effect and the bending "
                  "that grows with the longitudinal extension under payload are found without being declared."]
    (ROOT / "docs" / "paper-reproduction.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
