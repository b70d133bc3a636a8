"""Delivering a calibration to a robot that runs its own controller: corrected robot programs.

Nothing of gecgen imports this package but the command line and the API.
"""
