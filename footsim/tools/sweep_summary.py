"""``footsim-sweep-summary dir=MULTIRUN_DIR [out=PREFIX]``: every job of a Hydra multirun in one
table (:func:`footsim.rl.sweeps.write_summary`)."""

from __future__ import annotations

import sys

from footsim.rl import sweeps

USAGE = "usage: footsim-sweep-summary dir=MULTIRUN_DIR [out=PREFIX]"


def parse_args(argv: list[str]) -> dict[str, str]:
    keys = {"dir": "the multirun directory", "out": "output prefix (writes PREFIX.csv and PREFIX.md)"}
    args: dict[str, str] = {}
    for token in argv:
        key, sep, value = token.partition("=")
        if not sep or key not in keys or not value:
            raise ValueError(f"expected one of {', '.join(k + '=' for k in keys)} with a value, got {token!r}")
        if key in args:
            raise ValueError(f"{key}= given twice")
        args[key] = value
    if "dir" not in args:
        raise ValueError("missing dir= (the multirun directory, e.g. multirun/2025-01-01/12-00-00)")
    return args


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if any(a in ("-h", "--help") for a in argv):
        print(USAGE + "\n\n" + sweeps.__doc__)
        return 0
    try:
        args = parse_args(argv)
        csv_path, md_path, rows = sweeps.write_summary(args["dir"], args.get("out"))
    except (ValueError, FileNotFoundError) as exc:
        print(f"footsim-sweep-summary: {exc}\n{USAGE}", file=sys.stderr)
        return 2
    print(md_path.read_text(), end="")
    print(f"\nwrote {csv_path} and {md_path}")
    failed = [r for r in rows if r["status"] == "failed"]
    for row in failed:
        print(f"job {row['job']} failed: {row['error']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
