"""What the robot believes its pose is: localization noise (thesis 6.1).

Zero-mean Gaussian noise in the robot frame, drawn afresh every step: σx 0.05 m, σy 0.03 m,
σθ 0.07 rad in the ``localization`` preset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from footsim.geometry import Pose2D


@dataclass(frozen=True)
class NoiseModel:
    sigma_x: float = 0.0
    sigma_y: float = 0.0
    sigma_theta: float = 0.0

    def __post_init__(self) -> None:
        for key in ("sigma_x", "sigma_y", "sigma_theta"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"noise.{key} must be a number >= 0, got {value!r}")

    @property
    def active(self) -> bool:
        return self.sigma_x > 0 or self.sigma_y > 0 or self.sigma_theta > 0

    def believe(self, true_pose: Pose2D, rng: np.random.Generator) -> Pose2D:
        if not self.active:
            return true_pose
        nx, ny, nt = rng.normal(0.0, 1.0, size=3) * (self.sigma_x, self.sigma_y, self.sigma_theta)
        return true_pose.compose(Pose2D(float(nx), float(ny), float(nt)))
