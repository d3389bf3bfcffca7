"""The walk node's options in the 3D driver (WalkParams.engine_freq, trunk_pid_*, phase_reset_*):
the engine update rate, the Bit-Bots' trunk PID and the phase reset on foot contact.

Most checks drive ``Physics3DBackend`` on a sim without physics (:class:`StillSim`: a base held
at a fixed tilt, the leg commands recorded per tick, scripted foot forces), so the expectations
are hand-computed; the phase reset is also checked on MuJoCo and PyBullet with a bump in the floor
under the swing foot's landing."""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

import footsim.config as fconf
from footsim.backends.control import PID, TrunkPID
from footsim.backends.physics3d import Physics3DBackend, PhysicsSim, SimState, quat_to_matrix
from footsim.geometry import Pose2D
from footsim.scene import Obstacle, Scene
from footsim.walk import DoubleStep, Footstep, QuinticWalk, WalkParams
from footsim.walk.engine import WalkState
from footsim.walk.ik import leg_fk, rotation_from_rpy

ROBOT = fconf.build_robot("wolfgang")
SLOW = fconf.build_walk(fconf.load_preset("walk", "footsim_slow"))
EMPTY = Scene(goal=Pose2D(100.0, 0.0, 0.0))
FORWARD = DoubleStep(Footstep(0.05), Footstep(0.05))


class StillSim(PhysicsSim):
    """No physics: the base stays at a fixed fused ``pitch``; ``sent`` gets the leg commands after
    every control tick (one ``advance`` per tick); ``forces`` (left, right) [N] are the foot
    forces, or a callable of the tick count."""

    def __init__(self, pitch: float = 0.0, forces=(0.0, 0.0)):
        self.pitch, self.forces = pitch, forces
        self.sent: list[np.ndarray] = []

    def build(self, robot, physics_dt: float) -> None:
        half = 0.5 * self.pitch
        self.state = SimState(
            quat=np.array([math.cos(half), 0.0, math.sin(half), 0.0]),  # (w, x, y, z): about +y
            position=np.array([0.0, 0.0, 0.4]),
            command=np.zeros(12),
            leg_ids=np.arange(12),
            finite=(np.zeros(1),),
        )

    def set_obstacles(self, scene: Scene) -> None:
        pass

    def reset_robot(self, base_position, joint_positions) -> None:
        pass

    def advance(self, n_steps: int) -> None:
        self.sent.append(self.state.command.copy())

    def base_pose(self):
        return self.state.position.copy(), quat_to_matrix(self.state.quat)

    def obstacle_contact(self) -> bool:
        return False

    def sole_forces(self) -> tuple[float, float]:
        forces = self.forces(len(self.sent)) if callable(self.forces) else self.forces
        return float(forces[0]), float(forces[1])


def still_backend(walk: WalkParams, sim: StillSim, dt: float = 0.01) -> Physics3DBackend:
    backend = Physics3DBackend(robot=ROBOT, walk=walk, sim=sim, control_dt=dt, physics_dt=dt)
    backend.reset(EMPTY, np.random.default_rng(0))
    sim.sent.clear()  # the settling advance at reset
    return backend


def engine_alone(walk: WalkParams, dt: float = 0.01) -> QuinticWalk:
    """A second engine like the backend's, to compute the planned trajectory independently."""
    backend = Physics3DBackend(robot=ROBOT, walk=walk, sim=StillSim(), control_dt=dt, physics_dt=dt)
    return backend.engine


# --- the PID -------------------------------------------------------------------------------------


def test_pid_terms_by_hand():
    pid = PID(p=0.0035, i=0.5, d=0.004, i_min=-0.001, i_max=0.001)
    # first update: no previous error, so no D; I = 0.5 * 0.1 * 0.01 = 0.0005
    assert pid.update(0.1, 0.01) == pytest.approx(0.0035 * 0.1 + 0.0005, abs=1e-15)
    # second: I = 0.0005 + 0.5 * 0.05 * 0.01 = 0.00075; D = 0.004 * (0.05 - 0.1) / 0.01 = -0.02
    assert pid.update(0.05, 0.01) == pytest.approx(0.0035 * 0.05 + 0.00075 - 0.02, abs=1e-15)
    # the I term stops at its clamp: 0.00075 + 0.5 * 0.2 * 0.01 = 0.00175 -> 0.001
    assert pid.update(0.2, 0.01) == pytest.approx(0.0035 * 0.2 + 0.001 + 0.004 * (0.2 - 0.05) / 0.01, abs=1e-15)
    pid.reset()
    assert pid.update(0.1, 0.01) == pytest.approx(0.0035 * 0.1 + 0.0005, abs=1e-15)


def test_trunk_pid_reads_the_walk_params_and_maps_pitch_to_x_and_roll_to_y():
    walk = WalkParams(trunk_pid_pitch_p=0.01, trunk_pid_roll_p=-0.02)
    pid = TrunkPID.from_walk(walk)
    assert pid.active and not TrunkPID.from_walk(WalkParams()).active
    assert pid.shift(roll_error=0.1, pitch_error=0.2, dt=0.01) == pytest.approx((0.002, -0.002))


def test_trunk_pid_shifts_the_trunk_in_the_support_frame_by_the_gain_times_the_error():
    """The base leans 0.1 rad further forward than planned: with pitch p = 0.02 m/rad the trunk
    moves by 0.02 × (planned − 0.1 − ...) in x of the support-sole frame, so both soles move by
    minus that shift, seen from the trunk."""
    p_gain, measured = 0.02, 0.1
    walk = dataclasses.replace(SLOW, trunk_pid_pitch_p=p_gain)
    sim = StillSim(pitch=measured)
    backend = still_backend(walk, sim)
    backend.execute(FORWARD)
    planned = engine_alone(walk).double_step(FORWARD)  # the same engine call, without the PID
    assert len(sim.sent) == len(planned)
    leg = ROBOT.leg_geometry
    checked = 0
    for k in range(0, len(planned), 7):
        trunk = planned.local_poses[2, :, k]
        dx = p_gain * (trunk[4] - measured)  # planned fused pitch = the trunk's pitch (it never rolls)
        expected_shift = -rotation_from_rpy(trunk[3:]).T @ np.array([dx, 0.0, 0.0])
        for side, joints in (("left", slice(0, 6)), ("right", slice(6, 12))):
            moved, _ = leg_fk(sim.sent[k][None, joints], side, leg)
            plain, _ = leg_fk(planned.joint_targets[k][None, joints], side, leg)
            assert np.allclose(moved[0] - plain[0], expected_shift, atol=1e-9), (k, side)
        assert dx < 0  # leaning forward more than planned: the trunk goes back over the support foot
        checked += 1
    assert checked > 20


def test_zero_gains_send_the_engines_targets_untouched():
    sim = StillSim(pitch=0.1)
    backend = still_backend(SLOW, sim)
    backend.execute(FORWARD)
    planned = engine_alone(SLOW).double_step(FORWARD)
    assert np.array_equal(np.array(sim.sent), planned.joint_targets)


# --- the engine update rate ----------------------------------------------------------------------


@pytest.mark.parametrize(
    "control_dt,engine_freq,per_second",
    [
        (0.002, 125.0, 125),  # an update every 4 ticks
        (0.01, 50.0, 50),  # every 2 ticks
        (0.01, 125.0, 100),  # the engine outpaces the control: every tick
        (0.002, None, 500),  # no rate: every tick
    ],
)
def test_engine_freq_sets_how_often_the_targets_change(control_dt, engine_freq, per_second):
    walk = dataclasses.replace(SLOW, engine_freq=engine_freq)
    sim = StillSim()
    backend = still_backend(walk, sim, dt=control_dt)
    standing = backend.engine.standing_joint_targets()
    backend.execute(FORWARD)  # the start movement and a double step: 1.83 s
    second = round(1.0 / control_dt)
    sent = [standing, *sim.sent[:second]]  # tick K (from 1) sends sent[K]; at reset: standing
    changes = sum(not np.array_equal(a, b) for a, b in zip(sent, sent[1:]))
    assert changes == per_second
    # Each held target is the engine's at the tick that saw the update.
    planned = engine_alone(walk, control_dt).double_step(FORWARD).joint_targets
    every = 1 if engine_freq is None else max(1, round(1.0 / (engine_freq * control_dt)))
    for k in range(0, second):
        update = (k + 1) // every * every - 1  # the last tick K = update + 1 with K % every == 0
        assert np.array_equal(sim.sent[k], standing if update < 0 else planned[update]), k


# --- the phase reset -----------------------------------------------------------------------------


def test_end_step_places_the_foot_where_it_is_and_starts_the_next_step_at_once():
    engine = engine_alone(SLOW)
    engine.double_step(FORWARD)  # from IDLE: start movement first
    trajectory = engine.double_step(FORWARD)
    n = len(trajectory)
    half = engine.ticks_per_double_step // 2
    k = half - 10  # ten ticks before the planned put-down of the right foot
    foot = trajectory.local_poses[1, :, k]  # right sole in the left-support frame
    rest = engine.end_step(trajectory, k)
    assert len(rest) == round(engine.half_period / engine.control_dt)  # the second step, in full
    assert rest.t[0] == pytest.approx(trajectory.t[k] + engine.control_dt)
    assert not rest.support[0] and rest.state[0] == WalkState.WALKING  # right support now
    left = trajectory.feet.left  # before the call's second step the left foot was the support
    support_before = trajectory.support_poses[:, k]
    placed = Pose2D(*support_before).compose(Pose2D(foot[0], foot[1], foot[5]))
    assert rest.support_poses[:, 0] == pytest.approx([placed.x, placed.y, placed.theta])
    # the trunk carries on from where it was: one tick of motion, not a jump
    before = trajectory.trunk[k]
    after = rest.trunk[0]
    assert np.abs(after[:2] - before[:2]).max() < 0.01
    assert after[2] == pytest.approx(before[2] - foot[2], abs=0.01)  # the support plane rose by the foot's height
    # the executed double step: the right foot where it landed, the left one as planned from there
    executed = rest.executed
    assert executed.first.x == pytest.approx(foot[0]) and executed.first.x < FORWARD.first.x
    assert executed.second == trajectory.executed.second
    assert rest.feet.right == placed and rest.feet.left != left
    assert k + 1 + len(rest) < n  # the double step is shorter
    # an end in the second step ends the call
    last = engine.end_step(rest, len(rest) - 5)
    assert len(last) == 0 and last.executed.second.x < FORWARD.second.x


def test_end_step_refuses_ticks_without_a_flying_foot():
    engine = engine_alone(SLOW)
    trajectory = engine.double_step(FORWARD)  # starts with the start movement (no flying foot)
    with pytest.raises(ValueError, match="START_MOVEMENT"):
        engine.end_step(trajectory, 0)
    with pytest.raises(ValueError, match="last double step"):
        engine.end_step(engine_alone(SLOW).double_step(FORWARD), 400)


def test_phase_reset_ends_the_step_at_the_first_contact_in_the_window():
    """The right (flying) foot reports 5 N from tick ``touch`` on: the step ends there once the
    phase passes min_phase / 2 of the half step; without the option nothing changes."""
    engine = engine_alone(SLOW)
    n, start = engine.ticks_per_double_step, engine.start_ticks  # 122 and 61 ticks of 0.01 s
    half = n // 2
    touch = start + half - 8  # 8 ticks before the right foot's planned put-down
    walk = dataclasses.replace(SLOW, phase_reset_foot_pressure_active=True, phase_reset_min_phase=0.5)

    def forces(ticks_sent):  # sole_forces is read after tick k's physics: len(sent) = k + 1
        return (0.0, 5.0) if ticks_sent - 1 >= touch else (0.0, 0.0)

    sim = StillSim(forces=forces)
    result = still_backend(walk, sim).execute(FORWARD)
    # tick `touch` ends the first step; the second runs its full half period
    assert len(sim.sent) == touch + 1 + round(engine.half_period / engine.control_dt)
    assert result.duration_s == pytest.approx(len(sim.sent) * 0.01)
    assert result.executed.first.x < FORWARD.first.x
    off = StillSim(forces=forces)
    plain = still_backend(SLOW, off).execute(FORWARD)
    assert len(off.sent) == start + n and plain.executed == FORWARD


def test_phase_reset_ignores_contact_before_the_window():
    walk = dataclasses.replace(SLOW, phase_reset_foot_pressure_active=True, phase_reset_min_phase=0.9)
    engine = engine_alone(SLOW)
    sim = StillSim(forces=(50.0, 50.0))  # both feet loaded all the time
    still_backend(walk, sim).execute(FORWARD)
    half = engine.ticks_per_double_step // 2  # 61 ticks: tick j of a half step has phase 0.5 j / 61 (+ 0.5)
    # no reset in the start movement; each step ends at its first tick past 90 %: j = 55 > 54.9
    first_window = math.floor(0.9 * half) + 1
    assert first_window == 55
    assert len(sim.sent) == engine.start_ticks + 2 * first_window


# --- on the simulators: a bump under the swing foot's landing ------------------------------------

BUMP_X, BUMP_Y, BUMP_RADIUS, BUMP_HEIGHT = 0.3, -0.09, 1.0, 0.025  # a 2.5 cm cap of a 1 m sphere
LONG = DoubleStep(Footstep(0.156), Footstep(0.0))  # the right foot's toe lands on the cap


def _bumped_backend(name: str, phase_reset: bool, bump: bool):
    """The backend with its walk and the phase reset on or off, reset on a floor with or without
    the bump; and what removes the bump (PyBullet parks its world for the next backend)."""
    pytest.importorskip("mujoco" if name == "mujoco" else "pybullet")
    # FootstepNav-v0's setup (its slow gait lands the long step on the bump's side reliably).
    walk = fconf.build_walk(
        {
            **fconf.load_preset("walk", "footsim_slow"),
            "phase_reset_foot_pressure_active": phase_reset,
            "phase_reset_min_phase": 0.5,
        }
    )
    backend = fconf.build_backend(
        fconf.load_preset("backend", f"{name}_v0"), fconf.build_robot("wolfgang_simplified"), walk
    )
    if name == "mujoco":
        import mujoco

        # The ball's pool geom (its own body), grown into the sphere and sunk into the floor.
        scene = Scene(goal=EMPTY.goal, ball=Obstacle(BUMP_X, BUMP_Y, 0.05)) if bump else EMPTY
        backend.reset(scene, np.random.default_rng(0))
        if bump:
            m, d = backend.sim.mj_model_data()
            g = int(backend.sim.obstacle_geoms[-1])
            r = BUMP_RADIUS
            m.geom_size[g], m.body_pos[m.geom_bodyid[g]] = (r, 0.0, 0.0), (BUMP_X, BUMP_Y, BUMP_HEIGHT - r)
            m.geom_rbound[g], m.geom_aabb[g] = r, (0.0, 0.0, 0.0, r, r, r)
            mujoco.mj_forward(m, d)
    else:
        import pybullet as p

        c = backend.sim.client
        if bump:
            shape = p.createCollisionShape(p.GEOM_SPHERE, radius=BUMP_RADIUS, physicsClientId=c)
            body = p.createMultiBody(0, shape, -1, [BUMP_X, BUMP_Y, BUMP_HEIGHT - BUMP_RADIUS], physicsClientId=c)
            backend.reset(EMPTY, np.random.default_rng(0))
            return backend, lambda: p.removeBody(body, physicsClientId=c)
        backend.reset(EMPTY, np.random.default_rng(0))
    return backend, lambda: None


@pytest.mark.parametrize("name", ["mujoco", "pybullet"])
def test_phase_reset_ends_the_step_early_on_a_bump(name):
    runs = {}
    for phase_reset, bump in ((True, True), (True, False), (False, True)):
        backend, remove_bump = _bumped_backend(name, phase_reset, bump)
        try:
            runs[phase_reset, bump] = backend.execute(LONG)
            ticks = backend.engine.start_ticks + backend.engine.ticks_per_double_step
            control_dt = backend.control_dt
        finally:
            remove_bump()
            backend.close()
    on_bump, on_flat, off_bump = runs[True, True], runs[True, False], runs[False, True]
    # Off: the double step runs in full and lands where commanded, bump or not.
    assert off_bump.duration_s == pytest.approx(ticks * control_dt) and off_bump.executed == LONG
    # On: the right foot meets the bump early, the step ends there, shorter than on the flat floor.
    assert on_bump.duration_s < off_bump.duration_s - 0.05
    assert on_bump.executed.first.x < on_flat.executed.first.x - 0.002
    assert on_bump.executed.first.x < LONG.first.x
    assert on_bump.max_tilt < 0.5


@pytest.mark.parametrize("name", ["mujoco", "dm_control", "pybullet"])
def test_sole_forces_carry_the_robots_weight_standing(name):
    pytest.importorskip({"mujoco": "mujoco", "dm_control": "dm_control", "pybullet": "pybullet"}[name])
    walk = fconf.build_walk(fconf.load_preset("walk", backend=name))
    backend = fconf.build_backend(fconf.load_preset("backend", {"name": name}), ROBOT, walk)
    try:
        backend.reset(EMPTY, np.random.default_rng(0))
        backend.hold(0.5)
        left, right = backend.sim.sole_forces()
    finally:
        backend.close()
    weight = ROBOT.total_mass * 9.81
    assert left + right == pytest.approx(weight, rel=0.03)
    # Standing on both feet; how the weight splits is statically indeterminate (two feet on the
    # floor close the chain), and on PyBullet it wanders by ±15 N while the robot stands still.
    assert min(left, right) > 0.25 * weight


@pytest.mark.parametrize(
    "values,field",
    [
        ({"phase_reset_foot_pressure_active": 1.0}, "phase_reset_foot_pressure_active"),
        ({"phase_reset_min_phase": 1.5}, "phase_reset_min_phase"),
        ({"phase_reset_ground_min_pressure": -1.0}, "phase_reset_ground_min_pressure"),
        ({"trunk_pid_pitch_i_clamp_min": 0.01}, "trunk_pid_pitch_i_clamp_min"),  # above its max (0)
        ({"trunk_pid_roll_d": math.nan}, "trunk_pid_roll_d"),
        ({"engine_freq": -125.0}, "engine_freq"),
    ],
)
def test_invalid_walk_node_options_name_the_field(values, field):
    with pytest.raises(ValueError, match=field):
        WalkParams(**values)


def test_walk_node_options_load_from_a_config_mapping():
    p = WalkParams.from_mapping(
        {"engine_freq": None, "phase_reset_foot_pressure_active": True, "trunk_pid_roll_p": "0.1"}
    )
    assert p.engine_freq is None and p.phase_reset_foot_pressure_active is True and p.trunk_pid_roll_p == 0.1
    assert WalkParams.from_mapping({"engine_freq": 125}).engine_freq == 125.0


@pytest.mark.parametrize("name", ["mujoco", "dm_control", "pybullet"])
def test_trunk_pid_acts_on_every_3d_backend(name):
    """The PID reads each sim's tilt (PyBullet: through read_state) and changes the commands:
    after a double step the last command differs from the engine's target by the IK of the shift."""
    pytest.importorskip({"mujoco": "mujoco", "dm_control": "dm_control", "pybullet": "pybullet"}[name])
    base = fconf.load_preset("walk", backend=name)
    results = {}
    for p_gain in (0.0, 0.05):
        walk = fconf.build_walk({**base, "trunk_pid_pitch_p": p_gain})
        backend = fconf.build_backend(fconf.load_preset("backend", {"name": name}), ROBOT, walk)
        try:
            backend.reset(EMPTY, np.random.default_rng(0))
            result = backend.execute(FORWARD)
            results[p_gain] = (result.pose, backend.sim.state.last_targets())
        finally:
            backend.close()
    (plain_pose, plain_targets), (pid_pose, pid_targets) = results[0.0], results[0.05]
    assert not np.allclose(plain_targets, pid_targets, atol=1e-6)
    assert plain_pose != pid_pose
