"""Try a few transition sets of the footstep planner on a 3D backend (falls count as failures).

    python scripts/sweep_footstep.py 30 backend=mujoco

Tuning scenes: seed 777 (not the evaluation sets), obstacle-free.  The 2D transition set uses
the full step limits; on the 3D walks large and changing steps tip the robot over, so the
candidates shrink the forward, lateral and turning fractions.  Score: success, then mean time.
"""

import sys

from footsim import config as fconf
from footsim.env import FootstepEnv
from footsim.planners.controllers import make_controller
from footsim.rl.evaluate import evaluate, summarize
from footsim.tasks.scenes import sample_scenes

CANDIDATES = {
    "2d": {},
    "half": {"x_fracs": [-0.25, 0.0, 0.25, 0.5], "y_fracs": [0.0, 0.5], "theta_fracs": [0.0, 0.25, 0.5]},
    "three_quarters": {"x_fracs": [-0.25, 0.0, 0.375, 0.75], "y_fracs": [0.0, 0.5], "theta_fracs": [0.0, 0.25, 0.5]},
    "third": {"x_fracs": [-0.2, 0.0, 0.2, 0.35], "y_fracs": [0.0, 0.35], "theta_fracs": [0.0, 0.2, 0.35]},
}


def main():
    options = dict(a.split("=", 1) for a in sys.argv[1:] if "=" in a)
    positional = [a for a in sys.argv[1:] if "=" not in a]
    n = int(positional[0]) if positional else 30
    backend = options.get("backend", "mujoco")
    names = options.get("only", ",".join(CANDIDATES)).split(",")
    base = dict(fconf.load_preset("controller", "footstep"))
    for name in names:
        env = FootstepEnv(task="nav", backend=backend)
        scenes = sample_scenes(env.sampler, n, 777)
        controller = make_controller(env, {**base, **CANDIDATES[name]})
        s = summarize(evaluate(env, controller, scenes, progress=False))
        env.close()
        print(
            f"{name} {CANDIDATES[name]}: success {s['success']:.3f} fall {s['fall']:.3f} timeout {s['timeout']:.3f} "
            f"time {s['success_time_mean']:.2f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
