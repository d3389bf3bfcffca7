"""Walk-engine parameters (the quintic walk's configuration).

Defaults are the Hamburg Bit-Bots' Webots-simulation values of 2022 (``../shared/FACTS.md``).
Every backend may override them through the Hydra group ``walk``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields


@dataclass(frozen=True)
class WalkParams:
    freq: float = 1.9633  # double steps per second
    double_support_ratio: float = 0.0264  # share of each half step spent in double support
    foot_distance: float = 0.1799  # lateral distance between the feet at rest [m]
    foot_rise: float = 0.0820  # flying-foot apex height [m]
    foot_apex_phase: float = 0.5  # apex time as a share of single support
    foot_put_down_phase: float = 1.0  # put-down time as a share of single support
    trunk_height: float = 0.3948  # trunk (base) height above the support sole [m]
    trunk_pitch: float = 0.1056  # [rad]
    trunk_pitch_p_coef_forward: float = -0.186  # pitch added per metre of step x
    trunk_pitch_p_coef_turn: float = -0.457  # pitch added per radian of |step yaw|
    trunk_swing: float = 0.1549  # lateral trunk swing, as a share of half the foot offset
    trunk_phase: float = -0.1517  # phase shift of the trunk swing (in half steps)
    trunk_x_offset: float = 0.0089  # [m]
    trunk_y_offset: float = 0.0037  # [m]
    trunk_z_movement: float = 0.0155  # vertical trunk oscillation [m]
    first_step_swing_factor: float = 1.806  # trunk swing gain in the start step
    # Velocity orders: a step per axis = v / (2 freq) * multiplier (then clipped to the limits).
    x_speed_multiplier: float = 1.0
    y_speed_multiplier: float = 1.0
    yaw_speed_multiplier: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"WalkParams.{f.name} must be a finite number, got {value!r}")
        checks = {
            "freq": self.freq > 0,
            "double_support_ratio": 0.0 <= self.double_support_ratio < 1.0,
            "foot_distance": self.foot_distance > 0,
            "foot_rise": self.foot_rise >= 0,
            "foot_apex_phase": 0.0 < self.foot_apex_phase < 1.0,
            "foot_put_down_phase": 0.0 < self.foot_put_down_phase <= 1.0,
            "trunk_height": self.trunk_height > 0,
            "trunk_z_movement": self.trunk_z_movement >= 0,
        }
        ranges = {
            "freq": "> 0",
            "double_support_ratio": "in [0, 1)",
            "foot_distance": "> 0",
            "foot_rise": ">= 0",
            "foot_apex_phase": "in (0, 1)",
            "foot_put_down_phase": "in (0, 1]",
            "trunk_height": "> 0",
            "trunk_z_movement": ">= 0",
        }
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"WalkParams.{name} must be {ranges[name]}, got {getattr(self, name)!r}")

    @property
    def double_step_duration(self) -> float:
        """Seconds per double step (one full walk cycle)."""
        return 1.0 / self.freq

    @property
    def half_period(self) -> float:
        return 0.5 / self.freq

    @classmethod
    def from_mapping(cls, mapping) -> WalkParams:
        """Build from a dict / DictConfig, naming any unknown key."""
        known = {f.name for f in fields(cls)}
        data = dict(mapping)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown walk parameter(s) {unknown}; valid: {sorted(known)}")
        return cls(**{k: float(v) for k, v in data.items()})

    def to_dict(self) -> dict:
        return asdict(self)
