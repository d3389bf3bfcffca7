"""Small helpers shared by the command lines, the configs and the trainer: atomic file writes,
``key=value`` argument parsing, the check of a count setting and the note on a command-line request
not honoured as given."""

from __future__ import annotations

import operator
import os
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any


def _default_file_mode() -> int:
    """What ``open()`` would give a new file under the current umask (``mkstemp`` gives 0600)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def atomic_save(save: Callable[[str], None], path: str | os.PathLike, suffix: str = ".tmp") -> None:
    """Let ``save`` write a temporary file beside ``path``, then move it into place: a crash
    leaves either the old or the new file, never a half one.  The file gets the usual
    permissions (umask), not ``mkstemp``'s owner-only ones."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
    os.close(fd)
    try:
        save(tmp)
        os.chmod(tmp, _default_file_mode())
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """``text`` into ``path`` atomically, synced to disk before the move (:func:`atomic_write_texts`)."""
    atomic_write_texts({path: text})


def atomic_write_texts(files: Mapping[str | os.PathLike, str]) -> None:
    """Several files that belong together (a data file and the one derived from it): every text is
    written and synced to a temporary file first, and only then are they moved into place, one
    after the other.  A failure while writing replaces none of them; the moves themselves are the
    only window in which a crash could leave the files from two different writes."""
    temps: list[tuple[str, Path]] = []
    try:
        for path, text in files.items():
            path = Path(path)
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
            temps.append((tmp, path))
            with os.fdopen(fd, "w") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(tmp, _default_file_mode())
        for tmp, path in temps:
            os.replace(tmp, path)
    finally:
        for tmp, _ in temps:
            Path(tmp).unlink(missing_ok=True)


def check_count(name: str, value: Any, least: int = 0, below: tuple[str, int] | None = None) -> int:
    """``value`` as an int if it is a whole count >= ``least`` (and < the bound ``below`` = (its name,
    its value)); else a ValueError naming ``name``. A bool or 1.5 is a typo, not a count, which int()
    would silently turn into one."""
    try:
        count = None if isinstance(value, bool) else operator.index(value)  # int and numpy integers
    except TypeError:
        count = None
    if count is None or count < least or (below is not None and count >= below[1]):
        bound = f"an integer >= {least}" if below is None else f"an integer in [{least}, {below[0]})"
        raise ValueError(f"{name} must be {bound}, got {value!r}")
    return count


def parse_kv_args(argv: list[str], allowed: Mapping[str, object], command: str, usage: str | None = None) -> dict:
    """Parse ``key=value`` arguments (the Hydra-like style of every footsim command); ``-h`` or
    ``--help`` prints ``usage`` (the tool's module docstring) and exits."""
    out = dict(allowed)
    for arg in argv:
        if arg in ("-h", "--help"):
            print((usage or f"{command} key=value ...").strip())
            print(f"keys (defaults): {', '.join(f'{k}={v}' for k, v in allowed.items())}")
            raise SystemExit(0)
        if "=" not in arg:
            raise SystemExit(f"{command}: expected key=value, got {arg!r}; keys: {sorted(allowed)}")
        key, value = arg.split("=", 1)
        if key not in allowed:
            raise SystemExit(f"{command}: unknown key {key!r}; keys: {sorted(allowed)}")
        out[key] = value
    return out


def split_overrides(argv: list[str], groups_taken: tuple[str, ...]) -> tuple[list[str], dict[str, dict]]:
    """``(the tool's own key=value arguments, {group: {key: value}})`` from ``group.key=value``
    arguments of the groups ``groups_taken`` (values parsed as YAML, as Hydra does)."""
    own: list[str] = []
    groups: dict[str, dict] = {g: {} for g in groups_taken}
    for arg in argv:
        key, sep, value = arg.partition("=")
        group, dot, field = key.partition(".")
        if sep and dot and group in groups and field:
            from omegaconf import OmegaConf  # only the command-line tools parse overrides

            parsed = OmegaConf.to_container(OmegaConf.create(f"v: {value}"))  # YAML values, as Hydra reads them
            groups[group][field] = parsed["v"] if isinstance(parsed, dict) else value
        else:
            own.append(arg)
    return own, groups


def preset_choice(name: str, overrides: dict) -> str | dict | None:
    """A config group's choice from a tool's ``group=NAME`` and ``group.KEY=VALUE`` arguments: the
    preset's name, a mapping of keys over it (with ``name`` when given), or None (the default)."""
    if not overrides:
        return name or None
    return {**({"name": name} if name else {}), **overrides}


def note_not_honoured(cause: str, used: str, ignored: str) -> None:
    """Say on stdout, in one line, that a command line's request is not taken as given: ``cause``
    (what decides, e.g. ``resume`` or ``backend=mujoco``), what is ``used`` instead, and what is
    ``ignored``, rather than dropping it silently."""
    print(f"{cause}: {used}; ignoring {ignored}")
