"""``footsim-walkcheck [backends=mujoco,dm_control,pybullet] [out=FILE.md]``: the open-loop walking
checks on each backend and the consistency report (:func:`footsim.calibration.walkcheck.walkcheck`)."""

from __future__ import annotations

import sys

from footsim.backends.base import require_known_backends
from footsim.calibration.walkcheck import walkcheck
from footsim.utils import atomic_write_text, parse_kv_args


def main(argv: list[str] | None = None) -> None:
    args = parse_kv_args(
        sys.argv[1:] if argv is None else argv,
        {"backends": "mujoco,dm_control,pybullet", "out": ""},
        "footsim-walkcheck",
    )
    backends = [b for b in args["backends"].split(",") if b]
    require_known_backends(backends, "footsim-walkcheck")
    backends = [b for b in backends if b != "pymunk"]  # the consistency report adds 2D itself
    _, table = walkcheck(backends)
    print(table)
    if args["out"]:
        atomic_write_text(args["out"], table + "\n")
