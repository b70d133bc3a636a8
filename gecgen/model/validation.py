"""The one error type for bad user input, and the checks that raise it."""
from __future__ import annotations


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
