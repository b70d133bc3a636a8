"""gecgen: Geometric and Elastic Error Compensation compiler and toolkit for large robots.

The Python API (docs/python-api.md) is importable from here: `gecgen.Calibrator`, `gecgen.Diagnoser`,
`gecgen.calibrate`, `gecgen.load_robot`, `gecgen.read_measurements`, `gecgen.load_calibration`,
`gecgen.filter_program`, the results `gecgen.Score`, `gecgen.Errors`, `gecgen.Compensation`,
`gecgen.Selection`, `gecgen.FilteredProgram` (with `gecgen.ProgramTarget`), and the error type
`gecgen.ModelError`.
"""
from gecgen.version import __version__  # noqa: F401  (gecgen.__version__)

_API = ("Calibrator", "Compensation", "Diagnoser", "Errors", "FilteredProgram", "ModelError", "ProgramTarget", "Score",
        "Selection", "calibrate", "filter_program", "load_calibration", "load_robot", "read_measurements")
__all__ = list(_API)


def __getattr__(name):
    # imported on first use: the command line starts without sympy, scipy and the compiled models
    if name in _API:
        from gecgen import api

        return getattr(api, name)
    raise AttributeError(f"module 'gecgen' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_API])
