"""Whether the significance gate should hold coefficients of a pixel fit by default: the eye-in-hand set-up
of scripts/reproduce_camera.py (its docstring) over more seeds, each fitted with and without the gate
(fit and oracle alike); prints each run and a summary, the figures docs/camera.md quotes.

    python scripts/camera_gate.py [--seeds 20] [--first 5]
"""
from __future__ import annotations

import argparse
import json
import warnings

import numpy as np

from reproduce_camera import NOISES, ROOT, hand
from gecgen.model import load_robot
from gecgen.model.validation import read_yaml
from gecgen.simulate import load_truth
from gecgen.symbolic.terms import load_error_model


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first", type=int, default=0, help="the first seed")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    robot = load_robot(ROOT / "robots" / "industrial6r.yaml")
    truth = load_truth(read_yaml(ROOT / "robots" / "industrial6r.truth.yaml", "truth file"), robot)
    model = load_error_model(ROOT / "robots" / "constant.errors.yaml", robot)
    rows = []
    for noise in NOISES:
        for seed in range(args.first, args.first + args.seeds):
            row = {"noise": noise, "seed": seed}
            for gate in (True, False):
                r = hand(robot, truth, model, seed, noise, significance=gate)
                key = "gate" if gate else "none"
                row |= {f"{key}_fit": r["fit"], f"{key}_oracle": r["oracle"],
                        f"{key}_fit_registered": r["fit_registered"], f"{key}_oracle_registered": r["oracle_registered"]}
            rows.append(row)
            print(json.dumps(row), flush=True)
    for noise in NOISES:
        on = [r for r in rows if r["noise"] == noise]
        for key in ("gate", "none"):
            fit = np.array([r[f"{key}_fit"] for r in on])
            ratio = fit / np.array([r[f"{key}_oracle"] for r in on])
            reg = np.array([r[f"{key}_fit_registered"] for r in on])
            print(f"{noise} px, {'with' if key == 'gate' else 'without'} the gate: held-out fit median "
                  f"{np.median(fit):.3f} mm, worst {fit.max():.3f} mm (registered median {np.median(reg):.3f}, worst "
                  f"{reg.max():.3f}); fit / oracle median {np.median(ratio):.2f}, worst {ratio.max():.2f}, "
                  f"{int(np.sum(ratio <= 1.2))} of {len(on)} within 1.2")
        for what in ("fit", "fit_registered"):
            gain = np.array([r[f"none_{what}"] / r[f"gate_{what}"] for r in on])
            print(f"{noise} px, {what.replace('_', ' ')}: held-out without / with the gate median "
                  f"{np.median(gain):.2f}, range {gain.min():.2f} to {gain.max():.2f}, worse without in "
                  f"{int(np.sum(gain > 1))} of {len(on)}")


if __name__ == "__main__":
    main()
