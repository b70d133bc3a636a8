"""Designed against random poses on simulated robots; writes docs/pose-design.md (with figaroh side by side).

    python scripts/reproduce_design.py            # every robot, then figaroh (skipped without it)
    python scripts/reproduce_design.py --quick    # one seed, the smallest sizes: a smoke run

For each robot and seed: K uniform candidates within the joint limits (seeded); `design_poses`
chooses N of them; random choices of N, 2N and 4N poses come from the same candidates. Each
choice is measured on the truth robot (`gecgen.simulate`, noise included), identified with the
robot's error model, and judged on 500 fresh uniform validation poses: the RMS over their targets
of |true position - calibrated model|, the truth without noise (what the calibration gets wrong,
not the tracker). Medians over the seeds.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gecgen.model import load_error_model, load_robot  # noqa: E402
from gecgen.model.validation import read_yaml  # noqa: E402
from gecgen.runtime.compiled import CompiledModel  # noqa: E402
from gecgen.runtime.design import design_poses, uniform_candidates  # noqa: E402
from gecgen.runtime.identify import identify, position_errors  # noqa: E402
from gecgen.simulate import load_truth, random_design, simulate  # noqa: E402
from gecgen.simulate.designs import Design  # noqa: E402

DOC = ROOT / "docs" / "pose-design.md"
OUT = ROOT / "out" / "design"
SEEDS = 5
CANDIDATES = 2000
N_VALIDATION = 500
#: a geometric truth for the arm: constant errors and joint offsets, a tracker's noise
TIAGO_TRUTH = {"seed": 11, "constant": {"translation_std": 1.0e-3, "rotation_std": 1.0e-3},
               "joint_offsets": {"std": 1.0e-3}, "noise": {"repeatability": 3.0e-5, "tracker": 5.0e-5}}

CASES = [
    {"name": "pps", "robot": "robots/pps.yaml", "errors": "robots/pps.errors.yaml", "truth": "robots/pps.truth.yaml",
     "targets": ("t1", "t2", "t3"), "payloads": (0.0, 70.0), "sizes": (30, 60, 120),
     "label": "PPS, default model (quadratic in each joint, linear in the wrench), 3 targets, payload 0 or 70 kg"},
    {"name": "industrial6r", "robot": "robots/industrial6r.yaml", "errors": "robots/industrial6r.errors.yaml",
     "truth": "robots/industrial6r.truth.yaml", "targets": ("smr",), "payloads": None, "sizes": (40, 80, 160),
     "label": "industrial6r, default model (no payload: its wrench terms are unexcited), one SMR"},
    {"name": "tiago", "robot": "robots/tiago.yaml", "errors": "robots/tiago.errors.yaml", "truth": TIAGO_TRUTH,
     "targets": ("m1", "m2", "m3", "m4"), "payloads": None, "sizes": (8, 16, 32),
     "label": "TIAGo torso + 7-joint arm, constant model (6 constant errors per frame), 4 markers; geometric truth"},
]


def fitted_rms(cm, robot, truth, q, payload, targets, val, rng) -> float:
    """Validation RMS (mm) of the calibration identified from measuring the poses q (P, n)."""
    names = tuple(targets)
    data = simulate(robot, truth, Design(q, payload, np.zeros(3), names, np.array(["d"] * len(q))), rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = identify(cm, data)
    e = position_errors(cm, val, val.xyz, fit.c)
    return float(1e3 * np.sqrt(np.mean(e ** 2)))


def run_case(case: dict, seeds: int, sizes) -> dict:
    robot = load_robot(ROOT / case["robot"])
    spec = case["truth"] if isinstance(case["truth"], dict) else read_yaml(ROOT / case["truth"], "truth")
    truth = load_truth(spec, robot)
    model = load_error_model(ROOT / case["errors"], robot)
    cm = CompiledModel(robot, model)
    names = list(robot.targets)
    targets = np.array([names.index(t) for t in case["targets"]])
    exact = replace(truth, repeatability=0.0, tracker=0.0)
    rows = {"design": {n: [] for n in sizes}, "random": {n: [] for m in sizes for n in (m, 2 * m, 4 * m)},
            "pred_design": {n: [] for n in sizes}, "pred_random": {n: [] for n in sizes}, "seconds": {n: [] for n in sizes}}
    for seed in range(seeds):
        rng = np.random.default_rng(1000 + seed)
        cands = uniform_candidates(robot, CANDIDATES, rng, case["payloads"], truth.gravity)
        payload = cands.payload_kg if cands.payload_kg is not None else np.zeros(len(cands))
        v = random_design(robot, N_VALIDATION, rng, case["payloads"] or (0.0,), targets=case["targets"])
        val = simulate(robot, exact, v, rng)
        for n in sizes:
            t0 = time.perf_counter()
            d = design_poses(cm, cands, n, targets, seed=seed)
            rows["seconds"][n].append(time.perf_counter() - t0)
            rows["design"][n].append(fitted_rms(cm, robot, truth, cands.q[d.chosen], payload[d.chosen],
                                                case["targets"], val, rng))
            for key in ("design", "random"):  # None: a singular design (infinite uncertainty)
                rows[f"pred_{key}"][n].append(d.predicted_std_mm[key]["rms_mm"] or np.inf)
        for n in rows["random"]:
            pick = rng.choice(len(cands), n, replace=False)
            rows["random"][n].append(fitted_rms(cm, robot, truth, cands.q[pick], payload[pick], case["targets"], val, rng))
        print(f"{case['name']} seed {seed}: " + ", ".join(f"design {n} {rows['design'][n][-1]:.4f}" for n in sizes),
              flush=True)
    return {"robot": case["name"], "label": case["label"], "k": None,
            **{key: {str(n): float(np.median(v)) for n, v in table.items()} for key, table in rows.items()}}


def poses_to_match(random: dict, rms: float) -> float | None:
    """Random poses needed for a validation RMS (log-log interpolation of the median curve);
    None when even the largest random set does not reach it."""
    n = np.array(sorted(int(k) for k in random))
    r = np.array([random[str(k)] for k in n])
    if rms >= r[0]:
        return float(n[0]) if rms == r[0] else None if not np.isfinite(rms) else float(n[0])
    for a, b in zip(range(len(n) - 1), range(1, len(n))):
        if r[b] <= rms <= r[a]:
            t = (np.log(rms) - np.log(r[a])) / (np.log(r[b]) - np.log(r[a]))
            return float(np.exp(np.log(n[a]) + t * (np.log(n[b]) - np.log(n[a]))))
    return None


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results = [run_case(c, 1 if args.quick else SEEDS, c["sizes"][:1] if args.quick else c["sizes"]) for c in CASES]
    (OUT / "curves.json").write_text(json.dumps(results, indent=1))
    print(f"curves took {time.perf_counter() - t0:.0f} s", flush=True)


if __name__ == "__main__":
    main()
