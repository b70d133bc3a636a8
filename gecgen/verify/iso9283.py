"""ISO 9283:1998 pose performance of a manipulator, scored: pose accuracy and repeatability, distance
accuracy and repeatability at the points of a test (`plan.iso9283` plans it). Inputs in m and rad;
results in mm and mrad.

Characteristics, for one point over n cycles j = 1..n, attained (x_j, y_j, z_j), commanded
(x_c, y_c, z_c), barycentre (xbar, ybar, zbar) the means:

* pose accuracy (clause 7.2.1): AP_p = sqrt((xbar - x_c)^2 + (ybar - y_c)^2 + (zbar - z_c)^2),
  AP_x = xbar - x_c, AP_y, AP_z alike; orientation AP_a = abar - a_c, AP_b, AP_c alike;
* pose repeatability (clause 7.2.2): RP_l = lbar + 3 S_l with l_j = |(x_j, y_j, z_j) - barycentre|,
  lbar their mean and S_l = sqrt(sum (l_j - lbar)^2 / (n - 1)); RP_a = +-3 S_a (S_a the sample
  standard deviation of a_j, n - 1), RP_b, RP_c alike, reported as 3 S;
* distance accuracy and repeatability (clause 7.4 in our reading of the 1998 edition, where 7.3 is
  the multi-directional pose accuracy variation; position part only): D_c = |P_c1 - P_c2|,
  D_j = |P_1j - P_2j|, AD_p = Dbar - D_c, RD_p = +-3 S_D (S_D with n - 1), reported as 3 S_D.

What we were unsure of, and chose: the standard gives a, b, c as rotations about the base x, y, z
axes and subtracts the commanded angle from the attained; angle differences depend on how the
commanded orientation is parametrized and wrap at +-pi. Here each attained rotation is taken
relative to the commanded one in the base frame, R_j R_c^T, and its extrinsic xyz angles
(R_j R_c^T = Rz(c_j) Ry(b_j) Rx(a_j)) are a_j, b_j, c_j, so the commanded angles are 0: AP_a is
the mean of a_j and RP_a three times their sample standard deviation. This equals the standard's
differences when the commanded orientation is the base frame's (R_c = I).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gecgen.model.validation import require


@dataclass(frozen=True)
class PoseCharacteristics:
    """ISO 9283 pose accuracy (AP) and repeatability (RP) at one point over n cycles: positions in mm,
    orientations in mrad (NaN when no orientations were given). RP_a, RP_b, RP_c are the half-widths
    3 S of the standard's +-3 S."""

    AP_p: float
    AP_x: float
    AP_y: float
    AP_z: float
    AP_a: float
    AP_b: float
    AP_c: float
    RP_l: float
    RP_a: float
    RP_b: float
    RP_c: float
    n: int


@dataclass(frozen=True)
class DistanceCharacteristics:
    """ISO 9283 distance accuracy AD_p and repeatability RD_p (the half-width 3 S_D of +-3 S_D), with
    the commanded distance D_c and the mean attained Dbar; mm, over n cycles."""

    AD_p: float
    RD_p: float
    D_c: float
    D_bar: float
    n: int


def pose_characteristics(commanded: tuple, attained: tuple) -> PoseCharacteristics:
    """ISO 9283 pose accuracy and repeatability at one point. commanded: (position (3,) m, rotation
    (3, 3) or None); attained over n >= 2 cycles: (positions (n, 3) m, rotations (n, 3, 3) or None).
    Orientation characteristics are NaN unless both rotations are given."""
    xyz_c, R_c = commanded
    xyz, R = attained
    xyz_c, xyz = np.asarray(xyz_c, float), np.asarray(xyz, float)
    n = len(xyz)
    require(n >= 2 and xyz.shape == (n, 3) and xyz_c.shape == (3,),
            f"pose_characteristics: positions (n >= 2, 3) and one commanded (3,), not {xyz.shape} and {xyz_c.shape}")
    bary = xyz.mean(axis=0)
    ap = 1e3 * (bary - xyz_c)
    l = 1e3 * np.linalg.norm(xyz - bary, axis=1)
    rp_l = l.mean() + 3 * l.std(ddof=1)
    if R_c is None or R is None:
        ap_abc = rp_abc = np.full(3, np.nan)
    else:
        R = np.asarray(R, float)
        require(R.shape == (n, 3, 3), f"pose_characteristics: rotations ({n}, 3, 3), not {R.shape}")
        abc = 1e3 * Rotation.from_matrix(R @ np.asarray(R_c, float).T).as_euler("xyz")  # (n, 3) a, b, c
        ap_abc, rp_abc = abc.mean(axis=0), 3 * abc.std(axis=0, ddof=1)
    return PoseCharacteristics(float(np.linalg.norm(ap)), *map(float, ap), *map(float, ap_abc), float(rp_l),
                               *map(float, rp_abc), n)


def distance_characteristics(cmd_a: np.ndarray, cmd_b: np.ndarray, att_a: np.ndarray,
                             att_b: np.ndarray) -> DistanceCharacteristics:
    """ISO 9283 distance accuracy and repeatability between two commanded positions cmd_a, cmd_b (3,)
    m and the positions attained there over n >= 2 cycles, att_a, att_b (n, 3) m."""
    att_a, att_b = np.asarray(att_a, float), np.asarray(att_b, float)
    n = len(att_a)
    require(n >= 2 and att_a.shape == att_b.shape == (n, 3),
            f"distance_characteristics: attained positions (n >= 2, 3) at both ends, not {att_a.shape}, {att_b.shape}")
    d_c = 1e3 * float(np.linalg.norm(np.asarray(cmd_a, float) - np.asarray(cmd_b, float)))
    d = 1e3 * np.linalg.norm(att_a - att_b, axis=1)
    return DistanceCharacteristics(AD_p=float(d.mean() - d_c), RD_p=float(3 * d.std(ddof=1)), D_c=d_c,
                                   D_bar=float(d.mean()), n=n)
