"""``footsim-calibrate backend=mujoco out=FILE.json`` fits the execution model of the 2D backend on
a 3D backend; ``footsim-calibrate compare=FILE.json`` prints its consistency table
(:mod:`footsim.calibration.execution_model`)."""

from __future__ import annotations

import sys

from footsim.backends.base import require_known_backends
from footsim.calibration.execution_model import DEFAULT_FEATURES, OUTPUTS, collect, fit
from footsim.calibration.walkcheck import execution_model_consistency, make_backend
from footsim.rl.common import write_json
from footsim.tasks.nav import tilted_over
from footsim.utils import atomic_write_text, parse_kv_args

# -- command ------------------------------------------------------------------------------------
USAGE = (
    "usage: footsim-calibrate backend=mujoco [n_steps=800] [seed=0] [scale=1.0] [repeat=0.9] "
    "[features=dx,dy,dtheta] out=FILE.json\n"
    "       footsim-calibrate compare=FILE.json [backend=mujoco] [out=FILE.md]"
)


def main(argv: list[str] | None = None) -> None:
    args = parse_kv_args(
        sys.argv[1:] if argv is None else argv,
        {
            "backend": "mujoco",
            "n_steps": "800",
            "seed": "0",
            "scale": "1.0",
            "repeat": "0.9",
            "features": ",".join(DEFAULT_FEATURES),
            "out": "",
            "compare": "",
        },
        "footsim-calibrate",
        usage=__doc__,
    )
    require_known_backends([args["backend"]], "footsim-calibrate")
    if args["compare"]:
        _, table = execution_model_consistency(args["compare"], args["backend"], int(args["seed"]))
        print(table)
        if args["out"]:
            atomic_write_text(args["out"], table + "\n")
        return
    if not args["out"]:
        raise SystemExit(f"footsim-calibrate: out=FILE.json is required\n{USAGE}")
    try:
        n_steps, seed = int(args["n_steps"]), int(args["seed"])
        scale, repeat = float(args["scale"]), float(args["repeat"])
    except ValueError as err:
        raise SystemExit(f"footsim-calibrate: bad number ({err})\n{USAGE}") from None
    if n_steps <= 0 or not 0 < scale <= 1 or not 0 <= repeat < 1:
        raise SystemExit("footsim-calibrate: need n_steps > 0, 0 < scale <= 1, 0 <= repeat < 1")
    if args["backend"] == "pymunk":
        raise SystemExit("footsim-calibrate: calibrate against a 3D backend (mujoco, dm_control, pybullet)")

    backend = make_backend(args["backend"])
    try:
        data = collect(backend, n_steps, tilted_over, seed, scale, repeat)
    finally:
        backend.close()
    names = [f for f in args["features"].split(",") if f]
    model = fit(
        data,
        meta={"backend": args["backend"], "n_steps": n_steps, "seed": seed, "scale": scale, "repeat": repeat},
        names=names,
    )
    write_json(args["out"], model)
    print(f"{model['n_samples']} double steps, {model['n_falls']} falls on {args['backend']}")
    for k, name in enumerate(OUTPUTS):
        terms = " ".join(f"{c:+.3f}·{f}" for c, f in zip(model["coef"][k], names))
        print(
            f"  {name} = {terms} {model['intercept'][k]:+.4f}   σ={model['residual_std'][k]:.4f}  "
            f"R²={model['r2'][k]:.3f}  (uncorrected 2D RMSE {model['uncorrected_rmse'][k]:.4f})"
        )
    print(f"execution model written to {args['out']}")
