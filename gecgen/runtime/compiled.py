"""Load the generated code of a robot and error model, and call it on many poses at once.

The C source is built once per content hash with the system compiler into a cache folder
(`$GECGEN_CACHE`, default `~/.cache/gecgen`) and loaded with ctypes. Its chain (the kinematics and
J_e, two thirds of the compiler's time) is the same for every error model of a robot: it is compiled
once per robot into an object file that each model's own code is linked to, so a new model (each
round of diagnose, each candidate of calibrate) compiles only its own part. Two processes that want
the same entry build it once: the second waits for the first. Without a C compiler the
same functions come from the generated CasADi module, and a warning says so. A model whose library
is not in the cache yet runs on the numpy evaluation of the same functions (`runtime.numeric`: no
computer algebra, no compiler), while a detached process of the same Python builds its C for the
next run (`runtime.background`); `GECGEN_BACKEND` (c, numpy, casadi) chooses instead. Every cache entry is
checked against its content hash before it is used, and a library or object file against its
own headers (every byte they place is there): a truncated or corrupt entry is rebuilt, never loaded. A cache folder that cannot be written is replaced, with a warning, by a fresh
temporary folder for the rest of the run.
"""
from __future__ import annotations

import atexit
import contextlib
import ctypes
import functools
import hashlib
import importlib.util
import json
import os
import pickle
import platform
import shutil
import struct
import subprocess
import sys
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gecgen.model.files import cache_dir, cache_kept, write_atomically
from gecgen.model.errors import ErrorModel
from gecgen.model.loads import catalog, signal_values
from gecgen.model.robot import Robot
from gecgen.model.validation import ModelError, excerpt
from gecgen.runtime.numeric import BOUNDED, NONFINITE, NOT_CONVERGED, OK, OUTSIDE_LIMITS, SINGULAR, NumericModel

#: how every translation unit of the generated C is compiled
COMPILE_FLAGS = ["-std=c99", "-O2", "-fPIC", "-Wall", "-Wextra", "-Werror"]
#: and linked into a shared library
CFLAGS = [*COMPILE_FLAGS, "-shared"]

#: the environment variable that chooses the backend of `CompiledModel(..., backend="auto")`
BACKEND_VARIABLE = "GECGEN_BACKEND"
BACKENDS = ("auto", "c", "numpy", "casadi")

#: how many commands at most `CompiledModel.correct` corrects in numpy when the model's C is not built
#: yet (an example program's few: numpy takes milliseconds a command, up to 0.2 s near a singular posture,
#: and the compiler seconds); more wait for the C
NUMPY_COMMANDS = 64
#: each code's name in files and messages (the generated header's GECGEN_ codes, in lower case)
STATUS_NAMES = ("ok", "not_converged", "singular", "outside_limits", "nonfinite", "bounded")
#: the codes whose tool is not placed within the tolerance (OUTSIDE_LIMITS is placed, but leaves the
#: joint limits; SINGULAR and BOUNDED hold a correction that may be sent, the tool off by the residual)
FAILED = (NOT_CONVERGED, SINGULAR, NONFINITE, BOUNDED)


def _sha256_file(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def compiler() -> str | None:
    return os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")


@functools.cache
def _emitter_hash() -> str:
    """Hash of the code that decides what is generated: a change to it invalidates the cache (read
    once per process: every model's key and every robot's chain key use it)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    model = [root / "model" / f for f in ("errors.py", "robot.py", "robot_file.py", "urdf.py", "loads.py",
                                          "kinematics.py")]
    for path in sorted([*root.glob("symbolic/*.py"), *root.glob("emit/**/*.py"), *root.glob("emit/**/*.j2"), *model]):
        h.update(path.read_bytes())
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def toolchain() -> tuple[str, ...]:
    """What a compiled library is for: the machine, the system and the compiler (its path and the
    first line of its --version). A cache shared between machines, or kept across a compiler
    upgrade, then never hands over a library built for another."""
    cc = compiler() or ""
    try:
        version = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.SubprocessError):
        version = ""
    return platform.machine(), platform.system(), cc, (version.splitlines() or [""])[0]


def chain_key(robot: Robot) -> str:
    """Cache key of the printed code of a robot's own functions (`emit.printed_chain`): the robot's
    content (its files and targets) and the code that prints it."""
    spec = json.dumps([robot.source_hashes, robot.targets, _emitter_hash()], sort_keys=True)
    return hashlib.sha256(spec.encode()).hexdigest()[:24]


def model_key(robot: Robot, model: ErrorModel) -> str:
    """Cache key of the generated code for a robot and error model (content, not file names) on this
    toolchain. The targets are content beyond the files: a derived robot (the virtual targets of
    pose measurements) has the files of the robot it derives from."""
    spec = json.dumps([robot.source_hashes, robot.targets, model.to_yaml_dict(robot), CFLAGS, _emitter_hash(),
                       toolchain()], sort_keys=True)
    return hashlib.sha256(spec.encode()).hexdigest()[:24]


def _intact(path: Path) -> bool:
    """A cache entry is used only when its sidecar `.sha256`, written after it, matches its bytes,
    and a library or object file is whole by its own headers: loading a truncated library crashes
    the process (SIGBUS), and a sidecar can be rewritten to match a truncated file (a copy, a
    restore, a user's repair)."""
    try:
        data = path.read_bytes()
        sidecar = path.with_name(path.name + ".sha256").read_text().strip()
    except OSError:
        return False  # no entry, or half of one
    return hashlib.sha256(data).hexdigest() == sidecar and (path.suffix not in (".so", ".o") or _whole_binary(data))


def _whole_binary(data: bytes) -> bool:
    """Whether an ELF file holds everything its headers place in it: the program and section header
    tables, every segment's file bytes and every section's (but those that take no room, SHT_NOBITS).
    Where the platform's libraries are not ELF (macOS, Windows) the sidecar alone is the check."""
    if sys.platform == "darwin" or os.name == "nt":
        return True
    if len(data) < 64 or data[:4] != b"\x7fELF" or data[4] not in (1, 2) or data[5] not in (1, 2):
        return False
    wide = data[4] == 2  # ELFCLASS64; the offsets below are the ELF header's and entries' fields

    def unpack(fmt: str, at: int) -> tuple:
        return struct.unpack_from(("<" if data[5] == 1 else ">") + fmt.replace("W", "Q" if wide else "I"), data, at)

    phoff, shoff = unpack("WW", 0x20 if wide else 0x1C)
    phentsize, phnum, shentsize, shnum = unpack("HHHH", 0x36 if wide else 0x2A)
    if phoff + phnum * phentsize > len(data) or shoff + shnum * shentsize > len(data):
        return False
    segments = [unpack("WWWW", phoff + k * phentsize + (8 if wide else 4))[0::3] for k in range(phnum)]
    sections = [unpack("WW", shoff + k * shentsize + (0x18 if wide else 0x10)) for k in range(shnum)
                if unpack("I", shoff + k * shentsize + 4)[0] != SHT_NOBITS]
    return all(offset + size <= len(data) for offset, size in segments + sections)


#: an ELF section that takes no room in the file (.bss)
SHT_NOBITS = 8


def _store(path: Path, data: bytes):
    write_atomically(path, data)
    write_atomically(path.with_name(path.name + ".sha256"), hashlib.sha256(data).hexdigest() + "\n")


@contextlib.contextmanager
def _building(path: Path):
    """Held while the cache entry at path is built: a second process building the same entry waits
    for the first, then finds it built (`_intact`), rather than building it too (the forked workers
    of calibrate start on the same models). Where no lock can be taken (not POSIX, a lock file of
    another user, a file system without locks), each builds its own: the writes stay atomic, only
    the work is repeated."""
    try:
        import fcntl

        fd = os.open(path.with_name(path.name + ".lock"), os.O_RDONLY | os.O_CREAT, 0o666)
    except (ImportError, OSError):
        fd = None
    if fd is None:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:
            pass  # no locks here: built unguarded
        yield
    finally:
        os.close(fd)  # releases the lock


def _built(path: Path, build) -> Path:
    """The cache entry at path, its bytes built (`build()`) and stored on a miss, once across processes."""
    if not _intact(path):
        with _building(path):
            if not _intact(path):
                _store(path, build())
    return path


def _cached_json(path: Path, build):
    """The JSON at path in the cache (`build()` on a miss, stored with its key order: a function's
    outputs are in it)."""
    def stored() -> bytes:
        return json.dumps(build()).encode()

    try:
        return json.loads(_built(path, stored).read_text())
    except ValueError:  # written by another version of this code: built again
        path.unlink(missing_ok=True)
        return json.loads(_built(path, stored).read_text())


def chain_code(robot: Robot) -> dict[str, list[dict]]:
    """`emit.printed_chain` of a robot (cache key `chain_key`): its functions that no error model
    changes, nearly all of the symbolic work, built once per robot."""
    def build():
        from gecgen.emit import printed_chain  # the symbolic build: needed on a cache miss only

        return printed_chain(robot)

    return _cached_json(cache_dir() / f"{robot.name}-{chain_key(robot)}.chain.json", build)


def printed_code(robot: Robot, model: ErrorModel, key: str | None = None) -> dict[str, list[dict]]:
    """`emit.printed` for a robot and error model (cache key `model_key`), kept in the cache beside
    its library: the symbolic build and its printing run once per model content, not again for the
    files that export, diagnose and calibrate write (3 s of an 18-pose UR10 calibrate). A new model
    of a known robot prints only its own basis terms (`chain_code`)."""
    def build():
        from gecgen.emit import printed

        return printed(robot, model, chain_code(robot))

    return _cached_json(cache_dir() / f"{robot.name}-{key or model_key(robot, model)}.code.json", build)


def rendered(robot: Robot, model: ErrorModel, key: str | None = None) -> dict[str, str]:
    """`emit.render` of a robot and error model, its printed code from the cache (`printed_code`)."""
    from gecgen.emit import render

    return render(robot, model, printed_code(robot, model, key))


def _compiler_output(robot: Robot, files: dict[str, str | bytes], args: list[str]) -> bytes:
    """What the C compiler makes (its output `out`) of `files` (name -> text or bytes, written to a
    fresh folder) with `args`: flags, then the sources and objects."""
    with tempfile.TemporaryDirectory() as tmp:
        for fname, content in files.items():
            Path(tmp, fname).write_bytes(content if isinstance(content, bytes) else content.encode())
        run = subprocess.run([compiler(), *args, "-o", "out"], cwd=tmp, capture_output=True, text=True)
        if run.returncode != 0:
            raise RuntimeError(f"compiling the generated C for {robot.name} failed: {run.stderr.strip()}")
        return Path(tmp, "out").read_bytes()


def shared_library(robot: Robot, model: ErrorModel, key: str) -> Path:
    """The compiled generated C of a robot and error model (cache key `model_key`): the model's own
    code (`emit.render_c_parts`) compiled and linked to the robot's chain object (compiled once per
    robot and toolchain), each rendered and built only on a cache miss (`_intact`)."""
    name = robot.name

    def library() -> bytes:
        from gecgen.emit import render_c_parts  # jinja2 and the symbolic layer: needed on a cache miss only

        files = render_c_parts(robot, model, printed_code(robot, model, key), len(chain_code(robot)["c"]))
        source = f"{name}_chain.c"
        spec = json.dumps([chain_key(robot), COMPILE_FLAGS, toolchain()], sort_keys=True)
        chain = cache_dir() / f"{name}-{hashlib.sha256(spec.encode()).hexdigest()[:24]}.chain.o"
        obj = _built(chain, lambda: _compiler_output(robot, {source: files[source]}, [*COMPILE_FLAGS, "-c", source]))
        return _compiler_output(robot, {f"{name}.c": files[f"{name}.c"], f"{name}.h": files[f"{name}.h"],
                                        "chain.o": obj.read_bytes()}, [*CFLAGS, f"{name}.c", "chain.o", "-lm"])

    return _built(library_path(robot, key), library)


def library_path(robot: Robot, key: str) -> Path:
    """Where the cache keeps the shared library of a robot and model (cache key `model_key`)."""
    return cache_dir() / f"{robot.name}-{key}.so"


#: the background builds this process started (`build_in_background`), by the cache entry each builds
_background: dict[Path, subprocess.Popen] = {}


def build_in_background(robot: Robot, model: ErrorModel, key: str, alongside: bool = False) -> bool:
    """Start building the shared library of a robot and model in a detached process of this Python
    (`runtime.background`, at low priority; it outlives this one), unless one this process started for
    the same cache entry still runs, or any of its builds does (one at a time: the candidate models of
    diagnose and calibrate do not start a compiler each; `alongside`: start it all the same, for the
    model a command delivers), or the cache is this run's temporary folder (no next run would find the
    C). The cache's locks keep it from colliding with any other build of the entry. Whether one was
    started."""
    entry = library_path(robot, key)
    running = {e for e, p in _background.items() if p.poll() is None}
    if not cache_kept() or entry in running or not alongside and running:
        return False
    try:
        proc = subprocess.Popen([sys.executable, "-m", "gecgen.runtime.background"], stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                                env={**os.environ, "GECGEN_CACHE": str(cache_dir()), BACKEND_VARIABLE: "c"})
        with proc.stdin:
            pickle.dump((robot, model, key), proc.stdin)
    except OSError:  # no process to be had, or it ended at once: this run needs none, the next builds
        return False
    if not _background:
        atexit.register(_leave_builds)
    _background[entry] = proc
    return True


def _leave_builds():
    """Let go of the builds still running as this process ends (they are meant to outlive it): left to
    the interpreter's shutdown, each one's Popen said "ResourceWarning: subprocess N is still running"
    on stderr whatever the warning filters, after the command's own output."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        _background.clear()


def _ptr(a: np.ndarray | None):
    return None if a is None else a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


@dataclass
class Dims:
    nq: int
    nt: int
    ne: int
    nc: int
    naux: int


class CompiledModel:
    """Batch entry points over the generated code of one robot and error model.

    Shapes: q (N, nq), w (N, 6), aux (N, naux), c (nc,), eps (N, ne). Returned target arrays
    are (N, nt, 3); Jacobians (N, 3 nt, ne) and (N, 3 nt, nc).

    backend: "c" the compiled generated C (built first on a cache miss), "casadi" its CasADi form,
    "numpy" the numpy evaluation (`runtime.numeric`; compensation too for up to NUMPY_COMMANDS
    commands while the C is not built, else it loads the C, built first if it must be), "auto" the
    value of `$GECGEN_BACKEND` when set, else the C when its library is in the cache, numpy while a
    background process builds it when not, CasADi without a C compiler. build False:
    that background build is left to the caller (`c_pending` says it is wanted), e.g. until it has
    printed the model's code itself rather than wait for a fresh process to print it.
    """

    def __init__(self, robot: Robot, model: ErrorModel, backend: str = "auto", build: bool = True):
        robot.require_placed()
        self.robot, self.model = robot, model
        self.key = model_key(robot, model)
        self.dims = Dims(robot.n, len(robot.targets), robot.n_errors, len(model.coefficients), len(model.aux))
        if backend == "auto":
            backend = os.environ.get(BACKEND_VARIABLE) or "auto"
            if backend not in BACKENDS:
                raise ModelError(f"{BACKEND_VARIABLE}={excerpt(backend)} is not a backend; set it to "
                                 f"{', '.join(BACKENDS)}, or unset it")
        #: the C is not built and is left to a background build (`build_in_background`)
        self.c_pending = False
        if backend == "auto":
            backend = "casadi" if not compiler() else "c" if _intact(library_path(robot, self.key)) else "numpy"
            if backend == "casadi":
                warnings.warn("no C compiler found (set CC): using the CasADi form of the generated code, "
                              "which is slower", stacklevel=2)
            if backend == "numpy":
                self.c_pending = True
                if build:
                    build_in_background(robot, model, self.key)
        self.backend = backend
        if backend == "c":
            self._lib = ctypes.CDLL(str(shared_library(robot, model, self.key)))
        elif backend == "casadi":
            self._ca = load_casadi_module(rendered(robot, model, self.key), robot.name).functions()
        elif backend == "numpy":
            self._numeric, self._lib = NumericModel(robot, model), None
        else:
            raise ValueError(f"unknown backend {backend!r}; use {', '.join(BACKENDS)}")

    # -- argument handling -------------------------------------------------------------
    def _poses(self, q, w=None, aux=None):
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, float)))
        N = q.shape[0]
        w = np.zeros((N, 6)) if w is None else np.ascontiguousarray(np.broadcast_to(np.asarray(w, float), (N, 6)))
        if self.dims.naux:
            if aux is None:
                raise ValueError(f"the error model uses auxiliary signals {list(self.model.aux)}: pass aux values")
            aux = np.ascontiguousarray(np.broadcast_to(np.asarray(aux, float), (N, self.dims.naux)))
        else:
            aux = None
        return q, w, aux, N

    def _fn(self, name):
        return getattr(self._lib, f"{self.robot.name}_{name}")

    def _casadi(self, name, N, *columns):
        """Evaluate a CasADi function pose by pose (columns: per-pose arrays, or shared arrays)."""
        f = self._ca[name]
        outs = []
        for i in range(N):
            args = [a[i] if (a is not None and a.ndim == 2) else (a if a is not None else np.zeros(0)) for a in columns]
            res = f(*args)
            res = res if isinstance(res, (list, tuple)) else [res]
            outs.append([np.asarray(r).ravel() for r in res])
        return [np.array([o[k] for o in outs]) for k in range(len(outs[0]))] if outs else []

    # -- entry points ---------------------------------------------------------------------
    def model_targets(self, q, w, aux, c, with_H: bool = False):
        """Modelled target positions (N, nt, 3) at eps(c), and H_e (N, 3nt, nc) if asked."""
        q, w, aux, N = self._poses(q, w, aux)
        c = np.ascontiguousarray(c, float)
        d = self.dims
        if self.backend == "numpy":
            return self._numeric.model_targets(q, w, aux, c, with_H)
        if self.backend == "casadi":
            (p,) = self._casadi("model", N, q, w, aux, c)
            if not with_H:
                return p.reshape(N, d.nt, 3)
            (eps,) = self._casadi("eps", N, q, w, aux, c)
            (H,) = self._casadi("H_e", N, q, w, aux, eps)
            return p.reshape(N, d.nt, 3), H.reshape(N, 3 * d.nt, d.nc)
        p = np.empty((N, d.nt, 3))
        H = np.empty((N, 3 * d.nt, d.nc)) if with_H else None
        self._fn("model_batch")(ctypes.c_int(N), _ptr(q), _ptr(w), _ptr(aux), _ptr(c), _ptr(p), _ptr(H))
        return (p, H) if with_H else p

    def J_e(self, q, eps):
        """Target positions (N, nt, 3) and J_e (N, 3nt, ne) at per-pose errors eps."""
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, float)))
        N, d = q.shape[0], self.dims
        eps = np.ascontiguousarray(np.broadcast_to(np.asarray(eps, float), (N, d.ne)))
        if self.backend == "numpy":
            return self._numeric.J_e(q, eps)
        if self.backend == "casadi":
            p, J = self._casadi("J_e", N, q, eps)
            return p.reshape(N, d.nt, 3), J.reshape(N, 3 * d.nt, d.ne)
        p, J = np.empty((N, d.nt, 3)), np.empty((N, 3 * d.nt, d.ne))
        self._fn("J_e_batch")(ctypes.c_int(N), _ptr(q), _ptr(eps), _ptr(p), _ptr(J))
        return p, J

    def load_signals(self, q, w=None) -> tuple[list[str], np.ndarray]:
        """Every load signal the robot supports at joints q (N, nq) and wrenches w (N, 6) (zero when
        None): their names, exactly the term-language spellings (`gecgen.model.loads`), and values
        (N, L) in N m (N for a prismatic joint; gravity columns per kg and per kg m). Computed in numpy
        (`model.loads.signal_values`): the generated code computes only the model's own."""
        q, w, _, _ = self._poses(q, w, np.zeros(self.dims.naux))  # the loads need no aux signals
        return catalog(self.robot).names, signal_values(self.robot, q, w)

    def nominal_targets(self, q):
        """Target positions (N, nt, 3) of the nominal model."""
        if self.backend == "casadi":
            return self.J_e(q, np.zeros(self.dims.ne))[0]
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, float)))
        if self.backend == "numpy":
            return self._numeric.nominal_targets(q)
        p = np.empty((len(q), self.dims.nt, 3))
        self._fn("nominal_batch")(ctypes.c_int(len(q)), _ptr(q), _ptr(p))
        return p

    def eps(self, q, w, aux, c):
        """Generalized errors (N, ne) at each pose for coefficients c."""
        q, w, aux, N = self._poses(q, w, aux)
        c = np.ascontiguousarray(c, float)
        if self.backend == "numpy":
            return self._numeric.eps(q, w, aux, c)
        if self.backend == "casadi":
            return self._casadi("eps", N, q, w, aux, c)[0].reshape(N, self.dims.ne)
        out = np.empty((N, self.dims.ne))
        self._fn("eps_batch")(ctypes.c_int(N), _ptr(q), _ptr(w), _ptr(aux), _ptr(c), _ptr(out))
        return out

    def basis(self, q, w, aux):
        """The distinct basis terms f (N, nf) of the error model at each pose (`model.unique_terms()`
        order; coefficient k scales term `terms.index(coefficients[k].term.text)` of its error)."""
        q, w, aux, N = self._poses(q, w, aux)
        nf = len(self.model.unique_terms())
        if self.backend == "numpy":
            return self._numeric.basis(q, w, aux).copy()
        if self.backend == "casadi":
            return self._casadi("basis", N, q, w, aux)[0].reshape(N, nf)
        out = np.empty((N, nf))
        self._fn("basis_batch")(ctypes.c_int(N), _ptr(q), _ptr(w), _ptr(aux), _ptr(out))
        return out

    def compensate(self, q_cmd, w, aux, c, max_iter: int = 50, tol: float = 1e-11, branch: int = 0):
        """Corrected joint commands (N, nq) and status codes (N,): `correct` with no bound."""
        q, status, _ = self.correct(q_cmd, w, aux, c, max_iter, tol, branch)
        return q, status

    def correct(self, q_cmd, w, aux, c, max_iter: int = 50, tol: float = 1e-11, branch: int = 0, bound=None):
        """Corrected joint commands (N, nq), status codes (N,) and residuals (N,) for nominal commands
        q_cmd (N, nq) (m or rad), residual tolerance tol (m; 1 rad counts as 1 m), bound None or (nq,)
        the largest |q - q_cmd| per joint (m or rad; inf leaves a joint free). The generated C's
        NAME_compensate_bounded_batch; the codes (its header's GECGEN_ codes), per row:
        OK (0) converged inside the joint limits; NOT_CONVERGED (1) the last iterate (max_iter steps, or
        20 in a row that each lowered the residual by under 0.1 %); SINGULAR (2) near a singular
        posture: the correction that would place the tool is more than the model's error justifies, and
        the row holds the least damped correction that is justified; OUTSIDE_LIMITS (3) converged, outside
        the limits; NONFINITE (4) an input is NaN or infinite, tol is not > 0, max_iter < 0 or the
        computation overflowed, and the row holds q_cmd unchanged (residual inf); BOUNDED (5) a joint's
        correction reached its bound and is held there. The residual is the tool error left (m, 1 rad
        as 1 m; a branch with fewer than six joints of its own places its tool's whole pose where they can,
        otherwise its position alone, and the residual is then that position's error, `Robot.task_rows`).
        On a tree, the tool of `branch` (index) is placed by its own joints, every other reading held.
        With the numpy backend up to NUMPY_COMMANDS commands are corrected in numpy (`NumericModel.correct`, the C's numbers to
        rounding) while the C is not built; otherwise the C is loaded here, built first unless a
        background build has finished it (waiting for one under way)."""
        q, w, aux, N = self._poses(q_cmd, w, aux)
        c = np.ascontiguousarray(c, float)
        if self.backend == "casadi":
            raise RuntimeError("compensation runs in the generated C; install a C compiler (or set CC)")
        if self._lib is None and N <= NUMPY_COMMANDS and not _intact(library_path(self.robot, self.key)):
            return self._numeric.correct(q, w, aux, c, max_iter, tol, branch, bound)
        if self._lib is None:
            self._lib = ctypes.CDLL(str(shared_library(self.robot, self.model, self.key)))
        out, status, residual = np.empty_like(q), np.empty(N, dtype=np.intc), np.empty(N)
        limit = None if bound is None else np.ascontiguousarray(np.broadcast_to(np.asarray(bound, float), (self.dims.nq,)))
        name = "compensate_bounded_batch" + (f"_{self.robot.branches[branch].name}" if self.robot.branches else "")
        self._fn(name).restype = ctypes.c_int
        self._fn(name)(ctypes.c_int(N), _ptr(q), _ptr(w), _ptr(aux), _ptr(c), ctypes.c_int(max_iter),
                       ctypes.c_double(tol), None if limit is None else _ptr(limit), _ptr(out), _ptr(residual),
                       status.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
        return out, status, residual

def load_casadi_module(files: dict[str, str], name: str):
    """Import the generated CasADi module from its text (written to the cache first; its name
    carries the text's hash, and an entry whose bytes do not match it is written again)."""
    text = files[f"{name}_casadi.py"]
    digest = hashlib.sha256(text.encode()).hexdigest()[:20]
    path = cache_dir() / f"{name}_casadi_{digest}.py"
    try:
        intact = _sha256_file(path)[:20] == digest
    except OSError:
        intact = False
    if not intact:
        write_atomically(path, text)
    spec = importlib.util.spec_from_file_location(f"gecgen_generated_{name}_{digest}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module
