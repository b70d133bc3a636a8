"""What a command loads: one whose compiled code is in the cache reads its robot, error model and
data, and fits, evaluates or compensates, without sympy, jinja2 or the emitter (they took about a
second of every run; speed itself is measured in benchmarks/bench_startup.py)."""
import json
import os
import shutil
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

#: runs each command line given (a JSON list of argument lists) in one process, exit code 0 or 1
#: each, then prints the heavy modules the runs loaded
WRAPPER = ("import json, sys\nfrom gecgen.cli import main\nfor args in json.loads(sys.argv[1]):\n"
           "    assert main(args) in (0, 1), args\n"
           "print(sorted(m for m in ('sympy', 'jinja2', 'gecgen.emit') if m in sys.modules))")

ROBOT = """name: arm3
angle_unit: deg
joints:
  - {type: R, theta: 0, d: 0.4, a: 0.1, alpha: 90, limits: [-170, 170]}
  - {type: R, theta: 0, d: 0, a: 0.5, alpha: 0, limits: [-100, 100]}
  - {type: R, theta: 0, d: 0, a: 0.4, alpha: 0, limits: [-150, 150]}
targets:
  a: [0.05, 0, 0]
  b: [0, 0.05, 0]
"""


def _arm3(folder):
    """arm3.yaml and 40 simulated poses of it, data.csv, in folder; the robot."""
    from gecgen.model import load_robot
    from gecgen.model.kinematics import target_positions

    (folder / "arm3.yaml").write_text(ROBOT)
    robot = load_robot(folder / "arm3.yaml")
    rng = np.random.default_rng(3)
    q = rng.uniform(-1.2, 1.2, (40, 3))
    P = target_positions(robot, q) + rng.normal(0, 1e-5, (40, 2, 3))  # (poses, targets, xyz)
    rows = [f"{i},{','.join(map(str, q[i].tolist()))},{t},{','.join(map(str, P[i, k].tolist()))}"
            for i in range(40) for k, t in enumerate("ab")]
    (folder / "data.csv").write_text("\n".join(["pose,q1,q2,q3,target,x,y,z", *rows]) + "\n")
    return robot


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """A folder with arm3.yaml, its data.csv and commands cmd.csv, and `cache`, a code cache holding
    the default model's compiled code (the first run's work), shared by this module's tests."""
    from gecgen.runtime.compiled import CompiledModel
    from gecgen.symbolic.terms import load_error_model

    folder = tmp_path_factory.mktemp("warm")
    robot = _arm3(folder)
    (folder / "cmd.csv").write_text("q1,q2,q3\n0.1,0.2,0.3\n-0.4,0.5,0.6\n")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GECGEN_CACHE", str(folder / "cache"))
        CompiledModel(robot, load_error_model(None, robot))
    return folder


def _warmed(warm, tmp_path, monkeypatch):
    """The robot, data and commands of `warm` copied into tmp_path (each test's outputs apart), and
    its code cache in use."""
    for name in ("arm3.yaml", "data.csv", "cmd.csv"):
        shutil.copy(warm / name, tmp_path / name)
    monkeypatch.setenv("GECGEN_CACHE", str(warm / "cache"))


def test_a_command_whose_code_is_cached_loads_no_sympy_jinja2_or_emitter(warm, tmp_path, monkeypatch):
    _warmed(warm, tmp_path, monkeypatch)
    # identify, and then on its calibration evaluate and compensate (which a three-joint arm cannot
    # do whole: it corrects what it can and exits 1)
    runs = [["identify", "arm3.yaml", "data.csv", "-o", "c.json", "--json"], ["evaluate", "c.json", "data.csv"],
            ["compensate", "c.json", "cmd.csv", "-o", "q.csv"]]
    done = subprocess.run([sys.executable, "-c", WRAPPER, json.dumps(runs)], capture_output=True, text=True,
                          cwd=tmp_path, env=os.environ, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout + done.stderr
    assert json.loads(done.stdout.splitlines()[0])["n_params"] > 0 and (tmp_path / "q.csv").is_file()


#: the commands whose parser is built without numpy (the others' modules compute with it at the top)
LIGHT = ("identify", "calibrate", "diagnose", "evaluate", "compensate", "check", "accuracy", "filter")


def test_building_any_commands_parser_loads_no_sympy():
    """The parser is built for the command run only (`build_parser(argv)`), and building it, for any
    command, loads no computer algebra, no emitter and neither scipy.optimize nor scipy's rotations,
    and for those in LIGHT not even numpy: `gecgen X --help` answers at once."""
    code = ("import sys\nfrom gecgen.cli import COMMANDS, build_parser\n"
            f"for name in sorted(COMMANDS, key=lambda c: c not in {LIGHT!r}):\n"
            "    assert len(build_parser([name])._subparsers._group_actions[0].choices[name]._actions) > 2\n"
            f"    assert name not in {LIGHT!r} or 'numpy' not in sys.modules, name\n"
            "print(sorted(m for m in ('sympy', 'jinja2', 'gecgen.emit', 'scipy.optimize', 'scipy.spatial') "
            "if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and done.stdout.strip() == "[]", done.stdout + done.stderr


#: runs one command line (a JSON list) with no backend chosen, then prints what it loaded and the
#: background builds it started
FIRST = ("import json, sys\nfrom gecgen.cli import main\nfrom gecgen.runtime import compiled\n"
         "assert main(json.loads(sys.argv[1])) == 0\n"
         "print(json.dumps({'loaded': sorted(m for m in ('sympy', 'jinja2', 'gecgen.emit') if m in sys.modules),"
         " 'builds': [p.pid for p in compiled._background.values()]}))")


def _running(pid: int) -> bool:
    """Whether a process runs (one that has ended but was not reaped yet, a zombie, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_a_new_robot_is_fitted_in_numpy_while_its_c_is_built_in_the_background(tmp_path):
    """The first run of a robot (an empty cache, no backend chosen) loads no sympy, jinja2 or emitter,
    and leaves one process building the C, which ends; the next run uses that C (it starts no build)
    and fits the same to 1e-9 mm."""
    _arm3(tmp_path)
    env = {k: v for k, v in os.environ.items() if k != "GECGEN_BACKEND"} | {"GECGEN_CACHE": str(tmp_path / "cache")}
    runs = []
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", FIRST, json.dumps(["identify", "arm3.yaml", "data.csv", "-o",
                                                                        "c.json", "--json"])],
                              capture_output=True, text=True, cwd=tmp_path, env=env, timeout=600)
        assert done.returncode == 0, done.stderr
        fit, ran = (json.loads(line) for line in done.stdout.strip().splitlines()[-2:])
        runs.append((fit, ran))
        for pid in ran["builds"]:
            deadline = time.monotonic() + 300
            while _running(pid) and time.monotonic() < deadline:
                time.sleep(0.1)
            assert not _running(pid), "the background build did not end"
    (first, cold), (second, warm) = runs
    assert cold == {"loaded": [], "builds": cold["builds"]} and len(cold["builds"]) == 1
    assert warm == {"loaded": [], "builds": []}
    assert len(list((tmp_path / "cache").glob("arm3-*.so"))) == 1
    assert first["n_params"] == second["n_params"] > 0
    assert abs(first["train"]["rms_mm"] - second["train"]["rms_mm"]) < 1e-9


def test_exporting_the_c_of_a_calibration_whose_code_is_cached_loads_no_sympy(warm, tmp_path, monkeypatch):
    """`export --c` (what calibrate writes into its folder) renders the printed code the cache kept and
    the calibration's header and example: jinja2 and the emitter, but no computer algebra."""
    _warmed(warm, tmp_path, monkeypatch)
    runs = [["identify", "arm3.yaml", "data.csv", "-o", "c.json"], ["export", "c.json", "--c", "gen"]]
    code = WRAPPER.replace("('sympy', 'jinja2', 'gecgen.emit')", "('sympy',)")
    done = subprocess.run([sys.executable, "-c", code, json.dumps(runs)], capture_output=True, text=True,
                          cwd=tmp_path, env=os.environ, timeout=600)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout + done.stderr
    assert (tmp_path / "gen" / "arm3_calibration.h").is_file() and (tmp_path / "gen" / "arm3.c").is_file()


def test_a_command_loads_only_the_scipy_it_computes_with(warm, tmp_path, monkeypatch):
    """Compensating with a calibration (warm cache) loads no scipy at all, and scoring one or fitting
    one, weak directions held too, neither scipy.optimize nor scipy's rotations: each is a tenth of a
    second or more of every start-up."""
    from gecgen.api import Calibrator

    _warmed(warm, tmp_path, monkeypatch)
    with warnings.catch_warnings():  # the coefficients 40 poses leave undetermined are said, not tested, here
        warnings.simplefilter("ignore")
        Calibrator().fit(tmp_path / "arm3.yaml", tmp_path / "data.csv").save(tmp_path / "c.json")
    code = ("import sys\nfrom gecgen.cli import main\n"
            "assert main(['compensate', 'c.json', 'cmd.csv', '-o', 'q.csv']) in (0, 1)\n"
            "print('loaded', sorted(m for m in sys.modules if m.split('.')[0] in ('scipy', 'sympy')))\n"
            "assert main(['evaluate', 'c.json', 'data.csv']) == 0\n"
            "assert main(['identify', 'arm3.yaml', 'data.csv', '-o', 'again.json']) == 0\n"
            # what a fit that holds weak directions computes besides: why (the tool's turn) and the noise's limit
            "import numpy\nfrom gecgen.fit import identify, weak\nfrom gecgen.model import load_robot\n"
            "assert weak.tool_turn(load_robot('arm3.yaml'), numpy.zeros((3, 3))) < 1e-6\n"
            "assert 6.6 < identify.noise_rise_limit(1) < 6.7\n"
            "print('loaded', sorted(m for m in ('scipy.optimize', 'scipy.spatial', 'sympy') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=os.environ,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    assert [line for line in done.stdout.splitlines() if line.startswith("loaded")] == ["loaded []"] * 2, \
        done.stdout + done.stderr
    assert (tmp_path / "q.csv").is_file()


def test_an_error_model_of_load_functions_is_read_without_sympy(warm, tmp_path):
    """A model whose terms are load signals (the gravity shorthand expanded, a product with a signal) is
    read, its terms not cached yet, without sympy, into the terms the term parser reads."""
    from gecgen.model import load_robot
    from gecgen.symbolic.parse import parse_model
    from gecgen.model.validation import read_yaml

    model = tmp_path / "loads.errors.yaml"
    model.write_text('default: ["1"]\nframes:\n  2: {er: ["1", "gravity(q2)", "wrench_torque(q2)"]}\n'
                     '  3: ["1", "q3*wrench_torque(q3)", "wrench_load(2, mx)"]\n')
    code = ("import json, sys\nfrom gecgen.model import load_robot\n"
            "from gecgen.symbolic.terms import load_error_model\n"
            "m = load_error_model(sys.argv[1], load_robot(sys.argv[2]))\n"
            "print(json.dumps([[[t.text, t.label, list(t.variables)] for t in ts] for ts in m.terms]))\n"
            "print('sympy' in sys.modules)")
    env = {**os.environ, "GECGEN_CACHE": str(tmp_path / "cache")}  # empty: the terms are read, not recalled
    done = subprocess.run([sys.executable, "-c", code, str(model), str(warm / "arm3.yaml")], capture_output=True,
                          text=True, env=env, timeout=600)
    assert done.returncode == 0, done.stderr
    terms, loaded = done.stdout.strip().splitlines()
    assert loaded == "False"
    parsed, _ = parse_model(read_yaml(model, "error-model"), load_robot(warm / "arm3.yaml"), str(model))
    assert json.loads(terms) == [[[t.text, t.label, list(t.variables)] for t in ts] for ts in parsed]
    assert sum(t.text.startswith("gravity(q2,") for t in parsed[6 * 2 + 4]) >= 2  # the shorthand expanded
