"""One double-step command, repeated open loop: how far does a 3D backend's robot move per double step?

    python scripts/repeat_command.py backend=mujoco action=0,0,0,0,0,0 [steps=12] [skip=2] [backend.KEY=VALUE ...]

``action`` is the policy's 6-D action in [-1, 1] (right foot x, y, theta, then the left foot's, as
fractions of the step limits).  The robot starts standing at the origin; the first ``skip`` double
steps (the start from standing) are left out, and the displacement over the rest is reported per
double step in the robot's frame at that point: forward and lateral [mm], turn [deg].  With a zero
action this is the walk's creep when walking in place.  ``backend.KEY=VALUE`` overrides a backend
option (YAML values: ``null``, numbers, lists).
"""

from __future__ import annotations

import math
import sys

import footsim  # noqa: F401  (before NumPy loads: footsim pins OpenBLAS's kernels)

# isort: split
import numpy as np

from footsim.calibration.walkcheck import make_backend
from footsim.geometry import Pose2D
from footsim.scene import Scene
from footsim.tasks.nav import tilted_over
from footsim.utils import parse_kv_args, split_overrides
from footsim.walk.footsteps import DoubleStep


def per_double_step(poses: list[Pose2D]) -> tuple[float, float, float]:
    """Mean (forward [m], lateral [m], turn [rad]) per double step from ``poses[0]`` to ``poses[-1]``,
    in the frame of ``poses[0]``."""
    moved, n = poses[0].relative(poses[-1]), len(poses) - 1
    return moved.x / n, moved.y / n, moved.theta / n


def main(argv: list[str]) -> None:
    own, groups = split_overrides(argv, ("backend",))
    overrides = groups["backend"]
    defaults = {"backend": "mujoco", "action": "0,0,0,0,0,0", "steps": "12", "skip": "2"}
    args = parse_kv_args(own, defaults, "repeat_command.py")
    action = [float(v) for v in args["action"].split(",")]
    steps, skip = int(args["steps"]), int(args["skip"])
    if len(action) != 6 or not all(-1.0 <= v <= 1.0 for v in action):
        raise SystemExit(f"action must be 6 numbers in [-1, 1], got {args['action']!r}")
    if not 0 <= skip < steps:
        raise SystemExit(f"need 0 <= skip < steps, got skip={skip}, steps={steps}")
    name = args["backend"]
    backend = make_backend(name, backend_overrides=overrides)  # its own walk preset, the Wolfgang-OP
    try:
        backend.reset(Scene(goal=Pose2D(100.0, 0.0, 0.0)), np.random.default_rng(0))
        step = DoubleStep.from_action(action, backend.robot.step_limits)
        poses = [Pose2D(0.0, 0.0, 0.0)]  # the start; poses[k]: after double step k
        for i in range(steps):
            result = backend.execute(step)
            if tilted_over(result) or result.sim_error is not None:
                raise SystemExit(f"{name} {overrides or ''}: the robot fell at double step {i + 1}")
            poses.append(result.pose)
    finally:
        backend.close()
    forward, lateral, turn = per_double_step(poses[skip:])
    print(
        f"{name} {overrides or ''} action {action}: per double step over {steps - skip} double steps "
        f"forward {1000 * forward:+.1f} mm, lateral {1000 * lateral:+.1f} mm, turn {math.degrees(turn):+.3f} deg"
    )


if __name__ == "__main__":
    main(sys.argv[1:])
