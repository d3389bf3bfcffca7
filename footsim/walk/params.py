"""Walk-engine parameters (the quintic walk's configuration).

The fields are the Hamburg Bit-Bots' quintic-walk parameters (``engine.*`` of their walk config
files, plus the ``node.*`` rates and speed multipliers footsim uses), with their names, units and
conventions (``../shared/FACTS.md``, "Quintic walk: conventions and units"):

* ``freq`` is the full (double-step) cycle frequency; one step (half cycle) lasts
  ``half_period = 1 / (2 freq)``; each half step starts with ``double_support_ratio`` of it in
  double support, the rest is single support.
* ``foot_apex_phase``, ``foot_put_down_phase``, ``foot_overshoot_phase`` and ``foot_z_pause`` are
  shares of single support; ``trunk_phase``, ``first_step_trunk_phase`` and ``trunk_pause`` are
  shares of a half period.
* Angles in radians, lengths in metres; trunk offsets are in the support-sole frame.
* ``engine_freq``, ``trunk_pid_*`` and ``phase_reset_*`` are the walk node's (``node.*``): the 3D
  driver runs them (``footsim.backends.physics3d``); the 2D backend ignores them.

Defaults are the Bit-Bots' Webots-simulation values of 2022 for the parameters footsim's engine
has always had, and for the others the value that leaves the motion unchanged (no apex pitch,
no overshoot, no pauses, the first step's trunk phase = ``trunk_phase``, the engine sampled every
control tick, no trunk PID, no phase reset).  Every backend may
override them through the Hydra group ``walk``; ``conf/walk/bitbots_*.yaml`` hold the Bit-Bots'
own files.  The kick parameters (``engine.kick_*``) are not fields: footsim's engine has no kick.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields

# Fields that may be None, and the switches (the others are finite numbers).
_OPTIONAL = frozenset({"first_step_trunk_phase", "engine_freq"})
_SWITCHES = frozenset({"phase_reset_foot_pressure_active"})


@dataclass(frozen=True)
class WalkParams:
    freq: float = 1.9633  # double steps per second
    double_support_ratio: float = 0.0264  # share of each half step spent in double support
    foot_distance: float = 0.1799  # lateral distance between the feet at rest [m]
    foot_rise: float = 0.0820  # flying-foot apex height [m]
    foot_apex_phase: float = 0.5  # apex time as a share of single support
    foot_put_down_phase: float = 1.0  # put-down time as a share of single support
    foot_apex_pitch: float = 0.0  # flying-sole pitch at the apex [rad], positive = toe down
    foot_overshoot_ratio: float = 0.0  # x/y overshoot beyond the landing, as a share of the step
    foot_overshoot_phase: float = 1.0  # overshoot time as a share of the put-down time (1 = none)
    foot_z_pause: float = 0.0  # share of single support the foot holds foot_rise around the apex
    foot_put_down_z_offset: float = 0.0  # height [m] the foot reaches at put-down (then lowered)
    trunk_height: float = 0.3948  # trunk (base) height above the support sole [m]
    trunk_pitch: float = 0.1056  # [rad], positive leans forward
    trunk_pitch_p_coef_forward: float = -0.186  # pitch added per metre of step x
    trunk_pitch_p_coef_turn: float = -0.457  # pitch added per radian of |step yaw|
    trunk_swing: float = 0.1549  # lateral trunk swing, as a share of half the foot offset
    trunk_phase: float = -0.1517  # phase shift of the trunk swing (in half steps)
    first_step_trunk_phase: float | None = None  # trunk_phase of the start movement and start step; None = trunk_phase
    trunk_pause: float = 0.0  # share of a half step the trunk holds its lateral apex
    trunk_x_offset: float = 0.0089  # [m]
    trunk_x_offset_p_coef_forward: float = 0.0  # trunk x offset added per metre of step x [m/m]
    trunk_x_offset_p_coef_turn: float = 0.0  # trunk x offset added per radian of |step yaw| [m/rad]
    trunk_y_offset: float = 0.0037  # [m]
    trunk_z_movement: float = 0.0155  # vertical trunk oscillation [m]
    first_step_swing_factor: float = 1.806  # trunk swing gain in the start step
    # The Bit-Bots' walk-node update rate [Hz] (node.engine_freq): the 3D driver takes new joint
    # targets from the engine at this rate and holds them in between; None = every control tick.
    engine_freq: float | None = None
    # The Bit-Bots' stabilizer (node.trunk_pid.{pitch,roll}.*): PID controllers on the error
    # "planned − measured" fused trunk pitch / roll [rad] whose outputs shift the trunk by x (from
    # pitch) / y (from roll) in the support-sole frame [m]: p [m/rad], i [m/(rad s)], d [m s/rad];
    # the I term is clamped to [i_clamp_min, i_clamp_max] [m] (both 0, as in their files: no I
    # term).  All gains 0 = off.  Run by the 3D driver (footsim.backends.control.TrunkPID).
    trunk_pid_pitch_p: float = 0.0
    trunk_pid_pitch_i: float = 0.0
    trunk_pid_pitch_d: float = 0.0
    trunk_pid_pitch_i_clamp_min: float = 0.0
    trunk_pid_pitch_i_clamp_max: float = 0.0
    trunk_pid_roll_p: float = 0.0
    trunk_pid_roll_i: float = 0.0
    trunk_pid_roll_d: float = 0.0
    trunk_pid_roll_i_clamp_min: float = 0.0
    trunk_pid_roll_i_clamp_max: float = 0.0
    # Phase reset on foot contact (node.phase_reset.*, foot-pressure mode): once the walk phase
    # within a half step passes phase_reset_min_phase / 2 (their convention: min_phase in
    # single-step units, 0.9 = the last 10 % of each half step), a flying-sole normal contact
    # force above phase_reset_ground_min_pressure [N] ends the step there and the next one
    # starts (QuinticWalk.end_step).  Run by the 3D driver.
    phase_reset_foot_pressure_active: bool = False
    phase_reset_min_phase: float = 0.9
    phase_reset_ground_min_pressure: float = 1.5
    # Velocity orders: a step per axis = v / (2 freq) * multiplier (then clipped to the limits).
    x_speed_multiplier: float = 1.0
    y_speed_multiplier: float = 1.0
    yaw_speed_multiplier: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None and f.name in _OPTIONAL:
                continue
            if f.name in _SWITCHES:
                if not isinstance(value, bool):
                    raise ValueError(f"WalkParams.{f.name} must be true or false, got {value!r}")
                continue
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                kind = "a finite number or None" if f.name in _OPTIONAL else "a finite number"
                raise ValueError(f"WalkParams.{f.name} must be {kind}, got {value!r}")
        checks = {
            "freq": (self.freq > 0, "> 0"),
            "double_support_ratio": (0.0 <= self.double_support_ratio < 1.0, "in [0, 1)"),
            "foot_distance": (self.foot_distance > 0, "> 0"),
            "foot_rise": (self.foot_rise >= 0, ">= 0"),
            "foot_apex_phase": (0.0 < self.foot_apex_phase < 1.0, "in (0, 1)"),
            "foot_put_down_phase": (0.0 < self.foot_put_down_phase <= 1.0, "in (0, 1]"),
            "foot_overshoot_ratio": (0.0 <= self.foot_overshoot_ratio <= 1.0, "in [0, 1]"),
            "foot_overshoot_phase": (0.0 < self.foot_overshoot_phase <= 1.0, "in (0, 1]"),
            "foot_z_pause": (0.0 <= self.foot_z_pause < 1.0, "in [0, 1)"),
            "foot_put_down_z_offset": (self.foot_put_down_z_offset >= 0, ">= 0"),
            "trunk_height": (self.trunk_height > 0, "> 0"),
            "trunk_pause": (0.0 <= self.trunk_pause < 1.0, "in [0, 1)"),
            "trunk_z_movement": (self.trunk_z_movement >= 0, ">= 0"),
            "engine_freq": (self.engine_freq is None or self.engine_freq > 0, "> 0 or None"),
            "trunk_pid_pitch_i_clamp_min": (
                self.trunk_pid_pitch_i_clamp_min <= self.trunk_pid_pitch_i_clamp_max,
                "<= trunk_pid_pitch_i_clamp_max",
            ),
            "trunk_pid_roll_i_clamp_min": (
                self.trunk_pid_roll_i_clamp_min <= self.trunk_pid_roll_i_clamp_max,
                "<= trunk_pid_roll_i_clamp_max",
            ),
            "phase_reset_min_phase": (0.0 <= self.phase_reset_min_phase <= 1.0, "in [0, 1]"),
            "phase_reset_ground_min_pressure": (self.phase_reset_ground_min_pressure >= 0, ">= 0"),
        }
        for name, (ok, valid) in checks.items():
            if not ok:
                raise ValueError(f"WalkParams.{name} must be {valid}, got {getattr(self, name)!r}")

    @property
    def double_step_duration(self) -> float:
        """Seconds per double step (one full walk cycle)."""
        return 1.0 / self.freq

    @property
    def half_period(self) -> float:
        return 0.5 / self.freq

    @property
    def start_trunk_phase(self) -> float:
        """The trunk phase of the start movement and the start step."""
        return self.trunk_phase if self.first_step_trunk_phase is None else self.first_step_trunk_phase

    @classmethod
    def from_mapping(cls, mapping: Mapping) -> WalkParams:
        """Build from a dict / DictConfig, naming any unknown key."""
        known = {f.name for f in fields(cls)}
        data = dict(mapping)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown walk parameter(s) {unknown}; valid: {sorted(known)}")
        values: dict = {k: _value(k, v) for k, v in data.items()}
        return cls(**values)

    def to_dict(self) -> dict:
        return asdict(self)


def _value(name: str, value):
    """A config value as the field takes it: None (optional fields), a switch as given, else a float."""
    if value is None and name in _OPTIONAL:
        return None
    if name in _SWITCHES:
        return value  # __post_init__ names a non-boolean
    return float(value)
