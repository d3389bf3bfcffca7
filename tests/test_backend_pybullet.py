"""PyBullet backend specifics: turning, name mapping, faults, obstacle pool, coexisting clients, memory,
contact distance, the state contract, servo mode, armature (the common contract:
tests/test_backend_contract.py)."""

import math
import os

import numpy as np
import pytest

pybullet = pytest.importorskip("pybullet")


import footsim  # noqa: E402,F401  (registers the env)
from footsim.backends.bullet.sim import PybulletBackend  # noqa: E402
from footsim.backends.control import base_tilt, fused_roll_pitch, state_ok  # noqa: E402
from footsim.calibration.walkcheck import make_backend  # noqa: E402
from footsim.env import FootstepEnv  # noqa: E402
from footsim.geometry import Pose2D  # noqa: E402
from footsim.robots.urdf import urdf_xml  # noqa: E402
from footsim.scene import Obstacle, Scene  # noqa: E402
from footsim.walk.footsteps import DoubleStep  # noqa: E402
from footsim.walk.ik import LEG_JOINT_NAMES  # noqa: E402

EMPTY = Scene(goal=Pose2D(100.0, 0.0, 0.0))
FORWARD = np.array([0.5, 0.0, 0.0, 0.5, 0.0, 0.0])


# The tests share a module-scoped backend or env whose state one hands on to the next: under xdist
# they run on one worker, in file order (--dist loadgroup).
pytestmark = pytest.mark.xdist_group("test_backend_pybullet")


@pytest.fixture(scope="module")
def backend():
    b = make_backend("pybullet")
    yield b
    b.close()


@pytest.mark.parametrize("direction", [1, -1])
def test_max_turns_do_not_fall_and_turn_as_commanded(backend, direction):
    """Max turns are where a weak contact solver fails first (the stance foot slips):
    8 double steps of max turn must not fall and must turn within the walk check's 25 % of the
    planar footstep geometry's yaw (the 2D backend executing the same actions)."""
    from footsim.calibration.walkcheck import Sequence, run_sequence

    turn = Sequence("turn", np.tile([0, 0, direction, 0, 0, direction], (8, 1)).astype(float), "yaw")
    planar = make_backend("pymunk")
    try:
        commanded = run_sequence(planar, turn)["yaw"]
    finally:
        planar.close()
    executed = run_sequence(backend, turn)
    assert not executed["fell"] and executed["sim_error"] is None
    assert abs(commanded) > 10.0  # 8 x 2 x 0.764 rad, less the start step's shorter turn
    assert abs(executed["yaw"] - commanded) < 0.25 * abs(commanded)


def test_joint_name_mapping(backend):
    sim, c = backend.sim, backend.sim.client
    assert set(LEG_JOINT_NAMES) <= set(sim.joint_index)
    for name, index in sim.joint_index.items():
        info = pybullet.getJointInfo(sim.robot_id, index, physicsClientId=c)
        assert info[1].decode() == name
        assert info[12].decode() == backend.robot.joint(name).child
        assert (info[8], info[9]) == pytest.approx(backend.robot.joint(name).range)
    assert sim.leg_indices == [sim.joint_index[n] for n in LEG_JOINT_NAMES]
    # targets reach the right joints: a distinct target per leg joint, robot held in the air
    backend.reset(EMPTY, np.random.default_rng(0))
    targets = backend.engine.standing_joint_targets() + np.linspace(-0.06, 0.06, 12)
    pybullet.setGravity(0, 0, 0, physicsClientId=c)
    pos, orn = pybullet.getBasePositionAndOrientation(sim.robot_id, physicsClientId=c)
    pybullet.resetBasePositionAndOrientation(sim.robot_id, [pos[0], pos[1], pos[2] + 0.3], orn, physicsClientId=c)
    try:
        sim.set_leg_targets(targets)
        sim.advance(300)
        reached = np.array([sim.joint_positions()[n] for n in LEG_JOINT_NAMES])
    finally:
        pybullet.setGravity(0, 0, -9.81, physicsClientId=c)
    np.testing.assert_allclose(reached, targets, atol=0.02)
    assert np.argsort(reached).tolist() == np.argsort(targets).tolist()


def test_full_model_maps_every_spec_joint(backend):
    full = PybulletBackend(backend.robot, backend.walk, rigid_upper_body=False)
    try:
        assert set(full.sim.joint_index) == set(backend.robot.joint_names)
        full.reset(EMPTY, np.random.default_rng(0))
        q = full.sim.joint_positions()
        for name, angle in backend.robot.walk_ready.items():
            if name not in LEG_JOINT_NAMES:
                assert q[name] == pytest.approx(angle, abs=0.05), name
    finally:
        full.close()
    assert 'type="fixed"' in urdf_xml(backend.robot, True)


def test_blow_up_is_a_sim_error_with_finite_observation():
    env = FootstepEnv(backend="pybullet")
    try:
        env.reset(seed=1)
        sim = env.unwrapped.backend.sim
        pybullet.resetBaseVelocity(sim.robot_id, [float("nan")] * 3, [0, 0, 0], physicsClientId=sim.client)
        obs, reward, term, trunc, info = env.step(FORWARD)
        assert term and info["outcome"] == "sim_error" and "sim_error" in info
        assert np.all(np.isfinite(obs)) and np.isfinite(reward)
        for kick in ([0.0, 0.0, 200.0], [0.0, 0.0, 0.0]):  # exploding velocity; far out of bounds
            env.reset(seed=2)  # the env recovers on reset
            sim = env.unwrapped.backend.sim
            if kick[2]:
                for _ in range(10):  # a persistent blow-up, not a single kick Bullet absorbs
                    pybullet.resetBaseVelocity(sim.robot_id, kick, [0, 0, 0], physicsClientId=sim.client)
                    sim.advance(1)
            else:
                pybullet.resetBasePositionAndOrientation(
                    sim.robot_id, [0, 0, 1e4], [0, 0, 0, 1], physicsClientId=sim.client
                )
            out = max(abs(v) for v in sim.base_pose()[0]) > env.unwrapped.backend.out_of_bounds
            assert sim.sim_error() is not None or out  # what the driver's full check reports
            obs, reward, term, trunc, info = env.step(FORWARD)
            assert term and info["outcome"] == "sim_error", info["outcome"]
            assert np.all(np.isfinite(obs))
    finally:
        env.close()


def test_obstacles_and_ball_are_placed(backend):
    sim, c = backend.sim, backend.sim.client
    scene = Scene(
        goal=Pose2D(3.0, 0.0, 0.0),
        obstacles=(Obstacle(1.0, 0.5, 0.2), Obstacle(2.0, -0.5, 0.3)),
        ball=Obstacle(1.5, 0.0, 0.075),
    )
    backend.reset(scene, np.random.default_rng(0))
    assert len(sim.obstacle_ids) == 3
    pos = [pybullet.getBasePositionAndOrientation(b, physicsClientId=c)[0] for b in sim.obstacle_ids]
    np.testing.assert_allclose(pos[0][:2], (1.0, 0.5))
    np.testing.assert_allclose(pos[2], (1.5, 0.0, 0.075))
    assert pybullet.getCollisionShapeData(sim.obstacle_ids[1], -1, physicsClientId=c)[0][2] == pybullet.GEOM_CYLINDER
    assert pybullet.getCollisionShapeData(sim.obstacle_ids[2], -1, physicsClientId=c)[0][2] == pybullet.GEOM_SPHERE
    assert not sim.obstacle_contact()
    placed = list(sim.obstacle_ids)
    backend.reset(EMPTY, np.random.default_rng(0))
    assert sim.obstacle_ids == []  # the bodies are parked far below the floor, kept for reuse
    assert all(pybullet.getBasePositionAndOrientation(b, physicsClientId=c)[0][2] < -50 for b in placed)


def test_obstacle_bodies_take_each_episodes_radius_and_stay_few(backend):
    """The pooled unit-size bodies, scaled per episode, have the scene's geometry: the distance
    from a small probe sphere is the analytic distance to a cylinder (or ball) of the scene's
    radius.  Over 60 episodes with fresh random radii the number of bodies in the world stays
    what the first episode left (Bullet slows with every body in the world, parked or not; the
    earlier pool kept one body per radius ever seen)."""
    sim, c = backend.sim, backend.sim.client
    probe_radius = 0.01
    probe = pybullet.createMultiBody(
        0,
        pybullet.createCollisionShape(pybullet.GEOM_SPHERE, radius=probe_radius, physicsClientId=c),
        -1,
        [0, 0, -50],
        physicsClientId=c,
    )
    rng = np.random.default_rng(5)
    counts = []
    try:
        for episode in range(60):
            obstacles = tuple(
                Obstacle(float(x), float(y), float(r))
                for x, y, r in zip(rng.uniform(1, 3, 3), rng.uniform(-2, 2, 3), rng.uniform(0.05, 0.35, 3))
            )
            ball = Obstacle(float(rng.uniform(1, 3)), float(rng.uniform(-2, 2)), float(rng.uniform(0.05, 0.1)))
            backend.reset(Scene(goal=Pose2D(5.0, 0.0, 0.0), obstacles=obstacles, ball=ball), rng)
            counts.append(pybullet.getNumBodies(physicsClientId=c))
            if episode % 10:
                continue
            for body, obstacle, is_ball in zip(sim.obstacle_ids, (*obstacles, ball), (False,) * 3 + (True,)):
                gap = float(rng.uniform(0.01, 0.05))
                angle = float(rng.uniform(-np.pi, np.pi))
                z = obstacle.r if is_ball else 0.3
                at = [
                    obstacle.x + (obstacle.r + gap) * np.cos(angle),
                    obstacle.y + (obstacle.r + gap) * np.sin(angle),
                    z,
                ]
                pybullet.resetBasePositionAndOrientation(probe, at, [0, 0, 0, 1], physicsClientId=c)
                distance = pybullet.getClosestPoints(body, probe, 0.2, physicsClientId=c)[0][8]
                assert distance == pytest.approx(gap - probe_radius, abs=1e-4), (episode, obstacle, is_ball)
    finally:
        pybullet.removeBody(probe, physicsClientId=c)
    assert max(counts) == counts[0]


def test_several_backends_coexist(backend):
    other = make_backend("pybullet")
    try:
        assert other.sim.client != backend.sim.client
        a = backend.reset(EMPTY, np.random.default_rng(0))
        b = other.reset(EMPTY, np.random.default_rng(0))
        assert a == b
    finally:
        other.close()
    assert backend.sim.base_pose()[0][2] > 0.3  # still usable after the other one closed


def _rss_mb():
    psutil = pytest.importorskip("psutil")
    return psutil.Process(os.getpid()).memory_info().rss / 2**20


@pytest.mark.memory
def test_create_reset_close_cycles_do_not_leak(backend):
    for _ in range(20):  # warm up allocators
        PybulletBackend(backend.robot, backend.walk).close()
        backend.reset(EMPTY, np.random.default_rng(0))
    before = _rss_mb()
    rng = np.random.default_rng(0)
    for i in range(200):
        scene = Scene(
            goal=Pose2D(1.0, 0.0, 0.0),
            obstacles=(Obstacle(2.0, float(rng.uniform(-1, 1)), 0.2),),
            ball=Obstacle(1.2, 0.0, 0.075) if i % 2 else None,
        )
        backend.reset(scene, rng)
    after_resets = _rss_mb()
    paths = []
    for _ in range(200):
        b = PybulletBackend(backend.robot, backend.walk)
        b.reset(EMPTY, rng)
        paths.append(b.sim.urdf_path)
        b.close()
    end = _rss_mb()
    assert after_resets - before < 10.0, f"RSS grew {after_resets - before:.1f} MB over 200 resets"
    assert end - after_resets < 10.0, f"RSS grew {end - after_resets:.1f} MB over 200 create/reset/close cycles"
    assert not any(os.path.exists(p) for p in paths)  # temp URDF files removed


def test_obstacle_contact_means_touching_not_merely_near():
    """An obstacle is moved towards the standing robot in 0.5 mm steps across the first touch:
    ``obstacle_contact`` must agree with Bullet's own closest-point distance (touching or
    penetrating), not with ``getContactPoints`` (which for some shape pairs lists points that are
    still apart within Bullet's contact-breaking threshold)."""

    # The penetrating side needs an obstacle the robot still overlaps after the reset's settle: at
    # the default 50 solver iterations the settle pushes the robot out of it, at 10 it stays.
    backend = make_backend("pybullet", backend_overrides={"solver_iterations": 10, "physics_dt": 1 / 240})
    try:

        def placed(x: float) -> float:
            """The obstacle at ``x``; Bullet's closest-point gap to the robot (0.05 = farther)."""
            backend.reset(
                Scene(goal=Pose2D(1.0, 0.0, 0.0), obstacles=(Obstacle(float(x), 0.0, 0.1),)), np.random.default_rng(0)
            )
            sim = backend.sim
            closest = pybullet.getClosestPoints(sim.robot_id, sim.obstacle_ids[0], 0.05, physicsClientId=sim.client)
            return min((point[8] for point in closest), default=0.05)

        touch = next(x for x in np.arange(0.40, 0.05, -0.005) if placed(x) < 0.005)  # first touch, to 5 mm
        seen = set()
        for x in np.arange(touch + 0.004, touch - 0.008, -0.0005):
            gap = placed(x)
            if abs(gap) > 1e-4:  # skip exact touching, where the two queries may round differently
                assert backend.sim.obstacle_contact() == (gap < 0.0), (x, gap)
                seen.add(gap < 0.0)
        assert seen == {True, False}  # the sweep crossed the first touch
    finally:
        backend.close()


def test_the_state_contract_tilt_matches_the_rotation_matrix(backend):
    """The control law's tilt from the state Bullet's read fills (the inertial frame's quaternion,
    x y z w, and the link frame in it) against fused_roll_pitch of base_pose's matrix
    (pybullet's getMatrixFromQuaternion), for random orientations."""
    sim = backend.sim
    backend.reset(EMPTY, np.random.default_rng(0))
    rng = np.random.default_rng(5)
    try:
        for _ in range(300):
            q = rng.normal(size=4)
            position = pybullet.getBasePositionAndOrientation(sim.robot_id, physicsClientId=sim.client)[0]
            pybullet.resetBasePositionAndOrientation(
                sim.robot_id, position, (q / np.linalg.norm(q)).tolist(), physicsClientId=sim.client
            )
            sim.read_state()
            s = sim.state
            np.testing.assert_allclose(
                base_tilt(s.quat, s.w_last, s.frame), fused_roll_pitch(sim.base_pose()[1]), atol=1e-9
            )
    finally:
        backend.reset(EMPTY, np.random.default_rng(0))


def test_reset_stands_on_flat_soles_like_mujoco(backend):
    """The walk's standing pose leans the trunk forward (trunk_pitch); the robot must start with
    both soles flat on the floor, not tipped onto its heels with an upright trunk.  Checked with
    Bullet's own link frames (not the spec kinematics reset uses): feet level, soles at the floor and
    touching it, and the trunk pitch MuJoCo's reset gives.  (Before, the feet were 0.077 rad
    toe-up, each on one heel contact point, and the trunk upright.)"""
    backend.reset(EMPTY, np.random.default_rng(0))
    sim = backend.sim
    spec = backend.robot
    for side in ("left", "right"):
        foot, origin = spec.sole(side)
        state = pybullet.getLinkState(
            sim.robot_id, sim.link_index[foot], computeForwardKinematics=1, physicsClientId=sim.client
        )
        rotation = np.array(pybullet.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        assert abs(rotation[2, 0]) < 5e-3 and abs(rotation[2, 1]) < 5e-3  # level: no pitch, no roll
        sole = np.asarray(state[4]) + rotation @ np.asarray(origin.xyz)
        assert abs(sole[2] + spec.sole_clearance(side)) < 2e-3  # the foot's lowest point on the floor
        assert pybullet.getContactPoints(sim.robot_id, sim.floor_id, sim.link_index[foot], physicsClientId=sim.client)
    mujoco_backend = pytest.importorskip("footsim.calibration.walkcheck").make_backend("mujoco")
    try:
        mujoco_backend.reset(EMPTY, np.random.default_rng(0))
        expected_pitch = fused_roll_pitch(mujoco_backend.sim.base_pose()[1])[1]
    finally:
        mujoco_backend.close()
    assert fused_roll_pitch(sim.base_pose()[1])[1] == pytest.approx(expected_pitch, abs=0.015)


SERVO = {
    "name": "pybullet",
    "motor": "servo",
    "armature_scale": 1.0,
    "servo_kp_scale": 2.0,
    "servo_damping_scale": 0.5,
    "servo_kv": 3.0,
}


def _pybullet_backend(options):
    from footsim import config as fconf

    walk = fconf.build_walk(fconf.load_preset("walk", "pybullet"))
    return fconf.build_backend(fconf.load_preset("backend", options), fconf.build_robot("wolfgang"), walk)


def test_servo_motor_applies_mujocos_actuator_law():
    """motor=servo: torque = clip(kp (ctrl - q) - kv q̇, ±effort) - damping q̇, ctrl = target +
    kv/kp · target velocity (backward difference over control_dt), hand-computed from the spec."""
    b = _pybullet_backend(SERVO)
    try:
        b.reset(EMPTY, np.random.default_rng(0))
        sim, spec = b.sim, b.robot
        previous = sim.state.last_targets()  # the standing targets of reset
        targets = previous + np.linspace(-0.01, 0.01, 12)
        sim.set_leg_targets(targets)
        rng = np.random.default_rng(1)
        q, qd = previous + rng.normal(0, 0.05, 12), rng.normal(0, 4.0, 12)
        for index, angle, velocity in zip(sim.leg_indices, q, qd):
            pybullet.resetJointState(sim.robot_id, index, angle, velocity, physicsClientId=sim.client)
        expected, saturated = [], 0
        for name, target, before, angle, velocity in zip(LEG_JOINT_NAMES, targets, previous, q, qd):
            servo, effort = spec.joint(name).servo, spec.joint(name).effort
            kp, kv, damping = 2.0 * servo.kp, 3.0, 0.5 * servo.damping
            ctrl = target + kv / kp * (target - before) / b.control_dt
            force = kp * (ctrl - angle) - kv * velocity
            saturated += abs(force) > effort
            expected.append(np.clip(force, -effort, effort) - damping * velocity)
        np.testing.assert_allclose(sim.servo_torques(), expected, rtol=1e-9, atol=1e-9)
        assert 0 < saturated < 12  # both branches of the clip exercised
    finally:
        b.close()


def test_armature_adds_to_the_joints_mass_matrix_diagonal():
    """armature_scale: Bullet's own mass matrix (calculateMassMatrix) gains the spec's armature ×
    the scale on each ankle-roll diagonal entry (the last joint of a leg: only its own link
    carries it)."""
    from footsim import config as fconf

    plain = _pybullet_backend({"name": "pybullet", "armature_scale": 0.0})
    servo = _pybullet_backend({"name": "pybullet"})  # the preset's armature
    scale = fconf.load_preset("backend", {"name": "pybullet"})["armature_scale"]
    assert scale > 0
    try:
        matrices = []
        for b in (plain, servo):
            b.reset(EMPTY, np.random.default_rng(0))
            sim = b.sim
            q = [
                s[0]
                for s in pybullet.getJointStates(
                    sim.robot_id,
                    range(pybullet.getNumJoints(sim.robot_id, physicsClientId=sim.client)),
                    physicsClientId=sim.client,
                )
            ]
            matrices.append((np.array(pybullet.calculateMassMatrix(sim.robot_id, q, physicsClientId=sim.client)), sim))
        (m_plain, sim_plain), (m_servo, _) = matrices
        for name in ("LAnkleRoll", "RAnkleRoll"):
            i = 6 + sim_plain.joint_index[name]  # 6 base DoF first
            assert m_servo[i, i] - m_plain[i, i] == pytest.approx(
                scale * plain.robot.joint(name).servo.armature,
                rel=0.02,  # axis not principal: Bullet keeps the diagonal
            )
    finally:
        plain.close()
        servo.close()


def test_a_torso_com_offset_changes_the_walk_deterministically():
    """Bullet cannot move a loaded link's COM: the offset is a torque applied every physics step
    of the one control tick.  The same walk twice is the same to the bit; with the offset it differs."""

    def walk(randomization=None):
        backend = make_backend("pybullet")
        try:
            if randomization:
                backend.apply_randomization(randomization)
            backend.reset(EMPTY, np.random.default_rng(3))
            actions = np.random.default_rng(7).uniform(-0.6, 0.6, size=(4, 6))
            results = [backend.execute(DoubleStep.from_action(a, backend.robot.step_limits)) for a in actions]
            sim = backend.sim
            joints = pybullet.getJointStates(sim.robot_id, sim.leg_indices, physicsClientId=sim.client)
            base = pybullet.getBasePositionAndOrientation(sim.robot_id, physicsClientId=sim.client)
            return [s[:2] for s in joints], base, [(r.pose, r.tilt, r.max_tilt) for r in results]
        finally:
            backend.close()

    offset = {"torso_com_offset_x": 0.01, "torso_com_offset_y": -0.005}
    assert walk() == walk()
    assert walk(offset) == walk(offset) != walk()


def test_the_state_check_matches_the_full_check():
    """``control.state_ok`` on the state Bullet's read fills against the verbs (``sim_error`` +
    ``base_pose`` + ``fused_roll_pitch``): the same tilt while walking, and False for a base out
    of bounds, upside down, and with an exploding velocity."""
    b = make_backend("pybullet")
    try:
        sim = b.sim
        b.reset(EMPTY, np.random.default_rng(0))
        tilt = np.zeros(2)

        def check() -> bool:
            sim.read_state(velocity=True)
            return state_ok(*sim.state.check_args(b.out_of_bounds, tilt))

        for action in np.random.default_rng(1).uniform(-1, 1, size=(3, 6)):
            result = b.execute(DoubleStep.from_action(action, b.robot.step_limits))
            assert check() and sim.sim_error() is None
            np.testing.assert_allclose(tilt, fused_roll_pitch(sim.base_pose()[1]), rtol=0, atol=1e-12)
            np.testing.assert_array_equal(tilt, result.tilt)
        body, c = sim.robot_id, sim.client
        position, orientation = pybullet.getBasePositionAndOrientation(body, physicsClientId=c)
        bad_states = [
            ([position[0] + b.out_of_bounds + 1.0, position[1], position[2]], orientation, [0, 0, 0]),
            (position, pybullet.getQuaternionFromEuler([math.pi, 0.0, 0.0]), [0, 0, 0]),
            (position, orientation, [2.0 * sim.max_base_speed, 0.0, 0.0]),
        ]
        for bad_position, bad_orientation, velocity in bad_states:
            pybullet.resetBasePositionAndOrientation(body, bad_position, bad_orientation, physicsClientId=c)
            pybullet.resetBaseVelocity(body, velocity, [0, 0, 0], physicsClientId=c)
            assert not check()
            upside_down = sim.base_pose()[1][2, 2] < 0
            out = max(abs(v) for v in sim.base_pose()[0]) > b.out_of_bounds
            assert sim.sim_error() is not None or upside_down or out
        pybullet.resetBasePositionAndOrientation(body, position, orientation, physicsClientId=c)
        pybullet.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=c)
        assert check()
    finally:
        b.close()


def test_compare_settings_finds_no_difference_between_equal_settings_and_the_unconverged_solver():
    """The same settings twice end in the same poses (the simulation is deterministic); 10 solver
    iterations against Bullet's default 50 turn the robot differently (docs/BACKENDS.md)."""
    from footsim.calibration.walkcheck import compare_settings

    # at the Bit-Bots' 1/240 s, where docs/walkcheck/convergence_finer.md measured it (and 4x cheaper)
    ten, fifty = ({"solver_iterations": n, "physics_dt": 1 / 240} for n in (10, 50))
    same, _ = compare_settings("pybullet", ten, ten)
    assert all(r["distance"] == 0.0 and r["heading"] == 0.0 and r["converged"] for r in same)
    rows, table = compare_settings("pybullet", ten, fifty)
    turns = [r for r in rows if r["sequence"].startswith("turn")]
    assert len(turns) == 2 and all(r["heading"] > np.radians(2.0) and not r["converged"] for r in turns)
    assert table.startswith("### pybullet: solver_iterations=10, physics_dt=")
