"""``footsim-model robot=wolfgang format=mjcf|urdf out=FILE``: write a generated robot model.

Open the MJCF in MuJoCo's viewer (``python -m mujoco.viewer --mjcf=FILE``) or the URDF in RViz /
PyBullet.  ``out=-`` writes to standard output.
"""

from __future__ import annotations

import sys
from pathlib import Path

from footsim.robots.registry import ROBOTS, get_robot
from footsim.robots.urdf import urdf_xml

FORMATS = ("mjcf", "urdf")
KEYS = {"robot": "robot name", "format": "one of " + "|".join(FORMATS), "out": "output file, or - for stdout"}
USAGE = "usage: footsim-model robot=wolfgang format=mjcf|urdf out=FILE"


class UsageError(ValueError):
    pass


def parse_args(argv: list[str]) -> dict[str, str]:
    """``key=value`` arguments; unknown, repeated, malformed or missing keys raise UsageError."""
    args: dict[str, str] = {}
    for token in argv:
        key, sep, value = token.partition("=")
        if not sep or not key:
            raise UsageError(f"expected key=value, got {token!r}")
        if key not in KEYS:
            raise UsageError(f"unknown key {key!r}; valid keys: {', '.join(KEYS)}")
        if key in args:
            raise UsageError(f"key {key!r} given twice")
        if not value:
            raise UsageError(f"{key}= needs a value ({KEYS[key]})")
        args[key] = value
    args.setdefault("robot", "wolfgang")
    missing = [k for k in ("format", "out") if k not in args]
    if missing:
        raise UsageError(f"missing {', '.join(f'{k}= ({KEYS[k]})' for k in missing)}")
    if args["format"] not in FORMATS:
        raise UsageError(f"format must be one of {', '.join(FORMATS)}, got {args['format']!r}")
    if args["robot"] not in ROBOTS:
        raise UsageError(f"unknown robot {args['robot']!r}; valid robots: {', '.join(sorted(ROBOTS))}")
    return args


def render(robot: str, fmt: str) -> str:
    """The model text of ``robot`` in format ``fmt``."""
    spec = get_robot(robot)
    if fmt == "mjcf":
        from footsim.robots.mjcf import mjcf_xml  # needs mujoco, imported only here

        return mjcf_xml(spec)
    if fmt == "urdf":
        return urdf_xml(spec)
    raise UsageError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if any(a in ("-h", "--help", "help") for a in argv):
        print(USAGE)
        for key, meaning in KEYS.items():
            print(f"  {key}=  {meaning}")
        return 0
    try:
        args = parse_args(argv)
        text = render(args["robot"], args["format"])
    except UsageError as exc:
        print(f"footsim-model: {exc}\n{USAGE}", file=sys.stderr)
        return 2
    except ImportError as exc:
        print(f"footsim-model: {exc}", file=sys.stderr)
        return 1
    if args["out"] == "-":
        sys.stdout.write(text)
        return 0
    out = Path(args["out"])
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    except OSError as exc:
        print(f"footsim-model: cannot write {out}: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {args['format']} model of {args['robot']} to {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
