"""Writing files safely: every file gecgen writes goes through `write_atomically`, and every
output a command names is checked by `check_output_file` or `check_output_dir` before any work.

Below every pipeline layer (model, emit, runtime and loop all write files), so it imports
nothing of gecgen but the error type. `cache_dir` is where compiled code and read models are kept.
"""
from __future__ import annotations

import atexit
import contextlib
import contextvars
import functools
import glob
import os
import secrets
import shutil
import tempfile
import warnings
from pathlib import Path

from gecgen.model.validation import ModelError


#: the files the running command reads (`reading`): no output may replace one of them
_INPUTS: contextvars.ContextVar[tuple[str, ...]] = contextvars.ContextVar("gecgen_inputs", default=())


@contextlib.contextmanager
def reading(paths):
    """While the block runs, `write_atomically` refuses to replace any of the files `paths`: the
    inputs of the running command. A named output file is checked before the work
    (`check_output_file`); the files written into an output folder are known only as they are
    written, and this catches one that would land on an input."""
    token = _INPUTS.set(tuple(str(p) for p in paths))
    try:
        yield
    finally:
        _INPUTS.reset(token)


def write_atomically(path: str | Path, data: bytes | str) -> Path:
    """Write `data` (text is UTF-8) to path through a uniquely named temporary file in the same
    folder and a rename, creating the folder if needed: a reader, a parallel process or a crash
    never sees a half-written file, only the old one or the new one. Returns the path. A file the
    running command reads (`reading`) is refused, not replaced."""
    path = Path(path)
    for source in _INPUTS.get():
        if same_file(path, source):
            raise ModelError(f"{path}: is {source}, which this command reads; writing there would destroy it: "
                             f"give the output another folder or name")
    path.parent.mkdir(parents=True, exist_ok=True)
    # named apart from the target: a target name of the longest length a folder allows still fits
    part = path.with_name(f".gecgen-{os.getpid()}-{secrets.token_hex(4)}.part")
    try:
        # os.open with mode 0o666 leaves the permissions to the umask, as a plain open() would
        fd = os.open(part, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
        os.replace(part, path)
    except OSError as exc:
        part.unlink(missing_ok=True)
        raise OSError(exc.errno, exc.strerror, str(path)) from None  # name the target, not the temporary
    except BaseException:  # Ctrl-C while writing: no temporary left behind
        part.unlink(missing_ok=True)
        raise
    return path


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def _require_writable_folder(folder: Path, path: Path, what: str):
    """`folder` must exist as a folder we may create entries in, or be creatable: its nearest
    existing ancestor must be such a folder."""
    anchor = _nearest_existing(folder.absolute())
    if not anchor.is_dir():
        raise ModelError(f"{path}: cannot write the {what}: {anchor} is a file, not a folder; choose another location")
    if not os.access(anchor, os.W_OK | os.X_OK):
        raise ModelError(f"{path}: cannot write the {what} into {anchor} (permission denied); "
                         f"choose a writable location")


def check_output_file(path: str | Path, what: str) -> Path:
    """Refuse, before any work, an output file (`what`: "calibration", ...) that names a folder or
    lies where nothing can be written: a one-line ModelError naming the path and the fix."""
    path = Path(path)
    size = len(os.fsencode(path.name))
    if size > 255:  # before anything asks the file system, which refuses such a name
        raise ModelError(f"{path.parent / (path.name[:12] + '...' + path.name[-12:])}: the file name is longer than "
                         f"255 bytes ({size}); give a shorter name for the {what}")
    if path.is_dir():
        raise ModelError(f"{path}: is a folder; give a file name for the {what}")
    if path.exists() and not path.is_file():  # a device node or a pipe would be replaced by a file
        raise ModelError(f"{path}: is not a regular file (a device, pipe or socket); give a file name for the {what}")
    _require_writable_folder(path.parent, path, what)
    return path


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two existing paths are one file (the same inode: links and relative spellings too)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_output_dir(path: str | Path, what: str) -> Path:
    """Refuse, before any work, an output folder that is a file or lies where nothing can be written."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ModelError(f"{path}: is a file; give a folder for the {what}")
    _require_writable_folder(path, path, what)
    return path


def _sibling(path: Path, kind: str) -> Path:
    """The hidden file or folder beside the output folder `path` that gecgen uses while it works on
    it (`kind`: "lock", "build-..."): named after the folder, or after its name's hash where that
    name is too long for one more suffix."""
    import hashlib

    name = path.name if len(os.fsencode(path.name)) < 200 else hashlib.sha256(os.fsencode(path.name)).hexdigest()[:16]
    return path.parent / f".{name}.gecgen-{kind}"


@contextlib.contextmanager
def output_lock(path: str | Path, what: str):
    """Hold the output folder `path` (`what`: "calibration folder", ...) for this process while the
    block runs: a second gecgen run writing the same folder is refused at once with one line naming
    it, instead of both writing and the folder holding a mix. The lock is an flock on a hidden file
    beside the folder (`.NAME.gecgen-lock`): the system releases it when the process ends, however
    it ends, so a killed run never leaves the folder locked. The file is removed on release."""
    try:
        import fcntl
    except ImportError:  # Windows: no flock; the folder is still replaced whole (`output_folder`)
        yield Path(path)
        return
    path = Path(path)
    lock = _sibling(path, "lock")
    lock.parent.mkdir(parents=True, exist_ok=True)
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ModelError(f"{path}: another gecgen run is writing this {what} now; wait for it to finish, or "
                             f"give another folder") from None
        # the holder before us may have removed the file between our open and our lock: then the
        # lock is on a file nobody else will open, and the one at the path is the one to hold
        try:
            if os.stat(lock).st_ino == os.fstat(fd).st_ino:
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    try:
        yield path
    finally:
        lock.unlink(missing_ok=True)
        os.close(fd)


@contextlib.contextmanager
def output_folder(path: str | Path, what: str, figures: str = "*.png"):
    """Write the output folder `path` as a whole: the block writes into a new hidden folder beside
    it (yielded), which replaces `path` in one rename when the block succeeds, and is removed when
    it fails or is interrupted; so after an error, Ctrl-C, a full disk or a kill, `path` is the old
    folder (or absent) or the new one, never a mix. Held by `output_lock` throughout. Entries of
    the old folder that the new one lacks (files of the user's own) are carried into the new one,
    except the old run's figures (`figures`, a glob), which belong to the report they replace."""
    import shutil

    # a folder reached through a symbolic link is replaced where it is, the link left as it was
    path = Path(os.path.realpath(path)) if Path(path).is_symlink() else Path(path)
    with output_lock(path, what):
        for stale in path.parent.glob(glob.escape(_sibling(path, "build-").name) + "*"):  # left by a killed run
            if stale.name.endswith("-old") and not path.exists():  # killed between `_exchange`'s two renames
                os.rename(stale, path)
            else:
                shutil.rmtree(stale, ignore_errors=True)
        build = _sibling(path, f"build-{os.getpid()}-{secrets.token_hex(4)}")
        build.mkdir()
        try:
            yield build
            if path.is_dir():
                for entry in path.iterdir():
                    if not (build / entry.name).exists() and not entry.match(figures):
                        _carry(entry, build / entry.name)
                _exchange(build, path)  # build now names the old folder
            else:
                os.rename(build, path)
        finally:
            shutil.rmtree(build, ignore_errors=True)


def _carry(source: Path, target: Path):
    """A hard link of a file (a copy where links cannot be made), a folder's tree of them; symbolic links as links."""
    import shutil

    def link(a, b):
        try:
            os.link(a, b, follow_symlinks=False)
        except OSError:
            shutil.copy2(a, b, follow_symlinks=False)

    if source.is_dir() and not source.is_symlink():
        shutil.copytree(source, target, symlinks=True, copy_function=link)
    else:
        link(source, target)


def _exchange(a: Path, b: Path):
    """Swap the names of two folders in one step (Linux renameat2 RENAME_EXCHANGE), so that no
    moment exists at which b names nothing; where the system cannot, in two renames."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    renameat2 = getattr(libc, "renameat2", None)
    if renameat2 is not None:
        at_fdcwd, rename_exchange = -100, 2
        if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
            return
        errno = ctypes.get_errno()
        if errno not in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: this file system cannot swap
            raise OSError(errno, os.strerror(errno), str(b))
    aside = a.with_name(a.name + "-old")
    os.rename(b, aside)
    os.rename(a, b)
    os.rename(aside, a)


def cache_dir() -> Path:
    """`$GECGEN_CACHE` (default `~/.cache/gecgen`), or a temporary folder when that cannot be written."""
    return _usable_cache(_wanted_cache())


def cache_kept() -> bool:
    """Whether the cache folder outlives this run (it is not the temporary folder that stands in for
    one that cannot be written)."""
    return cache_dir() == _wanted_cache()


def _wanted_cache() -> Path:
    """`$GECGEN_CACHE` or the default. A leading `~` is the home folder: set in quotes or a service's
    environment, no shell expanded it, and the cache would be a folder named `~` in whatever folder the
    command runs in."""
    return Path(os.environ.get("GECGEN_CACHE") or Path.home() / ".cache" / "gecgen").expanduser()


@functools.cache
def _usable_cache(wanted: Path) -> Path:
    """wanted, created if needed, when a file can be created in it; else a fresh temporary folder,
    removed at exit (one warning per run and folder: the cache only saves time)."""
    try:
        wanted.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=wanted).close()
        return wanted
    except OSError as exc:
        fallback = Path(tempfile.mkdtemp(prefix="gecgen-cache-"))
        atexit.register(shutil.rmtree, fallback, ignore_errors=True)
        warnings.warn(f"the cache folder {wanted} cannot be written ({exc.strerror}); compiling into {fallback} "
                      f"for this run instead (set GECGEN_CACHE to a writable folder to keep the compiled code)",
                      stacklevel=3)
        return fallback
