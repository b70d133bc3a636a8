"""The closed loop on image points: how diagnose fits a model to pixels (`fit.camera.fit_pixels`, the
cameras' poses fitted with it), linearises the fit and scores it, as `loop.diagnose.Points` does for
tracker points.

The screening's statistics (chi-square against the residual variance, cross-validated RMS) do not
depend on the unit of the rows; its figures are in mm. The pixel rows are therefore scaled by one
constant, what a pixel means at the points (the median of depth over focal length), so that the
loop's figures are mm at the target, and by sqrt(2/3) besides: the screening counts three
coordinates to a point, an image point has two, so its RMS "per point" is then an image point's.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from gecgen.fit.camera import fit_pixels, frame_robot, linearised, summary_at
from gecgen.fit.significance import noise_test
from gecgen.loop.diagnose import LARGEST
from gecgen.loop.linear import Round
from gecgen.model.cameras import Board, Camera
from gecgen.model.errors import ErrorModel
from gecgen.model.pixels import Pixels
from gecgen.model.robot import Robot
from gecgen.runtime.compiled import CompiledModel

#: an image point's two coordinates against the screening's three per point
POINT_DOF = np.sqrt(2 / 3)


@dataclass(frozen=True)
class ImagePoints:
    """Image points of `robot` seen by `cameras` (and, for a camera on the tool, the board): what
    `loop.diagnose.diagnose` fits, linearises and scores when given as its `measure`. noise_px: the
    corners' noise per coordinate (px), when known: the fit holds what the images determine too
    weakly against it, and the loop says whether what remains is only that noise. loss and
    significance: as for `fit_pixels`."""

    robot: Robot
    cameras: dict[str, Camera]
    board: Board | None = None
    noise_px: float | None = None
    loss: str = "cauchy"
    #: the coefficients the images do not determine held at zero (`fit_pixels`'s significance)
    significance: bool = True
    #: each fit refines the cameras' intrinsics from the camera files' (`fit_pixels`'s intrinsics), and
    #: held-out images are seen through the intrinsics that fit refined
    intrinsics: bool = False

    def fit(self, robot: Robot, model: ErrorModel, data: Pixels, quiet: bool = True) -> Round:
        """The model and the cameras' poses fitted; quiet: its warnings kept back (diagnose's rounds: what
        the images leave weak is said by the final fit)."""
        cm = CompiledModel(frame_robot(robot), model)
        with warnings.catch_warnings():
            if quiet:
                warnings.simplefilter("ignore")
            fit = fit_pixels(robot, model, data, self.cameras, self.board, loss=self.loss, noise_px=self.noise_px,
                             significance=self.significance, intrinsics=self.intrinsics)
        return Round(model, cm, fit)

    def squared_error(self, rnd: Round, test: Pixels) -> tuple[float, float]:
        """(sum of squared image-point errors in m at the target, the points they count for) of poses the
        fit did not see, seen from the cameras (and board) as it placed them."""
        s = self.held_out(rnd, test)
        return 1e-6 * s["rms_mm_at_target"] ** 2 * len(test.uv), float(len(test.uv))

    def held_out(self, rnd: Round, test: Pixels) -> dict:
        """The residual of images the fit did not see (`summary_at`), through the cameras as it placed them."""
        return summary_at(rnd.cm, self.robot, test, self.cameras, self.board, rnd.fit.g, rnd.fit.c, self.intrinsics)

    def system(self, rnd: Round, data: Pixels):
        """As `loop.diagnose.Points.system`: the fit's weighted linear system (its columns the cameras'
        poses and the kept coefficients), rows in m at the target (the module docstring), each pose's
        adjacent, each row one degree of freedom."""
        lin = linearised(rnd.cm, self.robot, data, self.cameras, self.board, rnd.fit)
        order = np.argsort(data.pose, kind="stable")
        rows = (2 * order[:, None] + np.arange(2)).ravel()
        s = 1e-3 * lin.mm_per_px * POINT_DOF
        return (s * lin.A[rows], s * lin.r[rows], np.repeat(data.pose[order], 2), np.ones(len(rows)),
                s * lin.J[rows])

    @staticmethod
    def train_rms_mm(rnd: Round) -> float:
        return rnd.fit.train["rms_mm_at_target"]

    def noise(self, data: Pixels, robot: Robot, noise_px: float | None) -> dict | None:
        """The corners' noise, px per coordinate, as given (None: unknown; image points are not repeated)."""
        return None if noise_px is None else {"noise_px": float(noise_px), "source": "given (--noise-px)", "dof": None}

    def scores(self, rnd: Round, val: Pixels) -> dict:
        """Training and held-out residuals, mm at the target (`*_mm`, as `loop.diagnose._scores` names
        them) and px: the held-out points seen from the cameras (and board) as the fit placed them."""
        s = self.held_out(rnd, val)
        train = rnd.fit.train
        return {"train_rms_mm": train["rms_mm_at_target"], "val_rms_mm": s["rms_mm_at_target"],
                "val_max_mm": s["max_mm_at_target"], "train_rms_px": train["rms_px"], "val_rms_px": s["rms_px"],
                "val_max_px": s["max_px"]}

    @staticmethod
    def remains(rnd: Round, data: Pixels, cv_rms_mm: float | None, noise: dict | None) -> dict:
        """As `loop.diagnose.what_remains`, in mm at the target (px beside): whether the residual is only
        the corners' noise, and the largest image points when it is not."""
        fit = rnd.fit
        px, mm = fit.residuals.T
        mm_per_px = float(np.median(mm[px > 0] / px[px > 0]))
        flagged = {o.row for o in fit.outliers}
        inliers = np.flatnonzero([r not in flagged for r in data.row])
        top = inliers[np.argsort(-px[inliers])[:LARGEST]]
        out = {"train_rms_mm": fit.train["rms_mm_at_target"], "train_rms_px": fit.train["rms_px"],
               "cv_rms_mm": cv_rms_mm, "sigma_mm": mm_per_px * fit.sigma_px, "sigma_px": fit.sigma_px,
               "noise": None, "covered": None, "outliers": len(fit.outliers),
               "largest": [{"row": int(data.row[r]), "pose": int(data.pose_ids[data.pose[r]]),
                            "camera": data.cameras[data.camera[r]], "point": data.points[data.point[r]],
                            "residual_px": float(px[r]), "residual_mm": float(mm[r])} for r in top]}
        if noise is not None:
            out["noise"] = noise = {**noise, "noise_mm": mm_per_px * noise["noise_px"]}
            dof = max(2 * float(fit.weights.sum()) - len(fit.g) - len(fit.kept), 1.0)
            covered, p, ratio = noise_test(1e-3 * out["sigma_mm"], dof, noise)
            out.update(covered=covered, noise_p_value=p, sigma_over_noise=ratio)
        return out

    @staticmethod
    def confounding(rnd: Round, data: Pixels) -> list[dict]:
        """Coupling ratios are not checked on image points: none."""
        return []
