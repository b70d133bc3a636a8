"""Writing files safely: every file gecgen writes goes through `write_atomically`, and every
output a command names is checked by `check_output_file` or `check_output_dir` before any work.

Below every pipeline layer (model, emit, runtime and loop all write files), so it imports
nothing of gecgen but the error type.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import secrets
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
