"""The Bit-Bots' engine parameters in QuinticWalk (hand-computed expectations, FK of the IK output)
and the conf/walk/bitbots_*.yaml presets checked value by value against ../shared/FACTS.md."""

import math
import pathlib

import numpy as np
import pytest
from omegaconf import OmegaConf
from shared_facts import facts_text

from footsim.walk import DoubleStep, Footstep, FootstepGeometry, LegGeometry, QuinticWalk, Side, StepLimits, WalkParams
from footsim.walk.ik import leg_fk, rpy_from_rotation

LIMITS = StepLimits(0.156, 0.103, 0.764)
LEG = LegGeometry()
DT = 1.0 / 500.0
# A gait whose knot instants fall on whole ticks: 1 Hz, so a half step is 0.5 s = 250 ticks;
# double support 0.1 s, single support 0.4 s; the flying foot's apex (share 0.5) at 0.3 s.
TIMED = {"freq": 1.0, "double_support_ratio": 0.2, "trunk_phase": -0.1}  # trunk apex t1 = 0.25 s
HALF, DOUBLE_SUPPORT, SINGLE_SUPPORT = 0.5, 0.1, 0.4
LEFT, RIGHT, TRUNK = 0, 1, 2  # rows of WalkTrajectory.local_poses
X, Y, Z, PITCH, YAW = 0, 1, 2, 4, 5
REPO = pathlib.Path(__file__).parents[1]


def params(**overrides) -> WalkParams:
    return WalkParams(**{**TIMED, **overrides})


def make_engine(p: WalkParams, control_dt: float = DT) -> QuinticWalk:
    return QuinticWalk(p, FootstepGeometry(LIMITS, foot_distance=p.foot_distance), LEG, control_dt)


def tick(t: float) -> int:
    """Index of the tick at local time ``t`` of a half step that starts a call (tick k at (k+1)·dt)."""
    return round(t / DT) - 1


def walking(p: WalkParams, step: DoubleStep):
    """A double step in WALKING (after one start double step of the same order): its first half
    step is right foot flying over the left support, ticks 0..249 at local times 2 ms .. 0.5 s."""
    engine = make_engine(p)
    engine.double_step(step)
    return engine.double_step(step)


def flying_in_support(trajectory, i: int) -> np.ndarray:
    """Right (flying) sole in the left (support) sole frame at tick ``i``, from FK of the joint targets."""
    q = trajectory.joint_targets[i]
    ps, Rs = leg_fk(q[None, :6], Side.LEFT.value, LEG)
    pf, Rf = leg_fk(q[None, 6:], Side.RIGHT.value, LEG)
    return np.concatenate([Rs[0].T @ (pf[0] - ps[0]), rpy_from_rotation(Rs[0].T @ Rf[0])])


FORWARD = DoubleStep(Footstep(0.05), Footstep(0.05))


# --- flying foot ---------------------------------------------------------------------------------


def test_foot_apex_pitch_is_reached_at_the_apex_and_flat_at_lift_off_and_put_down():
    trajectory = walking(params(foot_apex_pitch=0.1), FORWARD)
    apex = tick(DOUBLE_SUPPORT + 0.5 * SINGLE_SUPPORT)
    pitch = trajectory.local_poses[RIGHT, PITCH]
    assert pitch[apex] == pytest.approx(0.1, abs=1e-12)
    assert pitch[apex] == pytest.approx(pitch[: tick(HALF) + 1].max(), abs=1e-12)
    assert pitch[tick(DOUBLE_SUPPORT)] == pytest.approx(0.0, abs=1e-12)
    assert pitch[tick(HALF)] == pytest.approx(0.0, abs=1e-12)
    assert np.allclose(trajectory.local_poses[LEFT, PITCH, : tick(HALF) + 1], 0.0)  # the support sole stays flat
    assert trajectory.reachable.all()
    fk = flying_in_support(trajectory, apex)
    assert fk[4] == pytest.approx(0.1, abs=1e-6)
    assert fk[2] == pytest.approx(WalkParams().foot_rise, abs=1e-6)


def test_foot_overshoot_passes_the_landing_by_the_ratio_at_the_overshoot_phase():
    # Right foot steps 0.05 forward and 0.03 outward; the left foot (support) stands still.
    step = DoubleStep(Footstep(0.05, -0.03), Footstep(0.05))
    ratio, phase = 0.2, 0.75
    trajectory = walking(params(foot_overshoot_ratio=ratio, foot_overshoot_phase=phase), step)
    right = trajectory.local_poses[RIGHT]
    start_x, start_y = right[X, tick(DOUBLE_SUPPORT)], right[Y, tick(DOUBLE_SUPPORT)]
    land_x, land_y = right[X, tick(HALF)], right[Y, tick(HALF)]
    assert land_x == pytest.approx(0.05, abs=1e-12)  # the step: 0.05 ahead of the support sole
    assert land_y == pytest.approx(-(WalkParams().foot_distance + 0.03), abs=1e-12)
    i = tick(DOUBLE_SUPPORT + SINGLE_SUPPORT * phase)  # put-down phase 1: 0.4 s
    expected_x = land_x + ratio * land_x  # a share of the step's x
    expected_y = land_y + ratio * (land_y - start_y)  # a share of the y travel
    assert right[X, i] == pytest.approx(expected_x, abs=1e-12)
    assert right[Y, i] == pytest.approx(expected_y, abs=1e-12)
    assert start_x == pytest.approx(-0.05, abs=1e-12)
    fk = flying_in_support(trajectory, i)
    assert fk[:2] == pytest.approx([expected_x, expected_y], abs=1e-6)
    # Without the ratio the foot reaches the landing at the overshoot phase and holds it.
    held = walking(params(foot_overshoot_phase=phase), step).local_poses[RIGHT]
    assert held[X, i : tick(HALF) + 1] == pytest.approx(np.full(tick(HALF) + 1 - i, land_x), abs=1e-12)


def test_foot_z_pause_holds_the_apex_height_for_its_share_of_single_support():
    pause = 0.25  # 0.1 s around the apex at 0.3 s
    trajectory = walking(params(foot_z_pause=pause), FORWARD)
    z = trajectory.local_poses[RIGHT, Z]
    rise = WalkParams().foot_rise
    first, last = tick(0.3 - 0.5 * pause * SINGLE_SUPPORT), tick(0.3 + 0.5 * pause * SINGLE_SUPPORT)
    assert (first, last) == (124, 174)
    assert z[first : last + 1] == pytest.approx(np.full(last - first + 1, rise), abs=1e-12)
    assert z[first - 5] < rise - 1e-6 and z[last + 5] < rise - 1e-6
    assert z.max() == pytest.approx(rise, abs=1e-12)
    assert flying_in_support(trajectory, last)[2] == pytest.approx(rise, abs=1e-6)


def test_foot_put_down_z_offset_is_the_height_at_put_down_then_the_foot_is_lowered():
    offset, put_down = 0.01, 0.8  # put-down at 0.1 + 0.32 s
    trajectory = walking(params(foot_put_down_z_offset=offset, foot_put_down_phase=put_down), FORWARD)
    right = trajectory.local_poses[RIGHT]
    i = tick(DOUBLE_SUPPORT + SINGLE_SUPPORT * put_down)
    assert right[Z, i] == pytest.approx(offset, abs=1e-12)
    assert right[X, i] == pytest.approx(0.05, abs=1e-12)  # on the landing in x/y already
    assert right[Z, tick(HALF)] == pytest.approx(0.0, abs=1e-12)
    assert flying_in_support(trajectory, i)[2] == pytest.approx(offset, abs=1e-6)


# --- trunk ---------------------------------------------------------------------------------------

T1 = 0.25  # trunk apex over the support foot: 0.5 + (-0.25 + 0.5 · 0.2 · 0.5 + trunk_phase · 0.5) with trunk_phase -0.1


@pytest.mark.parametrize("step_x", [0.05, -0.04])
def test_trunk_x_offset_grows_by_p_coef_forward_times_step_x(step_x):
    step = DoubleStep(Footstep(step_x), Footstep(step_x))
    coef = 0.3
    trunk = walking(params(trunk_x_offset_p_coef_forward=coef), step).local_poses[TRUNK]
    assert trunk[X, tick(T1)] == pytest.approx(WalkParams().trunk_x_offset + coef * step_x, abs=1e-12)


def test_trunk_x_offset_grows_by_p_coef_turn_times_step_yaw():
    step = DoubleStep(Footstep(0.0, 0.0, -0.3), Footstep())  # right foot turns outward, left returns
    coef = 0.05
    trajectory = walking(params(trunk_x_offset_p_coef_turn=coef), step)
    yaw = trajectory.local_poses[RIGHT, YAW, tick(HALF)]
    assert yaw == pytest.approx(-0.3, abs=1e-12)
    assert trajectory.local_poses[TRUNK, X, tick(T1)] == pytest.approx(
        WalkParams().trunk_x_offset + coef * abs(yaw), abs=1e-12
    )


def test_trunk_pause_holds_the_lateral_apex_for_its_share_of_a_half_step():
    pause = 0.2  # 0.1 s around t1
    trunk = walking(params(trunk_pause=pause), FORWARD).local_poses[TRUNK]
    fd, p = WalkParams().foot_distance, WalkParams()
    apex_y = p.trunk_y_offset - 0.5 * fd * (1.0 - p.trunk_swing)  # over the left foot, right at y = -fd
    first, last = tick(T1 - 0.5 * pause * HALF), tick(T1 + 0.5 * pause * HALF)
    assert trunk[Y, first : last + 1] == pytest.approx(np.full(last - first + 1, apex_y), abs=1e-12)
    assert abs(trunk[Y, first - 10] - apex_y) > 1e-5


def test_first_step_trunk_phase_times_the_start_steps_apex():
    first_phase = -0.3  # start-step apex at 0.5 + (-0.25 + 0.05 - 0.15) = 0.15 s
    p = params(first_step_trunk_phase=first_phase)
    engine = make_engine(p)
    trajectory = engine.double_step(FORWARD)
    start = engine.start_ticks  # the start movement's ticks come first
    y = trajectory.local_poses[TRUNK, Y, start : start + tick(HALF) + 1]  # the start step, left support
    fd = p.foot_distance
    expected = p.trunk_y_offset - 0.5 * fd * (1.0 - p.trunk_swing * p.first_step_swing_factor)
    assert y[tick(0.15)] == pytest.approx(expected, abs=1e-12)
    assert abs(int(np.argmax(y)) - tick(0.15)) <= 2  # the lateral apex, towards the left foot
    normal = make_engine(params()).double_step(FORWARD).local_poses[TRUNK, Y, start : start + tick(HALF) + 1]
    assert abs(int(np.argmax(normal)) - tick(T1)) <= 2  # trunk_phase's apex
    # Walking steps use trunk_phase again: the second double step matches the plain gait's at t1.
    assert engine.double_step(FORWARD).local_poses[TRUNK, Y, tick(T1)] == pytest.approx(
        p.trunk_y_offset - 0.5 * fd * (1.0 - p.trunk_swing), abs=1e-12
    )


def test_first_step_trunk_phase_none_is_trunk_phase():
    default = make_engine(params())
    explicit = make_engine(params(first_step_trunk_phase=TIMED["trunk_phase"]))
    for engine in (default, explicit):
        engine.double_step(FORWARD)
    a, b = default.double_step(FORWARD), explicit.double_step(FORWARD)
    np.testing.assert_array_equal(a.joint_targets, b.joint_targets)
    assert WalkParams().start_trunk_phase == WalkParams().trunk_phase


# --- validation ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "field,value",
    [
        ("foot_overshoot_ratio", -0.1),
        ("foot_overshoot_phase", 0.0),
        ("foot_overshoot_phase", 1.5),
        ("foot_z_pause", 1.0),
        ("foot_put_down_z_offset", -0.01),
        ("trunk_pause", -0.1),
        ("engine_freq", 0.0),
        ("first_step_trunk_phase", math.inf),
        ("foot_apex_pitch", math.nan),
    ],
)
def test_invalid_new_walk_params_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        WalkParams(**{field: value})


def test_engine_rejects_swing_knots_out_of_order():
    with pytest.raises(ValueError, match="foot_z_pause"):
        make_engine(params(foot_z_pause=0.9, foot_put_down_phase=0.9))
    with pytest.raises(ValueError, match="foot_overshoot_phase"):
        make_engine(params(foot_overshoot_phase=0.4))  # before the apex at 0.5
    with pytest.raises(ValueError, match="foot_put_down_z_offset"):
        make_engine(params(foot_put_down_z_offset=0.01))  # put-down phase 1: no time left to lower


def test_from_mapping_takes_null_first_step_trunk_phase():
    assert WalkParams.from_mapping({"first_step_trunk_phase": None}).first_step_trunk_phase is None
    assert WalkParams.from_mapping({"first_step_trunk_phase": "-0.5"}).start_trunk_phase == -0.5


# --- presets against FACTS -----------------------------------------------------------------------

PRESETS = {"bitbots_sim": "sim", "bitbots_robot": "robot", "bitbots_2022": "dq_webots"}
NODE_KEYS = {"engine_freq", "x_speed_multiplier", "y_speed_multiplier", "yaw_speed_multiplier"}
# The walk node's trunk PID and foot-pressure phase reset: WalkParams field -> FACTS row.
NODE_ROWS = {
    **{
        f"trunk_pid_{axis}_{gain}": f"node.trunk_pid.{axis}.{gain}"
        for axis in ("pitch", "roll")
        for gain in ("p", "i", "d", "i_clamp_min", "i_clamp_max")
    },
    "phase_reset_foot_pressure_active": "node.phase_reset.foot_pressure.active",
    "phase_reset_min_phase": "node.phase_reset.min_phase",
    "phase_reset_ground_min_pressure": "node.phase_reset.foot_pressure.ground_min_pressure",
}


def facts_row(key: str) -> str:
    if key in NODE_ROWS:
        return NODE_ROWS[key]
    return f"node.{key}" if key in NODE_KEYS else f"engine.{key}"


MISSING = "—"


def facts_parameter_table(text: str) -> dict[str, dict[str, str]]:
    """``{row: {column: cell}}`` of the markdown table under "## Quintic walk: all parameters"."""
    lines = text.splitlines()
    begin = next(i for i, line in enumerate(lines) if line.startswith("## Quintic walk: all parameters"))
    header, table = None, {}
    for line in lines[begin + 1 :]:
        if line.startswith("## "):
            break
        if not line.lstrip().startswith("|"):
            continue
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
        elif not all(set(cell) <= set("-: ") for cell in cells):
            table[cells[0]] = dict(zip(header[1:], cells[1:]))
    return table


@pytest.fixture(scope="module")
def facts_table():
    return facts_parameter_table(facts_text())


def preset(name: str) -> dict:
    """The preset file's own values, read with OmegaConf (not footsim's composer); its Hydra
    ``defaults`` list names the schema and carries no value."""
    values = OmegaConf.to_container(OmegaConf.load(REPO / "conf" / "walk" / f"{name}.yaml"))
    assert isinstance(values, dict)
    values.pop("defaults", None)
    return values


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_values_are_the_facts_table_column(name, facts_table):
    column = PRESETS[name]
    values = preset(name)
    for key, value in values.items():
        row = facts_row(key)
        assert row in facts_table, f"{name}.{key}: no FACTS row {row}"
        cell = facts_table[row][column]
        assert cell != MISSING, f"{name}.{key}: FACTS has no {column} value"
        if isinstance(value, bool):
            assert str(value) == cell, f"{name}.{key} = {value}, FACTS {column} = {cell}"
        else:
            assert float(value) == float(cell), f"{name}.{key} = {value}, FACTS {column} = {cell}"
    # Every engine row FACTS gives for this column is in the preset (the kick excepted: no kick).
    for row, cells in facts_table.items():
        if row.startswith("engine.") and not row.startswith("engine.kick_") and cells[column] != MISSING:
            assert row[len("engine.") :] in values, f"{name} lacks {row} = {cells[column]}"
    assert NODE_KEYS <= set(values) and set(NODE_ROWS) <= set(values)
    WalkParams.from_mapping(values)  # loads


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_presets_walk_in_the_engine_at_the_3d_control_tick(name):
    p = WalkParams.from_mapping(preset(name))
    engine = make_engine(p, control_dt=0.01)
    assert engine.ticks_per_double_step == round(1.0 / (p.freq * 0.01))
    rng = np.random.default_rng(3)
    for _ in range(10):
        trajectory = engine.double_step(DoubleStep.from_action(rng.uniform(-0.4, 0.4, 6), LIMITS))
        assert trajectory.reachable.all() and np.isfinite(trajectory.joint_targets).all()
    assert len(engine.stop()) == engine.ticks_per_double_step


def test_facts_table_parser_reads_a_small_table():
    text = "\n".join(
        [
            "## Quintic walk: all parameters (x)",
            "| parameter | a | b |",
            "|---|---|---|",
            "| engine.freq | 1.0 | — |",
            "## z",
        ]
    )
    assert facts_parameter_table(text) == {"engine.freq": {"a": "1.0", "b": "—"}}


# --- footsim's own tuned gait as a named preset --------------------------------------------------


def test_footsim_slow_is_the_v0_gait_and_bitbots_sim_the_3d_default():
    from footsim.config import load_preset

    slow = load_preset("walk", "footsim_slow")
    assert slow["freq"] == 0.819559 and slow["trunk_height"] == 0.360584  # the tuned 0.82 Hz gait
    assert WalkParams.from_mapping(slow).double_step_duration == pytest.approx(1.0 / 0.819559)
    sim = load_preset("walk", "bitbots_sim")
    for backend in ("mujoco", "dm_control", "pybullet"):
        assert load_preset("walk", backend=backend) == sim, backend
        assert load_preset("walk", backend=f"{backend}_v0") == slow, backend
