"""The version of gecgen, which calibration files, generated code and --version state."""
__version__ = "0.1.0"
