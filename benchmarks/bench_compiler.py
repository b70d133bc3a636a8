"""Compiler benchmark: generate time per robot, J_e / H_e per pose in C, CasADi and numpy, and the
load signals (NAME_loads) per pose in C next to J_e.

    python benchmarks/bench_compiler.py      # prints a table, updates docs/benchmarks.md

Times are the best of several repeats on warm caches (the first call of a batch also pays for
page faults on its output arrays). The numpy baseline is central finite differences of the exact
chain (gecgen.model.kinematics), batched over poses: what one would write without gecgen.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from bench_runtime import cpu_model, write_section  # noqa: E402

from gecgen.emit import render  # noqa: E402
from gecgen.model import load_robot  # noqa: E402
from gecgen.symbolic.terms import error_model_from_dict, load_error_model  # noqa: E402
from gecgen.model.loads import catalog  # noqa: E402
from gecgen.model.kinematics import target_positions  # noqa: E402
from gecgen.runtime.compiled import CFLAGS, COMPILE_FLAGS, CompiledModel, compiler  # noqa: E402

ROBOTS = ("pps", "industrial6r", "puma560")


def best(fn, repeats=5) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def generate_seconds(name: str) -> float:
    """A fresh process, as `gecgen generate` runs: imports, parsing, symbolic build, rendering, writing."""
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        subprocess.run([sys.executable, "-m", "gecgen.cli", "generate", str(ROOT / "robots" / f"{name}.yaml"),
                        "-o", tmp], check=True, capture_output=True)
        return time.perf_counter() - t


def compile_seconds(files: dict, name: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        for f in (f"{name}.c", f"{name}.h"):
            Path(tmp, f).write_text(files[f])
        t = time.perf_counter()
        subprocess.run([compiler(), *CFLAGS, f"{name}.c", "-o", "lib.so", "-lm"], cwd=tmp, check=True)
        return time.perf_counter() - t


def runtime_compile_seconds(robot, model) -> tuple[float, float]:
    """The runtime's build (`runtime.compiled.shared_library`), best of 3 each: the robot's chain compiled
    to an object file (once per robot), and a model's own code compiled and linked to it (each model)."""
    from gecgen.emit import printed, printed_chain, render_c_parts

    chain = printed_chain(robot)
    files = render_c_parts(robot, model, printed(robot, model, chain), len(chain["c"]))
    with tempfile.TemporaryDirectory() as tmp:
        for fname, text in files.items():
            Path(tmp, fname).write_text(text)

        def cc(*args: str) -> float:
            t = time.perf_counter()
            subprocess.run([compiler(), *args], cwd=tmp, check=True)
            return time.perf_counter() - t

        name = robot.name
        chain_s = min(cc(*COMPILE_FLAGS, "-c", f"{name}_chain.c", "-o", "chain.o") for _ in range(3))
        model_s = min(cc(*CFLAGS, f"{name}.c", "chain.o", "-o", "lib.so", "-lm") for _ in range(3))
    return chain_s, model_s


DRIVER = r"""
#include <math.h>
#include <stdio.h>
#include <time.h>
#include "%(name)s.h"
%(floor)s
static double seconds(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}
int main(void) {
    static double q[%(N)s_NQ], e[%(N)s_NE], p[3 * %(N)s_NT], J[3 * %(N)s_NT * %(N)s_NE];
    static double w[6] = {10, -20, 300, 1, -2, 3}, L[%(N)s_NL + 1];
    double sum = 0.0, best_J = 1e30, best_L = 1e30, best_F = 1e30, t;
    int rep, i, k;
    for (rep = 0; rep < 5; ++rep) {
        t = seconds();
        for (i = 0; i < 200000; ++i) {
            for (k = 0; k < %(N)s_NQ; ++k) q[k] = 1e-5 * i + 0.3 * k;
            for (k = 0; k < %(N)s_NE; ++k) e[k] = 1e-4 * k;
            %(name)s_J_e(q, e, p, J);
            sum += J[i %% (3 * %(N)s_NT * %(N)s_NE)];
        }
        t = (seconds() - t) / 200000 * 1e6;
        if (t < best_J) best_J = t;
        t = seconds();
        for (i = 0; i < 200000; ++i) {
            for (k = 0; k < %(N)s_NQ; ++k) q[k] = 1e-5 * i + 0.3 * k;
            %(name)s_loads(q, w, L);
            sum += L[i %% (%(N)s_NL + 1)];
        }
        t = (seconds() - t) / 200000 * 1e6;
        if (t < best_L) best_L = t;
        t = seconds();
        for (i = 0; i < 200000; ++i) {
            for (k = 0; k < %(N)s_NQ; ++k) q[k] = 1e-5 * i + 0.3 * k;
            for (k = 0; k < %(N)s_NE; ++k) e[k] = 1e-4 * k;
            floor_J_e(q, e, p, J);
            sum += J[i %% (3 * %(N)s_NT * %(N)s_NE)];
        }
        t = (seconds() - t) / 200000 * 1e6;
        if (t < best_F) best_F = t;
    }
    printf("%%.4f %%.4f %%.4f %%g\n", best_J, best_L, best_F, sum);
    return 0;
}
"""


def floor_source(c_text: str, name: str) -> str:
    """(C source, number of angles, number of stores) of a function that does only what NAME_J_e
    cannot avoid: the sine and cosine of every angle it takes them of (one sincos each, as the compiler
    merges them) and its stores, straight-line, each of a trig value: the floor J_e is measured against."""
    body = c_text[c_text.index(f"void {name}_J_e("):]
    body = body[:body.index("\n}\n")]
    angles = list(dict.fromkeys(re.findall(r"\bcos\((\w+\[\d+\])\)", body)))
    stores = re.findall(r"^\s*((?:J|p)\[\d+\]) = ", body, re.M)
    lines = ["static void floor_J_e(const double *q, const double *eps, double *p, double *J)", "{",
             "    (void)q; (void)eps;"]
    lines += [f"    const double s{i} = sin({a}), c{i} = cos({a});" for i, a in enumerate(angles)]
    lines += [f"    {x} = {'sc'[k % 2]}{(k // 2) % len(angles)};" for k, x in enumerate(stores)]
    return "\n".join(lines + ["}"]), len(angles), len(stores)


def c_loop_seconds(files: dict, name: str) -> tuple[float, float, float, int, int]:
    """J_e and the load signals per pose in a plain C loop (one pose's arrays reused, as in a
    controller), each the best of 5 x 200,000; then J_e's trig and store floor (`floor_source`) in the
    same loop, and its number of sincos and of stores."""
    floor, n_trig, n_stores = floor_source(files[f"{name}.c"], name)
    with tempfile.TemporaryDirectory() as tmp:
        for f in (f"{name}.c", f"{name}.h"):
            Path(tmp, f).write_text(files[f])
        Path(tmp, "driver.c").write_text(DRIVER % {"name": name, "N": name.upper(), "floor": floor})
        flags = [f for f in CFLAGS if f not in ("-shared", "-fPIC")]
        subprocess.run([compiler(), *flags, "-D_POSIX_C_SOURCE=199309L", "driver.c", f"{name}.c", "-o", "driver",
                        "-lm"], cwd=tmp, check=True)
        out = subprocess.run(["./driver"], cwd=tmp, check=True, capture_output=True, text=True).stdout
        J_e, loads, bound = (float(v) * 1e-6 for v in out.split()[:3])
        return J_e, loads, bound, n_trig, n_stores


def fd_jacobian(robot, q, h=1e-7):
    """Central differences of the exact chain for every generalized error, batched over poses."""
    J = np.empty((len(q), 3 * len(robot.targets), robot.n_errors))
    for k in range(robot.n_errors):
        e = np.zeros(robot.n_errors)
        e[k] = h
        J[:, :, k] = (target_positions(robot, q, e) - target_positions(robot, q, -e)).reshape(len(q), -1) / (2 * h)
    return J


def main():
    rng = np.random.default_rng(0)
    rows = []
    for name in ROBOTS:
        robot = load_robot(ROOT / "robots" / f"{name}.yaml")
        model = load_error_model(ROOT / "robots" / f"{name}.errors.yaml", robot)
        gen = min(generate_seconds(name) for _ in range(3))
        t = time.perf_counter()
        files = render(robot, model)
        symbolic = time.perf_counter() - t
        comp = compile_seconds(files, name)
        chain_cc, model_cc = runtime_compile_seconds(robot, model)
        c_model, ca_model = CompiledModel(robot, model, "c"), CompiledModel(robot, model, "casadi")
        lo = np.array([max(j.lower, -np.pi) for j in robot.joints])
        hi = np.array([min(j.upper, np.pi) for j in robot.joints])
        n_je, n_h, n_ca, n_fd = 20000, 2000, 20000, 2000
        q = rng.uniform(lo, hi, (n_je, robot.n))
        eps = rng.normal(0, 1e-3, (n_je, robot.n_errors))
        c = rng.normal(0, 1e-5, len(model.coefficients))
        w = rng.normal(0, 50, (n_h, 6))
        c_loop, _, c_floor, n_trig, n_stores = c_loop_seconds(files, name)
        # NAME_loads computes the signals the model's terms use: timed where they are all the robot supports
        n_loads = len(catalog(robot).names)
        every = error_model_from_dict({"default": ["1"], "frames": {0: {"ex": ["1", *catalog(robot).names]}}}, robot,
                                      "<every load signal>")
        c_loads = c_loop_seconds(render(robot, every), name)[1]
        c_je = best(lambda: c_model.J_e(q, eps)) / n_je
        c_h = best(lambda: c_model.model_targets(q[:n_h], w, None, c, with_H=True)) / n_h
        mapped = ca_model._ca["J_e"].map(n_ca)
        qT, eT = q[:n_ca].T.copy(), eps[:n_ca].T.copy()
        ca_je = best(lambda: mapped(qT, eT), 3) / n_ca
        fd = best(lambda: fd_jacobian(robot, q[:n_fd]), 3) / n_fd
        rows.append((name, len(robot.targets), len(model.coefficients), gen, symbolic, comp, chain_cc, model_cc, c_loop,
                     c_je, c_h, ca_je, fd, n_loads, c_loads, c_floor, n_trig, n_stores))
        print(f"{name:13s} targets {len(robot.targets)} coefficients {len(model.coefficients):4d} | generate "
              f"{gen:5.2f} s (symbolic+render {symbolic:4.2f} s) | cc {comp:5.2f} s (runtime: chain {chain_cc:4.2f} s, "
              f"model + link {model_cc:4.2f} s) | J_e C loop {1e6 * c_loop:6.3f} us, "
              f"C batch {1e6 * c_je:6.3f} us, "
              f"CasADi {1e6 * ca_je:6.2f} us, numpy FD {1e6 * fd:8.1f} us | H_e C {1e6 * c_h:6.2f} us | "
              f"{n_loads} loads C loop {1e6 * c_loads:6.3f} us ({c_loads / c_loop:.2f} x J_e) | floor "
              f"({n_trig} sincos + {n_stores} stores) {1e6 * c_floor:6.3f} us, J_e {c_loop / c_floor:.2f} x it")
    load_average = os.getloadavg()[0]  # other processes on the machine inflate the times
    cpu = cpu_model()
    lines = ["## Compiler: generate, and J_e / H_e per pose", "",
             f"Machine: {cpu}, {len(os.sched_getaffinity(0))} cores, load average {load_average:.1f} at the end. "
             "Regenerate: `python benchmarks/bench_compiler.py`. "
             "Each robot with its default error model (`robots/NAME.errors.yaml`). `generate` = a fresh "
             "`gecgen generate` process (imports, parsing, symbolic build, rendering, writing), best of 3; cc = "
             f"compiling the generated C with `{' '.join(CFLAGS)}`; the runtime instead compiles the robot's chain "
             "(its kinematics and J_e, `NAME_chain.c`) once to an object file (chain cc) and each model's own code "
             "linked to it (model cc), best of 3 each. C loop = a C driver calling NAME_J_e on one pose's "
             "arrays 200,000 times (what a controller sees), best of 5. The other per-pose times are the best of "
             "several batched calls: C through ctypes over 20,000 poses (J_e; the batch writes 3 nt x 6(n+1) doubles "
             "per pose to memory) and 2,000 poses (H_e, at eps(c), wrench included), "
             "CasADi's `Function.map` over 20,000 poses, and numpy central finite differences of the exact chain over "
             "2,000 poses. Loads = NAME_loads generated for a model whose terms use every load signal the robot "
             "supports (wrench torques, gravity regressor columns; a model's code computes only those its terms "
             "use), in the same C loop as J_e. Floor = J_e's own trig and stores alone (`floor_source`: one sin and "
             "cos of each angle J_e takes them of, merged into sincos by the compiler, and its stores, straight-line), "
             "in the same loop.", "",
             "| robot | targets | coefficients | generate (s) | symbolic + render (s) | cc (s) | "
             "runtime: chain cc (s) | runtime: model cc (s) | J_e C loop (us) | "
             "J_e C batch (us) | J_e CasADi (us) | J_e numpy FD (us) | CasADi / C batch | FD / C batch | "
             "H_e C batch (us) | load signals | loads C loop (us) | loads / J_e (C loop) | J_e floor: sincos + stores "
             "| floor (us) | J_e / floor |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for (name, nt, nc, gen, sym, comp, chain_cc, model_cc, c_loop, c_je, c_h, ca_je, fd, n_loads, c_loads, c_floor,
         n_trig, n_st) in rows:
        lines.append(f"| {name} | {nt} | {nc} | {gen:.2f} | {sym:.2f} | {comp:.2f} | {chain_cc:.2f} | {model_cc:.2f} | "
                     f"{1e6 * c_loop:.3f} | "
                     f"{1e6 * c_je:.3f} | {1e6 * ca_je:.2f} | {1e6 * fd:.1f} | {ca_je / c_je:.0f} | {fd / c_je:.0f} | "
                     f"{1e6 * c_h:.2f} | {n_loads} | {1e6 * c_loads:.3f} | {c_loads / c_loop:.2f} | "
                     f"{n_trig} + {n_st} | {1e6 * c_floor:.3f} | {c_loop / c_floor:.2f} |")
    lines += ["", "Targets: generate <= 10 s for a 6-joint robot with its default error model; C J_e <= 1 us per "
                  "pose for a 6-joint robot with 3 targets (puma560); the load signals <= 2 x J_e per pose."]
    write_section("compiler", "\n".join(lines))


if __name__ == "__main__":
    main()
