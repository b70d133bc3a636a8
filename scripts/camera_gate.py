"""Whether the significance gate should hold coefficients of a pixel fit by default: the set-ups of
scripts/reproduce_camera.py (its docstring) over more seeds, each fitted with and without the gate (fit and
oracle alike); writes the section "The significance gate on pixels" of docs/camera.md.

    python scripts/camera_gate.py [--seeds 20] [--write-only]
"""
from __future__ import annotations

import argparse
import json
import warnings

import numpy as np

from reproduce_camera import NOISES, RICH_NOISE, ROOT, hand, world, write_section
from gecgen.model import load_robot
from gecgen.model.validation import read_yaml
from gecgen.simulate import load_truth
from gecgen.symbolic.terms import load_error_model

HEADING = "## The significance gate on pixels"
#: what each set-up is judged on: eye-in-hand in the fit's own world (the board fixes it), eye-to-hand
#: registered on the held-out points (its own world carries the base's errors in the cameras' poses)
JUDGED = {"eye-in-hand": "fit", "eye-to-hand": "fit_registered", "eye-in-hand-rich": "fit"}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--write-only", action="store_true", help="write docs/camera.md from the last run's figures")
    args = parser.parse_args()
    saved = ROOT / "out" / "camera" / "gate.json"
    if args.write_only:
        write(json.loads(saved.read_text()), args.seeds)
        return
    warnings.simplefilter("ignore")
    robot = load_robot(ROOT / "robots" / "industrial6r.yaml")
    truth = load_truth(read_yaml(ROOT / "robots" / "industrial6r.truth.yaml", "truth file"), robot)
    model = load_error_model(ROOT / "robots" / "constant.errors.yaml", robot)
    rich = load_error_model(ROOT / "robots" / "industrial6r.errors.yaml", robot)
    runs = [("eye-in-hand", hand, model, NOISES), ("eye-to-hand", world, model, NOISES),
            ("eye-in-hand-rich", hand, rich, (RICH_NOISE,))]
    rows = []
    for kind, run, errors, noises in runs:
        for noise in noises:
            for seed in range(args.seeds):
                row = {"kind": kind, "noise": noise, "seed": seed}
                for gate in (True, False):
                    r = run(robot, truth, errors, seed, noise, significance=gate)
                    key = "gate" if gate else "none"
                    row |= {f"{key}_{k}": r[k] for k in ("fit", "oracle", "fit_registered", "oracle_registered")}
                rows.append(row)
                print(json.dumps(row), flush=True)
    saved.parent.mkdir(parents=True, exist_ok=True)
    saved.write_text(json.dumps(rows))
    write(rows, args.seeds)


def write(rows: list[dict], seeds: int):
    lines = [HEADING, "", f"Written by `scripts/camera_gate.py`. The set-ups above, {seeds} seeds each, every one "
             "fitted twice on the same pixels: with the significance gate (the default: the coefficients the images "
             "do not determine, |value| / std below 2 after backward elimination, held at zero) and without it "
             "(`--keep-insignificant`), the oracle likewise. Held-out tool error (mm): eye-in-hand in the fit's own "
             "world, eye-to-hand registered on the held-out points (its own world carries the base's errors in the "
             "cameras' poses). *without / with*: the ratio of the two fits' held-out errors, seed by seed.", "",
             "| set-up | noise px | with the gate: median / worst mm | without: median / worst mm | without / with: "
             "median (range) | without worse in | fit / oracle with the gate: median, worst | without: median, "
             "worst |", "|---|---|---|---|---|---|---|---|"]
    for kind, what in JUDGED.items():
        for noise in sorted({r["noise"] for r in rows if r["kind"] == kind}):
            on = [r for r in rows if r["kind"] == kind and r["noise"] == noise]
            gate, none = (np.array([r[f"{k}_{what}"] for r in on]) for k in ("gate", "none"))
            ratio = none / gate
            oracle = what.replace("fit", "oracle")
            by = {k: np.array([r[f"{k}_{what}"] / r[f"{k}_{oracle}"] for r in on]) for k in ("gate", "none")}
            lines.append(f"| {kind} | {noise} | {np.median(gate):.3f} / {gate.max():.3f} | {np.median(none):.3f} / "
                         f"{none.max():.3f} | {np.median(ratio):.2f} ({ratio.min():.2f} to {ratio.max():.2f}) | "
                         f"{int(np.sum(ratio > 1))} of {len(on)} | {np.median(by['gate']):.2f}, {by['gate'].max():.2f} "
                         f"| {np.median(by['none']):.2f}, {by['none'].max():.2f} |")
    ratio = {(r["kind"], r["noise"]): [] for r in rows}
    for r in rows:
        ratio[r["kind"], r["noise"]].append(r[f"none_{JUDGED[r['kind']]}"] / r[f"gate_{JUDGED[r['kind']]}"])

    def said(kind):
        on = [(noise, v) for (k, noise), v in ratio.items() if k == kind]
        return (f"median {' and '.join(f'{np.median(v):.2f} at {noise} px' for noise, v in on)}; without worse in "
                f"{' and '.join(str(int(np.sum(np.array(v) > 1))) for _, v in on)} of {len(on[0][1])}")

    lines += ["", f"Against the truth, the gate costs the constant model eye-in-hand nothing the seeds resolve (without / "
              f"with: {said('eye-in-hand')}); it helps eye-to-hand ({said('eye-to-hand')}) and the richer model most "
              f"({said('eye-in-hand-rich')}). So it stays the default for pixels, as for a tracker. Eye-in-hand, the "
              "fit / oracle ratios that move away from 1.00 with the gate are not the fit growing worse against the "
              "truth: the gate holds different coefficients in the fit and in the oracle, which without it agree "
              "to the digit.", ""]
    write_section(HEADING, lines)


if __name__ == "__main__":
    main()
