"""``footsim-capability backend=B [walk=W] [randomization=R] [grid=same:5] [repeats=2] [seed=0]
[warmup=2] [backend.KEY=VALUE ...] [walk.KEY=VALUE ...] [out=DIR]``: the capability map of a backend
(:mod:`footsim.calibration.capability`): ``DIR/capability.csv`` and ``DIR/capability.png`` (default
``DIR`` = ``capability_<backend>``).  ``backend.KEY=VALUE`` and ``walk.KEY=VALUE`` override a key of
the backend's config (e.g. ``backend.rolling_friction=0``) and of the walk (e.g.
``walk.trunk_pitch=0.3``), as in ``footsim-walkcheck``.

``footsim-capability compare=DIR_A,DIR_B [out=FILE.png]``: where two maps disagree (default
``FILE`` = ``capability_compare.png``)."""

from __future__ import annotations

import sys
from pathlib import Path

from footsim import config as fconf
from footsim.backends.base import require_known_backends
from footsim.calibration import capability as cap
from footsim.utils import parse_kv_args, preset_choice, split_overrides

COMMAND = "footsim-capability"


def _whole(args: dict, key: str, minimum: int) -> int:
    text = str(args[key])
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < minimum:
        raise SystemExit(f"{COMMAND}: {key} must be a whole number >= {minimum}, got {text!r}")
    return value


def main(argv: list[str] | None = None) -> None:
    own, groups = split_overrides(sys.argv[1:] if argv is None else argv, ("backend", "walk"))
    backend_overrides, walk_overrides = groups["backend"], groups["walk"]
    args = parse_kv_args(
        own,
        {
            "backend": "",
            "walk": "",
            "randomization": "none",
            "grid": cap.DEFAULT_GRID,
            "repeats": "2",
            "seed": "0",
            "warmup": "2",
            "out": "",
            "compare": "",
        },
        COMMAND,
        usage=__doc__,
    )
    if args["compare"]:
        if backend_overrides or walk_overrides:
            raise SystemExit(
                f"{COMMAND}: compare= reads two maps; backend.KEY=VALUE and walk.KEY=VALUE apply to measuring one"
            )
        _compare(args)
        return
    if not args["backend"]:
        raise SystemExit(f"{COMMAND}: give backend=NAME (or compare=DIR_A,DIR_B)")
    require_known_backends([args["backend"]], COMMAND)
    repeats, seed, warmup = _whole(args, "repeats", 1), _whole(args, "seed", 0), _whole(args, "warmup", 0)
    walk_name = args["walk"] or None
    walk = preset_choice(args["walk"], walk_overrides)
    try:  # every argument checked before the first trial
        cap.capability_grid(args["grid"])
        if walk_name is not None:
            fconf.load_preset("walk", walk_name)
        fconf.load_preset("randomization", args["randomization"])
    except ValueError as err:
        raise SystemExit(f"{COMMAND}: {err}") from None
    out = Path(args["out"] or f"capability_{args['backend']}")

    def progress(done: int, total: int) -> None:
        if done == total or done % 25 == 0:
            print(f"{done}/{total} cells", flush=True)

    try:  # a bad backend.KEY or walk.KEY (unknown key or value) fails when the backend is built, before the first trial
        cells, seconds = cap.timed_map(
            args["backend"],
            walk=walk,
            randomization=args["randomization"],
            grid=args["grid"],
            repeats=repeats,
            seed=seed,
            warmup=warmup,
            progress=progress,
            backend_overrides=backend_overrides,
        )
    except ValueError as err:
        raise SystemExit(f"{COMMAND}: {err}") from None
    settings = "".join(f", {key}={value}" for key, value in backend_overrides.items())
    walk_settings = "".join(f", {key}={value}" for key, value in walk_overrides.items())
    title = (
        f"{args['backend']}{settings}, walk={walk_name or 'backend default'}{walk_settings}, "
        f"randomization={args['randomization']}"
    )
    csv_path, png_path = cap.write_map(cells, out, title)
    print(f"{title}: {len(cells)} cells x {repeats} repeats in {seconds:.0f} s")
    print(cap.summary_text(cells))
    print(f"wrote {csv_path} and {png_path}")


def _compare(args: dict) -> None:
    if args["backend"]:
        raise SystemExit(f"{COMMAND}: compare= takes two map directories, not backend=")
    dirs = [d for d in args["compare"].split(",") if d]
    if len(dirs) != 2:
        raise SystemExit(f"{COMMAND}: compare needs two map directories DIR_A,DIR_B, got {args['compare']!r}")
    try:
        maps = [cap.read_map(d) for d in dirs]
        out = args["out"] or "capability_compare.png"
        line = cap.compare_maps(maps[0], maps[1], out, names=(Path(dirs[0]).name, Path(dirs[1]).name))
    except (FileNotFoundError, ValueError) as err:
        raise SystemExit(f"{COMMAND}: {err}") from None
    print(line)
    print(f"wrote {out}")
