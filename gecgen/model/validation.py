"""The one error type for bad user input, and the checks that raise it."""
from __future__ import annotations

from pathlib import Path

import yaml


class ModelError(ValueError):
    """Bad input: the message is one line naming the file, key or row, and the fix."""


def require(condition, message: str):
    if not condition:
        raise ModelError(message)
    return condition


def require_keys(spec: dict, where: str, required: set = frozenset(), optional: set = frozenset()):
    for key in sorted(required):
        require(key in spec, f"{where}: missing key '{key}'")
    unknown = sorted(str(k) for k in spec if k not in required | optional)
    require(not unknown, f"{where}: unknown key '{unknown[0] if unknown else ''}'; "
                         f"allowed keys are {sorted(required | optional)}")


def read_yaml(path: Path, what: str):
    """The parsed YAML document of a `what` file ("robot", "error-model"), or a one-line refusal."""
    require(path.is_file(), f"{path}: no such {what} file")
    try:
        return yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ModelError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
