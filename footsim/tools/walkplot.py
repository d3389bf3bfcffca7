"""``footsim-walkplot out=walk.png [steps="0.08,0,0,0.08,0,0;..."] [vel=vx,vy,omega] [n=2]
[stop=true] [dt=0.002]``: plot the walk engine's trajectories (:mod:`footsim.walk.plot`).

``steps`` are double steps (right foot x y θ, then left foot x y θ, ``;`` between double steps),
repeated ``n`` times; ``vel`` gives velocity orders instead.  ``stop=true`` adds the stop.
"""

from __future__ import annotations

import sys

import numpy as np

from footsim.utils import parse_kv_args
from footsim.walk.engine import QuinticWalk
from footsim.walk.footsteps import DoubleStep, FootstepGeometry, StepLimits
from footsim.walk.params import WalkParams
from footsim.walk.plot import plot_walk, simulate

_DEFAULTS = {"out": None, "steps": "0.08,0,0,0.08,0,0", "vel": "", "n": "2", "stop": "true", "dt": "0.002"}


def _parse_args(argv: list[str]) -> dict:
    args = parse_kv_args(argv, _DEFAULTS, "footsim-walkplot", usage=__doc__)
    if not args["out"]:
        raise SystemExit("footsim-walkplot: out=FILE.png is required")
    return args


def main(argv: list[str] | None = None) -> None:
    args = _parse_args(sys.argv[1:] if argv is None else argv)
    try:
        repeats = int(args["n"])
        dt = float(args["dt"])
        stop = {"true": True, "false": False}[args["stop"].lower()]
        params = WalkParams()
        geometry_probe = QuinticWalk(
            params, FootstepGeometry(StepLimits(), foot_distance=params.foot_distance), control_dt=dt
        )
        if args["vel"]:
            vx, vy, omega = (float(v) for v in args["vel"].split(","))
            orders = [geometry_probe.footsteps_from_velocity(vx, vy, omega)]
            title = f"velocity order vx={vx} vy={vy} ω={omega}"
        else:
            orders = [
                DoubleStep.from_array([float(v) for v in chunk.split(",")])
                for chunk in args["steps"].split(";")
                if chunk
            ]
            title = "double steps " + "; ".join(args["steps"].split(";"))
        if repeats < 1 or not orders:
            raise ValueError("need at least one double step and n >= 1")
        if not all(np.isfinite(order.as_array()).all() for order in orders):
            raise ValueError("double steps must be finite numbers")
    except (ValueError, KeyError) as error:
        raise SystemExit(f"footsim-walkplot: bad arguments ({error})") from None
    engine, trajectories = simulate(orders * repeats, stop=stop, params=params, control_dt=dt)
    plot_walk(trajectories, engine, args["out"], title=f"{title} ×{repeats}" + (", then stop" if stop else ""))
    print(f"wrote {args['out']}")


if __name__ == "__main__":  # pragma: no cover
    main()
