"""Fitting a calibration to measurements: registration, placement, redundancy, identification, significance."""
