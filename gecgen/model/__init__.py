"""Model layer: parse and validate robot, error-model and measurement files.

The names below are imported on first use: `from gecgen.model import ModelError` does not load
numpy or scipy, so the command line answers --help and --version at once. Error-model files are
read by `symbolic.terms.load_error_model` (the term language needs sympy).
"""
import importlib

_WHERE = {"Coefficient": "errors", "ErrorModel": "errors", "Term": "errors",
          "ERROR_NAMES": "robot", "WRENCH": "robot", "Joint": "robot", "Robot": "robot",
          "load_robot": "robot_file", "ModelError": "validation"}
__all__ = sorted(_WHERE)


def __getattr__(name):
    if name in _WHERE:
        return getattr(importlib.import_module(f"gecgen.model.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'gecgen.model' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_WHERE])
