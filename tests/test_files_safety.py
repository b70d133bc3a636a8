"""Files gecgen reads back and writes: cache entries are checked before use, an unwritable cache
falls back to a temporary one, outputs are checked before any work, and calibration files are
refused unless every number they apply is sound; a checkout that moved still loads."""
import hashlib
import json
import os
import shutil

import numpy as np
import pytest
from conftest import ROBOTS, random_q
from test_cli import gecgen

from gecgen.cli import main
from gecgen.emit import render
from gecgen.model import ModelError, load_robot
from gecgen.symbolic.terms import load_error_model
from gecgen.model.kinematics import target_positions
from gecgen.fit import calibration
from gecgen.runtime.compiled import CompiledModel, load_casadi_module, model_key, shared_library
from gecgen.fit.identify import redundancy


@pytest.fixture
def puma():
    robot = load_robot(ROBOTS / "puma560.yaml")
    return robot, load_error_model(ROBOTS / "constant.errors.yaml", robot)


@pytest.fixture
def own_cache(tmp_path, monkeypatch, puma):
    """A cache folder of this test's own, holding the compiled puma560 (copied: building it is slow)."""
    robot, model = puma
    lib = shared_library(robot, model, model_key(robot, model))
    cache = tmp_path / "cache"
    cache.mkdir()
    for entry in (lib, lib.with_name(lib.name + ".sha256")):
        shutil.copy(entry, cache)
    monkeypatch.setenv("GECGEN_CACHE", str(cache))
    return cache


def truncate(path):
    """Keep the first half of a file, through a new file: a library this process mapped stays intact."""
    half = path.read_bytes()[:path.stat().st_size // 2]
    path.unlink()
    path.write_bytes(half)


def test_a_truncated_library_in_the_cache_is_rebuilt_not_loaded(puma, own_cache, rng):
    robot, model = puma
    (lib,) = own_cache.glob("puma560-*.so")
    truncate(lib)  # loading this with ctypes is a SIGBUS or an OSError
    cm = CompiledModel(robot, model)
    q, eps = random_q(robot, rng, 5), rng.normal(0, 1e-3, (5, robot.n_errors))
    np.testing.assert_allclose(cm.J_e(q, eps)[0], target_positions(robot, q, eps), atol=1e-12)
    assert lib.with_name(lib.name + ".sha256").read_text().strip() == hashlib.sha256(lib.read_bytes()).hexdigest()


def test_a_truncated_library_whose_checksum_matches_is_rebuilt_not_loaded(puma, own_cache):
    """The sidecar rewritten to match the truncated bytes (a copy or restore of both): the library's
    own headers tell it is not whole. Run in a subprocess: loading it is a SIGBUS."""
    import subprocess
    import sys

    (lib,) = own_cache.glob("puma560-*.so")
    truncate(lib)
    lib.with_name(lib.name + ".sha256").write_text(hashlib.sha256(lib.read_bytes()).hexdigest() + "\n")
    run = subprocess.run([sys.executable, "-m", "gecgen.cli", "redundancy", str(ROBOTS / "puma560.yaml"), "--errors",
                          str(ROBOTS / "constant.errors.yaml"), "--json"], capture_output=True, text=True,
                         env={**os.environ, "GECGEN_CACHE": str(own_cache)})
    assert run.returncode == 0, (run.returncode, run.stderr[-2000:])
    assert json.loads(run.stdout)["n_params"] == 42


def test_broken_casadi_module_and_structural_analysis_are_recomputed(puma, own_cache):
    robot, model = puma
    files = render(robot, model)
    load_casadi_module(files, robot.name)
    (module,) = own_cache.glob(f"{robot.name}_casadi_*.py")
    truncate(module)  # a SyntaxError if imported
    assert "J_e" in load_casadi_module(files, robot.name).functions()
    cm = CompiledModel(robot, model)
    first = redundancy(cm)
    (entry,) = own_cache.glob(f"{robot.name}-structural-*.json")
    for broken in (entry.read_text()[:100], '{"names": ["x"], "kept": [0], "eliminated": []}'):
        entry.write_text(broken)
        assert redundancy(cm) == first
        assert json.loads(entry.read_text())["names"] == list(first.names)


def _unwritable(tmp_path, how):
    if how == "under a file":
        (tmp_path / "file").write_text("")
        return tmp_path / "file" / "cache"
    folder = tmp_path / "read-only"
    folder.mkdir(mode=0o500)
    if os.access(folder, os.W_OK):
        pytest.skip("permissions are not enforced for this user (root)")
    return folder


@pytest.mark.parametrize("how", ["under a file", "read-only"])
def test_an_unwritable_cache_falls_back_to_a_temporary_folder_with_one_warning(tmp_path, monkeypatch, how):
    from gecgen.runtime.compiled import cache_dir

    cache = _unwritable(tmp_path, how)
    monkeypatch.setenv("GECGEN_CACHE", str(cache))
    with pytest.warns(UserWarning, match=f"the cache folder {cache} cannot be written") as caught:
        fallback = cache_dir()
        assert cache_dir() == fallback  # the same folder all run long, and said once
    assert len([w for w in caught if "cache folder" in str(w.message)]) == 1
    assert fallback != cache and os.access(fallback, os.W_OK)
    # on the command line: the job is done, and the warning is one line
    run = gecgen("redundancy", ROBOTS / "puma560.yaml", "--errors", ROBOTS / "constant.errors.yaml", "--json",
                 env={**os.environ, "GECGEN_CACHE": str(cache)})
    assert run.returncode == 0 and json.loads(run.stdout)["n_params"] == 42
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "warning: the cache folder" in lines[0] and "compiling into" in lines[0], run.stderr


def test_a_cache_set_with_an_unexpanded_tilde_is_in_the_home_folder(tmp_path, monkeypatch):
    """GECGEN_CACHE='~/gc' (quoted, or from a service's environment) is the home folder's gc, not a folder
    named '~' in the working folder."""
    from gecgen.runtime.compiled import cache_dir

    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("GECGEN_CACHE", "~/gc")
    monkeypatch.chdir(tmp_path)
    assert cache_dir() == tmp_path / "home" / "gc" and (tmp_path / "home" / "gc").is_dir()
    assert not (tmp_path / "~").exists()


@pytest.mark.parametrize("command, expect", [
    (["identify", ROBOTS / "pps.yaml", "missing.csv", "-o", "{folder}"], "is a folder; give a file name for the calibration"),
    (["compensate", "missing.json", "missing.csv", "-o", "{folder}"], "is a folder; give a file name"),
    (["diagnose", ROBOTS / "pps.yaml", "missing.csv", "-o", "{folder}"], "is a folder; give a file name"),
    (["diagnose", ROBOTS / "pps.yaml", "missing.csv", "--report", "{file}"], "is a file; give a folder for the report"),
    (["simulate", ROBOTS / "pps.yaml", "-o", "{file}/data.csv"], "is a file, not a folder; choose another location"),
    (["import", ROBOTS / "pps.yaml", "missing.csv", "--mapping", "m.yaml", "-o", "{folder}"], "is a folder"),
    (["gravity", ROBOTS / "pps.yaml", "missing.csv", "-o", "{file}/sub/out.csv"], "is a file, not a folder"),
    (["generate", ROBOTS / "pps.yaml", "-o", "{file}"], "is a file; give a folder for the generated code"),
])
def test_outputs_are_checked_before_any_work(tmp_path, command, expect):
    """The inputs are missing: a refusal of the output shows it was checked first."""
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("")
    args = [str(a).format(folder=tmp_path / "folder", file=tmp_path / "file") for a in command]
    run = gecgen(*args, "--json", cwd=tmp_path)
    lines = run.stderr.strip().splitlines()
    assert run.returncode != 0 and run.stdout == "" and len(lines) == 1, run.stderr
    assert expect in lines[0] and str(tmp_path) in lines[0]


def test_an_os_error_is_one_line_with_the_path(tmp_path):
    long_name = "x" * 300
    run = gecgen("generate", ROBOTS / "pps.yaml", "-o", long_name, "--json", cwd=tmp_path)
    lines = run.stderr.strip().splitlines()
    assert run.returncode != 0 and run.stdout == "" and len(lines) == 1, run.stderr
    assert lines[0] == f"gecgen generate: {long_name}: File name too long"


@pytest.fixture(scope="module")
def checkout(tmp_path_factory):
    """A folder with a robot file and a calibration made from it, by absolute path."""
    root = tmp_path_factory.mktemp("checkout")
    robot = root / "robots" / "puma560.yaml"
    robot.parent.mkdir()
    shutil.copy(ROBOTS / "puma560.yaml", robot)
    assert main(["simulate", str(robot), "--poses", "30", "-o", str(root / "train.csv")]) == 0
    assert main(["identify", str(robot), str(root / "train.csv"), "--errors", str(ROBOTS / "constant.errors.yaml"),
                 "-o", str(root / "out" / "c.json")]) == 0
    (root / "cmd.csv").write_text("q1,q2,q3,q4,q5,q6\n0.1,0.2,-0.3,0.4,0.5,0.6\n")
    return root


def test_a_moved_checkout_still_loads_and_a_changed_robot_is_still_refused(checkout, tmp_path):
    robot = tmp_path / "before" / "robots" / "puma560.yaml"
    robot.parent.mkdir(parents=True)
    shutil.copy(ROBOTS / "puma560.yaml", robot)
    assert main(["identify", str(robot), str(checkout / "train.csv"), "--errors", str(ROBOTS / "constant.errors.yaml"),
                 "-o", str(tmp_path / "before" / "out" / "c.json")]) == 0
    moved = tmp_path / "after"
    shutil.move(tmp_path / "before", moved)
    calib = calibration.load(moved / "out" / "c.json")
    assert calib.robot.source == str((moved / "robots" / "puma560.yaml").resolve())
    d = json.loads((moved / "out" / "c.json").read_text())
    with (moved / "robots" / "puma560.yaml").open("a") as fh:
        fh.write("# edited\n")
    with pytest.raises(ModelError, match="changed since this calibration was made"):
        calibration.load(moved / "out" / "c.json")
    del d["robot_file_relative"]  # a calibration of an older gecgen cannot follow the move
    (moved / "out" / "c.json").write_text(json.dumps(d))
    with pytest.raises(ModelError, match="is missing; restore it"):
        calibration.load(moved / "out" / "c.json")


def _edit(d, key, value):
    if key.startswith("coefficient "):
        name, field = key.split()[1:]
        next(c for c in d["coefficients"] if c["name"] == name)[field] = value
    else:
        d["registration"][key] = value


NAN_VALUE = ("coefficient 1.ex:1 value", float("nan"), "coefficient '1.ex:1': value NaN is not a finite number")
NULL_VALUE = ("coefficient 2.er:1 value", None, "coefficient '2.er:1': value null is not a finite number")


@pytest.mark.parametrize("command, key, value, expect", [
    ("compensate", *NAN_VALUE), ("compensate", *NULL_VALUE), ("evaluate", *NAN_VALUE), ("evaluate", *NULL_VALUE),
    ("evaluate", "coefficient 3.ey:1 value", "0.001", "coefficient '3.ey:1': value \"0.001\" is not a finite number"),
    ("evaluate", "coefficient 1.ex:1 std", float("inf"),
     "coefficient '1.ex:1': std Infinity is neither a finite number nor null"),
    ("compensate", "rotation", [[1, 0, 0], [0, 1, 0], [0, 0, -1]], "registration.rotation is not a proper rotation"),
    ("evaluate", "rotation", [[1, 0.01, 0], [0, 1, 0], [0, 0, 1]], "registration.rotation is not a proper rotation"),
    ("evaluate", "translation", [0, float("nan"), 0], "registration.translation: expected three finite numbers"),
])
def test_unsound_numbers_in_a_calibration_are_refused(checkout, tmp_path, command, key, value, expect):
    d = json.loads((checkout / "out" / "c.json").read_text())
    _edit(d, key, value)
    (tmp_path / "c.json").write_text(json.dumps(d))
    inputs = {"evaluate": [checkout / "train.csv"], "compensate": [checkout / "cmd.csv", "-o", tmp_path / "o.csv"]}
    run = gecgen(command, tmp_path / "c.json", *inputs[command], "--json")
    lines = run.stderr.strip().splitlines()
    assert run.returncode != 0 and run.stdout == "" and len(lines) == 1, run.stderr
    assert expect in lines[0] and str(tmp_path / "c.json") in lines[0] and "identify again" in lines[0]
    assert not (tmp_path / "o.csv").exists()


def test_a_calibration_that_overflows_fails_compensate_naming_the_row(checkout, tmp_path):
    """Every row is written, each holding its command with status 4 (nonfinite); the exit status and one
    line on stderr say so, naming the first row."""
    d = json.loads((checkout / "out" / "c.json").read_text())
    _edit(d, "coefficient 0.ex:1 value", 1e308)  # finite, so loaded; the tool position overflows
    (tmp_path / "c.json").write_text(json.dumps(d))
    run = gecgen("compensate", tmp_path / "c.json", checkout / "cmd.csv", "-o", tmp_path / "o.csv", "--json")
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 1 and len(lines) == 1, run.stderr
    assert "cmd.csv: row 2: the correction is not finite" in lines[0]
    summary = json.loads(run.stdout)
    written = (tmp_path / "o.csv").read_text().splitlines()
    commands = (checkout / "cmd.csv").read_text().splitlines()
    assert len(written) == len(commands) and summary["status_counts"] == {"nonfinite": len(commands) - 1}
    assert all(row == command + ",4," for row, command in zip(written[1:], commands[1:])), written[:3]


def test_a_library_built_for_another_machine_or_compiler_is_never_reused(puma, monkeypatch):
    """The cache key names the toolchain: a cache copied from another architecture, or kept across a
    compiler upgrade, builds anew instead of loading (or failing to load) the other's library."""
    from gecgen.runtime import compiled

    robot, model = puma
    here = model_key(robot, model)
    for other in (("aarch64", "Linux", "/usr/bin/cc", "cc 12"), ("x86_64", "Linux", "/usr/bin/cc", "cc 99")):
        monkeypatch.setattr(compiled, "toolchain", lambda: other)
        assert model_key(robot, model) != here
    monkeypatch.undo()
    assert model_key(robot, model) == here


def test_a_cache_lock_that_cannot_be_taken_does_not_fail_the_build(tmp_path, monkeypatch):
    """The lock beside a cache entry only spares repeated work: a lock file another user owns, or a
    file system without locks, leaves each process to build its own entry, never a failure."""
    import fcntl

    import gecgen.runtime.compiled as compiled

    real_open = os.open

    def refuse_locks(path, *args, **kwargs):
        if str(path).endswith(".lock"):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(compiled.os, "open", refuse_locks)
    assert compiled._built(tmp_path / "a.bin", lambda: b"built").read_bytes() == b"built"
    monkeypatch.setattr(compiled.os, "open", real_open)
    monkeypatch.setattr(fcntl, "flock", lambda *args: (_ for _ in ()).throw(OSError(37, "No locks available")))
    assert compiled._built(tmp_path / "b.bin", lambda: b"built too").read_bytes() == b"built too"
    assert compiled._built(tmp_path / "b.bin", lambda: b"not again").read_bytes() == b"built too"  # an entry is kept


def _folder(root, files: dict) -> dict:
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    return {str(p.relative_to(root)): p.read_text() for p in sorted(root.rglob("*")) if p.is_file()}


def test_an_output_folder_is_replaced_whole_keeping_the_users_own_files(tmp_path):
    from gecgen.model.files import output_folder

    out = tmp_path / "cal"
    _folder(out, {"calibration.json": "old", "old_figure.png": "old", "generated/a.c": "old",
                  "notes.txt": "mine", "controller/x.c": "mine"})
    with output_folder(out, "calibration folder") as build:
        assert not (out / "new_figure.png").exists()  # nothing of the new run is seen before it is done
        _folder(build, {"calibration.json": "new", "new_figure.png": "new", "generated/b.c": "new"})
    got = {str(p.relative_to(out)): p.read_text() for p in sorted(out.rglob("*")) if p.is_file()}
    assert got == {"calibration.json": "new", "new_figure.png": "new", "generated/b.c": "new",
                   "notes.txt": "mine", "controller/x.c": "mine"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal"]  # no lock, no build folder left


@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt(), ModelError("bad")])
@pytest.mark.parametrize("existed", [True, False])
def test_an_output_folder_whose_writing_fails_is_left_as_it_was(tmp_path, error, existed):
    from gecgen.model.files import output_folder

    out = tmp_path / "cal"
    before = _folder(out, {"calibration.json": "old", "report.md": "old"}) if existed else None
    with pytest.raises(type(error)):
        with output_folder(out, "calibration folder") as build:
            (build / "calibration.json").write_text("new")  # the report not yet written
            raise error
    assert (_folder(out, {}) if existed else out.exists()) == (before if existed else False)
    assert sorted(p.name for p in tmp_path.iterdir()) == (["cal"] if existed else [])


def test_a_second_writer_of_an_output_folder_is_refused_naming_it(tmp_path):
    from gecgen.model.files import output_folder, output_lock

    out = tmp_path / "cal"
    with output_lock(out, "calibration folder"):
        with pytest.raises(ModelError) as exc:
            with output_folder(out, "calibration folder"):
                pass
        assert str(exc.value) == (f"{out}: another gecgen run is writing this calibration folder now; wait for it "
                                  f"to finish, or give another folder")
    with output_folder(out, "calibration folder") as build:  # released: taken again
        (build / "x").write_text("x")
    assert (out / "x").is_file()


def test_what_a_killed_run_left_beside_a_folder_goes_with_the_next_run(tmp_path):
    from gecgen.model.files import output_folder

    out = tmp_path / "cal"
    _folder(out, {"calibration.json": "old"})
    _folder(tmp_path / ".cal.gecgen-build-1-abcd", {"calibration.json": "half"})
    (tmp_path / ".cal.gecgen-lock").write_text("")  # its lock file, no longer held by anyone
    with output_folder(out, "calibration folder") as build:
        (build / "calibration.json").write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal"] and (out / "calibration.json").read_text() == "new"


def test_an_output_folder_reached_through_a_link_is_replaced_where_it_is(tmp_path):
    from gecgen.model.files import output_folder

    real = tmp_path / "disk" / "cal"
    _folder(real, {"calibration.json": "old"})
    (tmp_path / "cal").symlink_to(real, target_is_directory=True)
    with output_folder(tmp_path / "cal", "calibration folder") as build:
        (build / "calibration.json").write_text("new")
    assert (tmp_path / "cal").is_symlink() and (real / "calibration.json").read_text() == "new"
    assert sorted(p.name for p in real.parent.iterdir()) == ["cal"]
