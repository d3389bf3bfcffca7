"""``footsim-bench [what=env2d,walk,...] [repeats=5] [steps=20000] [wrapped=false]``: speed benchmarks.

Prints markdown tables (medians over ``repeats``) for ``docs/BENCHMARKS.md``; the benchmarks are
:data:`footsim.bench.suite.BENCHMARKS`.
"""

from __future__ import annotations

import sys

from footsim.bench.suite import BENCHMARKS, machine, table
from footsim.utils import parse_kv_args


def main(argv: list[str] | None = None) -> None:
    args = parse_kv_args(
        sys.argv[1:] if argv is None else argv,
        {"what": "env2d,walk", "repeats": "5", "steps": "20000", "wrapped": "false"},
        "footsim-bench",
        usage=__doc__,
    )
    names = [n for n in args["what"].split(",") if n]
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        raise SystemExit(f"footsim-bench: unknown benchmark(s) {unknown}; valid: {sorted(BENCHMARKS)}")
    try:
        repeats, steps = int(args["repeats"]), int(args["steps"])
    except ValueError:
        raise SystemExit(
            f"footsim-bench: repeats and steps must be integers, got repeats={args['repeats']} steps={args['steps']}"
        ) from None
    if repeats < 1 or steps < 1:
        raise SystemExit(f"footsim-bench: repeats and steps must be >= 1, got repeats={repeats} steps={steps}")
    print(f"machine: {machine()}; repeats: {repeats} (median reported)\n")
    for name in names:
        kwargs = {"repeats": repeats}
        if name == "env2d":
            kwargs["steps"] = steps
            kwargs["wrapped"] = str(args["wrapped"]).lower() in ("1", "true", "yes")
        try:
            rows = BENCHMARKS[name](**kwargs)
        except ImportError as err:
            print(f"{name}: skipped ({err})\n")
            continue
        print(table(rows) + "\n")
