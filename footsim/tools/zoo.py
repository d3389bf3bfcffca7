"""``footsim-zoo list | show NAME | add RUN_DIR name=NAME [...] | remove NAME | check [NAME ...] |
evaluate NAME [NAME ...]``: the model zoo
(:mod:`footsim.zoo`).  ``zoo=DIR`` (or ``$FOOTSIM_ZOO``) works on another zoo directory.

* ``list``: one line per entry (condition, seed, backend, task, noise, steps, recorded success).
* ``show NAME``: the entry's provenance and evaluation summary.
* ``add RUN_DIR name=NAME [condition=C] [description=TEXT] [commit=SHA|CHECKOUT] [check_scenes=20]
  [force=true [parent_name=P]]``: copy a finished run in (atomically) and record its provenance and
  check episodes; a run trained from the entry it replaces records that parent as ``zoo:P``.
* ``remove NAME [keep_children=true]``: take an entry out (refused while another entry records it
  as its parent, unless keep_children=true: a study plan's training stage).
* ``check [NAME ...]``: file digests and config composition of the entries (all by default); exit 1 on a problem.
* ``evaluate NAME [NAME ...]``: run each entry's own evaluation (the standard scenes of its task,
  under its noise) again with this footsim and replace its recorded summary and success.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from footsim import zoo

USAGE = (
    "usage: footsim-zoo list | show NAME | add RUN_DIR name=NAME [condition=C] [description=TEXT] "
    "[commit=SHA|CHECKOUT] [check_scenes=20] [force=true [parent_name=P]] | remove NAME [keep_children=true] "
    "| check [NAME ...] | evaluate NAME [NAME ...]   (any: zoo=DIR)"
)


def _split(args: list[str]) -> tuple[list[str], dict[str, str]]:
    positional, options = [], {}
    for arg in args:
        if "=" in arg:
            key, value = arg.split("=", 1)
            options[key] = value
        else:
            positional.append(arg)
    return positional, options


def _fmt(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.3f}"
    return str(value)


def _list(root: Path) -> None:
    entries = zoo.load_index(root)["entries"]
    if not entries:
        print(f"the zoo at {root} is empty (footsim-zoo add RUN_DIR name=NAME)")
        return
    header = ("name", "condition", "seed", "backend", "task", "noise", "steps", "success")
    rows = [
        (
            name,
            _fmt(row.get("condition")),
            _fmt(row.get("seed")),
            _fmt(row.get("backend")),
            _fmt(row.get("task")),
            _fmt(row.get("noise")),
            _fmt(row.get("steps_total")),
            _fmt(row.get("success")),
        )
        for name, row in entries.items()
    ]
    widths = [max(len(r[i]) for r in (header, *rows)) for i in range(len(header))]
    for row in (header, *rows):
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip())
    print(f"{len(rows)} entries, {zoo.total_size(root) / 1e6:.1f} MB in {root}")


def _show(name: str, root: Path) -> None:
    path = zoo.entry_dir(name, root)
    prov = zoo.provenance(name, root)
    print(f"{name}  ({path})")
    print(json.dumps(prov, indent=2))
    summary = path / zoo.SUMMARY_FILE
    if summary.is_file():
        print("evaluation summary (summary.json):")
        print(summary.read_text().rstrip())


def _bool(key: str, value: str) -> bool:
    if value.lower() not in ("true", "false"):
        raise SystemExit(f"footsim-zoo: {key} must be true or false, got {value!r}")
    return value.lower() == "true"


def _add(positional: list[str], options: dict[str, str], root: Path) -> None:
    allowed = {"name", "condition", "description", "commit", "check_scenes", "force", "parent_name"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise SystemExit(f"footsim-zoo add: unknown key(s) {unknown}; keys: {sorted(allowed | {'zoo'})}")
    if len(positional) != 1 or "name" not in options:
        raise SystemExit(f"footsim-zoo add: give one RUN_DIR and name=NAME\n{USAGE}")
    try:
        check_scenes = int(options.get("check_scenes", "20"))
    except ValueError:
        raise SystemExit(f"footsim-zoo add: check_scenes must be an integer, got {options['check_scenes']!r}") from None
    row = zoo.add(
        positional[0],
        options["name"],
        root,
        condition=options.get("condition"),
        description=options.get("description", ""),
        commit=options.get("commit"),
        check_scenes=check_scenes,
        force=_bool("force", options.get("force", "false")),
        parent_name=options.get("parent_name"),
    )
    print(f"added {options['name']} to {root}: {json.dumps(row)}")
    print(f"zoo size: {zoo.total_size(root) / 1e6:.1f} MB")


def _check(positional: list[str], root: Path) -> int:
    failed = 0
    for name in positional or zoo.names(root):
        problems = zoo.verify(name, root)
        print(f"{name}: {'ok' if not problems else '; '.join(problems)}")
        failed += bool(problems)
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> None:
    args = sys.argv[1:] if argv is None else argv
    if not args or args[0] in ("-h", "--help"):
        raise SystemExit(USAGE)
    command, (positional, options) = args[0], _split(args[1:])
    root = Path(options.pop("zoo")).expanduser() if "zoo" in options else zoo.zoo_dir()
    try:
        if command == "list":
            _list(root)
        elif command == "show":
            if len(positional) != 1:
                raise SystemExit(f"footsim-zoo show: give one NAME\n{USAGE}")
            _show(positional[0], root)
        elif command == "add":
            _add(positional, options, root)
        elif command == "remove":
            if len(positional) != 1:
                raise SystemExit(f"footsim-zoo remove: give one NAME\n{USAGE}")
            keep = options.pop("keep_children", "false")
            if keep not in ("true", "false"):
                raise SystemExit(f"footsim-zoo remove: keep_children must be true or false, got {keep!r}")
            zoo.remove(positional[0], root, keep_children=keep == "true")
            print(f"removed {positional[0]} from {root}; zoo size: {zoo.total_size(root) / 1e6:.1f} MB")
        elif command == "check":
            raise SystemExit(_check(positional, root))
        elif command == "evaluate":
            if not positional or options:
                raise SystemExit(f"footsim-zoo evaluate: give one or more NAMEs (no key=value)\n{USAGE}")
            for name in positional:
                summary = zoo.reevaluate(name, root)
                print(f"{name}: success {summary['success']:.3f} on {summary['episodes']} scenes (recorded)")
        else:
            raise SystemExit(f"footsim-zoo: unknown command {command!r}\n{USAGE}")
    except zoo.ZooError as err:
        raise SystemExit(f"footsim-zoo: {err}") from None
