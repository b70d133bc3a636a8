"""Delivering a calibration to a robot's controller: the generated C with the coefficients as data, a
calibrated URDF and the joint and link table (`export`), and, for a controller that takes neither,
corrected robot programs (`programs`).

Nothing of gecgen imports this package but the command line and the API.
"""
