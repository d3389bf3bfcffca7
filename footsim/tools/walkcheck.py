"""``footsim-walkcheck [backends=mujoco,dm_control,pybullet] [walk=W] [robot=R] [convergence=true]
[backend.KEY=VALUE ...] [walk.KEY=VALUE ...] [robot.KEY=VALUE ...] [out=FILE.md]``: the walking
checks on each backend and the consistency report (:func:`footsim.calibration.walkcheck.walkcheck`);
with ``convergence=true`` also the timestep-convergence check per backend
(:func:`footsim.calibration.walkcheck.timestep_convergence`).  ``backend.KEY=VALUE`` overrides a
key of every listed 3D backend's config (e.g. ``backend.physics_dt=0.001``)."""

from __future__ import annotations

import datetime
import sys

from footsim.backends.base import require_known_backends
from footsim.calibration.walkcheck import timestep_convergence, walkcheck
from footsim.utils import atomic_write_text, parse_kv_args, preset_choice, split_overrides

COMMAND = "footsim-walkcheck"


def header(argv: list[str], walk_name: str, backends: list[str], backend_overrides: dict, convergence: bool) -> str:
    """The page's title, its command, the date and each backend's timesteps (written with out=)."""
    from footsim import config as fconf

    timing = []
    for name in backends:
        cfg = fconf.env_config(backend={"name": name, **backend_overrides})["backend"]
        timing.append(f"{name} {cfg['physics_dt'] * 1000:.6g} ms physics, {cfg['control_dt'] * 1000:.6g} ms targets")
    lines = [
        f"# {COMMAND}, walk={walk_name or 'default'} (FootstepNav-v1 defaults otherwise)",
        "",
        f"Command: `{' '.join([COMMAND, *argv])}`",
        f"({datetime.date.today().isoformat()}; {'; '.join(timing)}; written by the command.)",
    ]
    if convergence:
        lines += [
            "",
            "The convergence tables compare one run at each timestep; where the walk amplifies small differences "
            "(MuJoCo), `footsim.calibration.walkcheck.ensemble_convergence` compares ensembles of pushed runs "
            '(`docs/walkcheck/convergence_finer.md`, "Ensembles").',
        ]
    return "\n".join(lines) + "\n\n"


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    own, overrides = split_overrides(argv, ("backend", "walk", "robot"))
    args = parse_kv_args(
        own,
        {"backends": "mujoco,dm_control,pybullet", "walk": "", "robot": "", "convergence": "false", "out": ""},
        COMMAND,
        usage=__doc__,
    )
    backends = [b for b in args["backends"].split(",") if b]
    require_known_backends(backends, COMMAND)
    backends = [b for b in backends if b != "pymunk"]  # the consistency report adds 2D itself
    if args["convergence"] not in ("true", "false"):
        raise SystemExit(f"{COMMAND}: convergence must be true or false, got {args['convergence']!r}")
    walk = preset_choice(args["walk"], overrides["walk"])
    robot = preset_choice(args["robot"], overrides["robot"])
    try:
        _, table = walkcheck(backends, walk, robot, overrides["backend"])
        if args["convergence"] == "true":
            for name in backends:
                table += "\n\n" + timestep_convergence(name, walk, robot, overrides["backend"])[1]
    except ValueError as err:
        raise SystemExit(f"{COMMAND}: {err}") from None
    print(table)
    if args["out"]:
        page = header(argv, args["walk"], backends, overrides["backend"], args["convergence"] == "true")
        atomic_write_text(args["out"], page + table + "\n")


if __name__ == "__main__":  # pragma: no cover
    main()
