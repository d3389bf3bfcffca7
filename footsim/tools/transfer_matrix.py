"""``footsim-transfer-matrix [backends=a,b] [runs=DIR] [key=value ...]``: the cross-backend transfer
matrix (:mod:`footsim.rl.transfer_matrix`).

The command's own keys and defaults are in ``conf/transfer_matrix.yaml``; every other
``key=value`` goes to ``footsim-train`` unchanged (``train.total_timesteps=200000 seed=1``).
"""

from __future__ import annotations

import sys
from typing import Any, cast

from omegaconf import OmegaConf

from footsim.backends.base import require_known_backends
from footsim.config import conf_dir
from footsim.rl.evaluate import Shard
from footsim.rl.transfer_matrix import transfer_matrix

USAGE = (
    "usage: footsim-transfer-matrix [backends=pymunk,mujoco] [eval_backends=...] [runs=MULTIRUN_DIR] [out=DIR] "
    "[scenes=FILE | n_scenes=N scenes_seed=S] [randomization=none,default] [launcher=local] [shard=K/N] "
    "[footsim-train overrides ...]"
)


LIST_KEYS = ("backends", "eval_backends", "randomization")


def _defaults():
    return OmegaConf.load(conf_dir() / "transfer_matrix.yaml")


def parse_args(argv: list[str]) -> tuple[dict, list[str]]:
    """This command's options (conf/transfer_matrix.yaml + overrides) and the footsim-train overrides."""
    cfg = cast("dict[str, Any]", OmegaConf.to_container(_defaults()))  # the YAML file is a mapping of str keys
    train_overrides: list[str] = []
    for arg in argv:
        if arg in ("-h", "--help"):
            raise SystemExit(USAGE)
        if "=" not in arg:
            raise SystemExit(f"footsim-transfer-matrix: expected key=value, got {arg!r}\n{USAGE}")
        key, value = arg.split("=", 1)
        if key not in cfg:
            train_overrides.append(arg)
            continue
        if key in LIST_KEYS:
            items = [v.strip() for v in value.strip("[]").split(",") if v.strip()]
            cfg[key] = items or None
        else:
            parsed = OmegaConf.from_dotlist([f"v={value}"]).v  # YAML typing: ints, bools, null
            cfg[key] = parsed
    if not cfg["backends"] and not cfg["runs"]:
        raise SystemExit("footsim-transfer-matrix: backends= is empty")
    if not cfg["randomization"]:
        cfg["randomization"] = ["none"]
    require_known_backends((cfg["backends"] or []) + (cfg["eval_backends"] or []), "footsim-transfer-matrix")
    if cfg["shard"] is not None:
        try:
            cfg["shard"] = Shard.parse(cfg["shard"]).name
        except ValueError as err:
            raise SystemExit(f"footsim-transfer-matrix: {err}") from None
        if not cfg["runs"] or not cfg["out"]:
            raise SystemExit(
                "footsim-transfer-matrix: shard=K/N evaluates trained runs into a shared directory: "
                "give runs=DIR and out=DIR (train first, once)"
            )
    if cfg["runs"] and train_overrides:
        raise SystemExit(
            f"footsim-transfer-matrix: runs= reuses trained policies; unknown keys {train_overrides} "
            f"(own keys: {sorted(cfg)})"
        )
    return cfg, train_overrides


def main(argv: list[str] | None = None) -> None:
    cfg, overrides = parse_args(sys.argv[1:] if argv is None else argv)
    transfer_matrix(cfg, overrides)
