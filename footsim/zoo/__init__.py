"""The model zoo: trained policies shipped with the code, registered by name.

An entry is a directory ``<zoo>/<NAME>/`` holding what a run directory holds for evaluation and
transfer (``model.zip``, ``vecnormalize.pkl`` when the run normalized, ``config.yaml``), its
evaluation summary (``summary.json``), ``provenance.json`` (commit, seed, steps, wall time,
library versions, parent, file digests), ``check_episodes.csv`` (the first ``check_scenes``
episodes of the standard scene set, evaluated when the entry was added: the reference a
re-evaluation must match exactly) and, when the run logged to TensorBoard, ``learning_curve.csv``.
``<zoo>/index.json`` lists the entries with a one-line summary each.

The zoo is ``footsim/zoo/`` (a wheel carries it as package data); the environment variable
``FOOTSIM_ZOO`` points every command at another directory instead.  ``zoo:NAME`` is accepted
wherever a run directory is (``footsim-eval run=zoo:NAME``, ``footsim-train init_from=zoo:NAME``);
resolving it checks that the entry's config still composes with the current code and fails
naming the key or group that changed.

``model.zip`` is the run's model with the optimizer's moment estimates dropped (an Adam state
with no steps taken): the policy and value weights are the run's, bit for bit, which is all that
evaluation and ``init_from`` read, and the file is a third of the size.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import os
import platform
import re
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

PREFIX = "zoo:"
INDEX_FILE = "index.json"
PROVENANCE_FILE = "provenance.json"
SUMMARY_FILE = "summary.json"
CHECK_FILE = "check_episodes.csv"
CURVE_FILE = "learning_curve.csv"
#: The standard scene set's seed (conf/eval.yaml ``scenes_seed``); the check episodes are its first scenes.
STANDARD_SCENES_SEED = 20220101
_NAME = re.compile(r"^[a-z0-9][a-z0-9_-]{0,63}$")
#: Libraries whose versions an entry records (besides the ones SB3 wrote into model.zip at training).
_LIBRARIES = ("numpy", "scipy", "gymnasium", "stable-baselines3", "torch", "pymunk", "numba", "hydra-core", "mujoco")


class ZooError(ValueError):
    """A zoo name, entry or index that cannot be used; the message says which and why."""


# -- where and what -----------------------------------------------------------------------------
def zoo_dir() -> Path:
    """The zoo's directory: ``$FOOTSIM_ZOO`` if set, else the package's own ``footsim/zoo``."""
    env = os.environ.get("FOOTSIM_ZOO")
    return Path(env).expanduser() if env else Path(__file__).resolve().parent


def is_zoo_ref(text: Any) -> bool:
    return isinstance(text, str) and text.startswith(PREFIX)


def load_index(root: Path | None = None) -> dict:
    """``{"format": 1, "entries": {NAME: {...}}}`` of the zoo (empty when it has no index yet)."""
    path = (root or zoo_dir()) / INDEX_FILE
    if not path.is_file():
        return {"format": 1, "entries": {}}
    try:
        index = json.loads(path.read_text())
    except ValueError as err:
        raise ZooError(f"the zoo index {path} is not valid JSON: {err}") from None
    if not isinstance(index, dict) or not isinstance(index.get("entries"), dict):
        raise ZooError(f"the zoo index {path} has no 'entries' mapping")
    return index


def write_index(index: dict, root: Path) -> None:
    """Rewrite the zoo index atomically (an interrupted write leaves the old one)."""
    from footsim.utils import atomic_write_text

    atomic_write_text(root / INDEX_FILE, json.dumps(index, indent=2) + "\n")


def update_index(root: Path, change: Callable[[dict], None]) -> None:
    """Apply ``change`` to the index and rewrite it, holding an exclusive lock on the zoo directory
    (where the OS has ``fcntl``) from the read to the write: two ``add`` runs at once each keep
    their row instead of the later write dropping the earlier one's."""
    fd = os.open(root, os.O_RDONLY)
    try:
        try:
            import fcntl

            fcntl.flock(fd, fcntl.LOCK_EX)
        except ImportError:  # no advisory locks on this OS: read-modify-write unguarded
            pass
        index = load_index(root)
        change(index)
        index["entries"] = dict(sorted(index["entries"].items()))
        write_index(index, root)
    finally:
        os.close(fd)  # releases the lock


def names(root: Path | None = None) -> list[str]:
    return sorted(load_index(root)["entries"])


def check_name(name: str) -> str:
    if not isinstance(name, str) or not _NAME.match(name):
        raise ZooError(
            f"zoo name {name!r} is not valid: lower-case letters, digits, '_' and '-', starting with a "
            "letter or digit, at most 64 characters"
        )
    return name


def entry_dir(name: str, root: Path | None = None) -> Path:
    """An entry's directory; an unknown name fails listing the zoo's names."""
    root = root or zoo_dir()
    known = names(root)
    if name not in known:
        listing = ", ".join(known) if known else "none (the zoo is empty)"
        raise ZooError(f"no zoo entry {name!r} in {root}; entries: {listing} (footsim-zoo list)")
    path = root / name
    if not (path / "model.zip").is_file() or not (path / "config.yaml").is_file():
        raise ZooError(f"zoo entry {name!r} is incomplete: {path} lacks model.zip or config.yaml")
    return path


def provenance(name: str, root: Path | None = None) -> dict:
    return json.loads((entry_dir(name, root) / PROVENANCE_FILE).read_text())


def resolve(spec: str | os.PathLike, root: Path | None = None, check: bool = True) -> Path:
    """A run directory from ``spec``: ``zoo:NAME`` is the entry's directory (with ``check``, after
    :func:`check_config`); anything else is taken as a path."""
    if not is_zoo_ref(spec):
        return Path(spec).expanduser().resolve()
    name = str(spec)[len(PREFIX) :]
    path = entry_dir(name, root)
    if check:
        check_config(name, root)
    return path


# -- does an entry still fit the code ------------------------------------------------------------
def config_problem(cfg: DictConfig, obs_size: int | None = None) -> str | None:
    """Why a run's saved config no longer composes with this code (naming the key or group), or None.

    Every env group must compose over its current preset (an unknown preset, a key the schema
    lost, a value the builders refuse), the agent section over the current agent schema, and
    the task's observation must still have the ``obs_size`` inputs the policy reads."""
    from footsim import config as fconf

    missing = [g for g in (*fconf.ENV_GROUPS, "agent") if g not in cfg]
    if missing:
        return f"the config has no {', '.join(missing)} section(s), which footsim now requires"
    try:
        env = fconf.env_config(**{g: fconf.to_plain(cfg[g]) for g in fconf.ENV_GROUPS})
        _, task = fconf.build_task(env["task"])
        fconf.build_noise(env["noise"])
        fconf.build_walk(env["walk"])
        fconf.build_robot(env["robot"])
        fconf.merge_checked(fconf.compose("config").agent, fconf.to_plain(cfg.agent), "agent")
    except (ValueError, TypeError, KeyError) as err:
        return str(err)
    if obs_size is not None:
        layout = task.observation_layout
        now = sum(size for _, size in layout)
        if now != obs_size:
            blocks = " + ".join(f"{block} {size}" for block, size in layout)
            name = env["task"]["name"]
            return f"task {name}: its observation is now {blocks} = {now} inputs; the policy reads {obs_size}"
    return None


def check_config(name: str, root: Path | None = None) -> DictConfig:
    """The entry's run config, after checking that it composes with this code (else :class:`ZooError`
    naming what changed and the commit the entry was made with)."""
    from footsim.rl.common import load_run_config

    path = entry_dir(name, root)
    cfg = load_run_config(path)
    prov_path = path / PROVENANCE_FILE
    prov = json.loads(prov_path.read_text()) if prov_path.is_file() else {}
    problem = config_problem(cfg, prov.get("obs_size"))
    if problem is not None:
        commit = (prov.get("commit") or {}).get("sha") or "an unknown commit"
        raise ZooError(
            f"zoo entry {name!r} no longer composes with this footsim: {problem} "
            f"(the entry's config.yaml was written by {commit}; re-train it or evaluate it with that commit)"
        )
    return cfg


# -- adding an entry ----------------------------------------------------------------------------
def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _git_commit(where: Path) -> dict | None:
    """HEAD and whether the tree has uncommitted changes, of the git checkout at ``where``."""
    try:
        sha = subprocess.run(
            ["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return {"sha": sha, "dirty": bool(dirty)}


def commit_of(commit: str | None) -> dict:
    """The provenance's commit record: ``commit`` is a SHA, a git checkout's path (its HEAD), or
    None (the checkout footsim is imported from, which is what adds the entry: said so)."""
    if commit and Path(commit).expanduser().is_dir():
        found = _git_commit(Path(commit).expanduser())
        if found is None:
            raise ZooError(f"commit={commit}: not a git checkout")
        return {**found, "source": f"HEAD of {Path(commit).expanduser().resolve()}"}
    if commit:
        if not re.fullmatch(r"[0-9a-f]{7,40}", commit):
            raise ZooError(f"commit={commit!r}: expected a git SHA (7-40 hex digits) or a checkout's path")
        return {"sha": commit, "dirty": None, "source": "given (commit=)"}
    found = _git_commit(Path(__file__).resolve().parent)
    if found is None:
        return {"sha": None, "dirty": None, "source": "unknown (footsim is not imported from a git checkout)"}
    return {**found, "source": "the footsim checkout that added the entry (the run did not record its own)"}


def _training_versions(model_zip: Path) -> dict:
    """The library versions SB3 wrote into ``model.zip`` (``system_info.txt``) when the run saved it."""
    import zipfile

    with zipfile.ZipFile(model_zip) as archive:
        if "system_info.txt" not in archive.namelist():
            return {}
        text = archive.read("system_info.txt").decode()
    out = {}
    for line in text.splitlines():
        key, _, value = line.lstrip("- ").partition(":")
        if value.strip():
            out[key.strip()] = value.strip()
    return out


def _installed_versions() -> dict:
    out = {"python": platform.python_version()}
    for lib in _LIBRARIES:
        try:
            out[lib] = metadata.version(lib)
        except metadata.PackageNotFoundError:
            pass
    return out


def deflate_zip(path: Path) -> None:
    """Rewrite the archive at ``path`` with every member deflated (SB3 stores them uncompressed; the
    weights shrink by about 7 %), member bytes and names unchanged; atomic."""
    import zipfile

    from footsim.utils import atomic_save

    with zipfile.ZipFile(path) as archive:
        members = [(info, archive.read(info)) for info in archive.infolist()]

    def write(target: str) -> None:
        with zipfile.ZipFile(target, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=9) as out:
            for info, data in members:
                info.compress_type = zipfile.ZIP_DEFLATED
                out.writestr(info, data)

    atomic_save(write, path, ".zip")


def weights_digest(model_zip: Path) -> str:
    """SHA-256 of a saved PPO model's policy and value weights: each tensor of ``policy.pth`` by name,
    dtype, shape and bytes.  It identifies the network whatever the archive's compression or optimizer
    state, so a run's model, its zoo entry and a child's recorded parent can be compared."""
    import zipfile

    import torch

    with zipfile.ZipFile(model_zip) as archive:
        state = torch.load(io.BytesIO(archive.read("policy.pth")), map_location="cpu", weights_only=True)
    digest = hashlib.sha256()
    for key in sorted(state):
        tensor = state[key].contiguous()
        digest.update(f"{key}|{tensor.dtype}|{tuple(tensor.shape)}|".encode())
        digest.update(tensor.numpy().tobytes())
    return digest.hexdigest()


def _slim_model(source: Path, target: Path) -> dict:
    """Save ``source``'s PPO model to ``target`` with a fresh optimizer state; check the weights survive."""
    import torch
    from stable_baselines3 import PPO

    from footsim.utils import atomic_save

    model = PPO.load(source, device="cpu")
    weights = {k: v.clone() for k, v in model.policy.state_dict().items()}
    policy = model.policy
    fresh: Any = policy.optimizer_class  # Adam (SB3's default); its constructor takes lr
    policy.optimizer = fresh(policy.parameters(), lr=model.lr_schedule(1), **policy.optimizer_kwargs)
    atomic_save(model.save, target, ".zip")
    deflate_zip(target)
    again = PPO.load(target, device="cpu").policy.state_dict()
    if weights.keys() != again.keys() or not all(torch.equal(weights[k], again[k]) for k in weights):
        raise ZooError(f"the policy weights of {target} differ from {source}'s after saving; not adding")
    shape = model.observation_space.shape
    return {"num_timesteps": int(model.num_timesteps), "obs_size": int(shape[0]) if shape else None}


def _learning_curve(tb_dir: Path, max_points: int = 200) -> str | None:
    """``step,success_rate,ep_rew_mean`` from the run's TensorBoard logs (at most ``max_points`` rows), or None."""
    if not tb_dir.is_dir():
        return None
    try:
        from tensorboard.backend.event_processing.event_accumulator import (  # type: ignore[import-untyped]
            EventAccumulator,
        )
    except ImportError:
        return None
    series: dict[str, dict[int, float]] = {"rollout/success_rate": {}, "rollout/ep_rew_mean": {}}
    for events in sorted({p.parent for p in tb_dir.rglob("events.out.tfevents.*")}):
        acc = EventAccumulator(str(events), size_guidance={"scalars": 0})
        acc.Reload()
        for tag, values in series.items():
            if tag in acc.Tags().get("scalars", []):
                values.update({int(e.step): float(e.value) for e in acc.Scalars(tag)})
    steps = sorted(series["rollout/success_rate"])
    if not steps:
        return None
    stride = max(1, -(-len(steps) // max_points))
    kept = steps[::stride] if steps[::stride][-1] == steps[-1] else [*steps[::stride], steps[-1]]
    lines = ["step,success_rate,ep_rew_mean"]
    for step in kept:
        reward = series["rollout/ep_rew_mean"].get(step)
        success = float32_text(series["rollout/success_rate"][step])
        lines.append(f"{step},{success},{'' if reward is None else float32_text(reward)}")
    return "\n".join(lines) + "\n"


def float32_text(value: float) -> str:
    """The shortest text that reads back as the same float32 (TensorBoard stores scalars as float32,
    so this loses nothing and writes 0.02 where repr of the widened value gives 0.019999999552965164)."""
    import numpy as np

    return np.format_float_positional(np.float32(value), unique=True, trim="-")


def episodes_csv(records: list[dict]) -> str:
    """Episode records as ``footsim-eval`` writes ``episodes.csv`` (the same columns and number text)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(records[0].keys()))
    writer.writeheader()
    writer.writerows(records)
    return buffer.getvalue()


def check_episodes(run_dir: Path, n_scenes: int, scenes_seed: int = STANDARD_SCENES_SEED) -> list[dict]:
    """The run's policy on the first ``n_scenes`` of the standard scene set of its own task and
    backend, deterministic, episode ``i`` seeded ``i`` (what ``footsim-eval run=... n_scenes=N`` does)."""
    from footsim.env import make_env
    from footsim.rl.common import LoadedPolicy, load_run_config
    from footsim.rl.evaluate import PolicyController, evaluate
    from footsim.tasks.scenes import sample_scenes

    cfg = load_run_config(run_dir)
    env = make_env(cfg)
    try:
        scenes = sample_scenes(env.sampler, n_scenes, scenes_seed)
        return evaluate(env, PolicyController(LoadedPolicy(run_dir)), scenes, seed=0, progress=False)
    finally:
        env.close()


def _parent_name(parent_path: str | None, root: Path, digest: str | None = None) -> str | None:
    """``zoo:NAME`` of the entry whose weights are the parent's (``digest``), else of the entry the
    parent path is or was added from; None when the parent is not in the zoo."""
    if not parent_path:
        return None
    entries = load_index(root)["entries"]
    if digest is not None:
        for name in entries:
            if entry_weights_digest(name, root) == digest:
                return f"{PREFIX}{name}"
        return None
    parent = Path(parent_path).resolve()
    for name, row in entries.items():
        if parent == (root / name).resolve() or str(parent) == row.get("source_run"):
            return f"{PREFIX}{name}"
    return None


def _parent_identity(parent: dict | None, root: Path) -> tuple[str | None, str | None]:
    """The weights digest of the parent a run's ``parent.json`` record names, and ``zoo:NAME`` of the
    entry holding those weights (None for either when there is none).  The digest is of the parent's
    weights as they are now: a run directory trained over since gives another digest, and the
    lineage check (footsim-reproduce) then names the mismatch."""
    if not parent or not parent.get("init_from"):
        return None, None
    model = Path(parent["init_from"]) / "model.zip"
    digest = weights_digest(model) if model.is_file() else None
    return digest, _parent_name(parent["init_from"], root, digest)


def _lineage_steps(parent: dict | None, parent_zoo: str | None, root: Path) -> int:
    """Training steps of the lineage a run was initialised from (its ``parent.json`` record): a zoo
    parent's recorded total, or a parent run's own steps plus its lineage's, followed through the
    runs' ``parent.json`` files (a staged training: each stage starts counting at 0)."""
    steps, seen = 0, set()
    while parent:
        own = int(parent.get("parent_num_timesteps", 0))
        if parent_zoo is not None:
            entry = load_index(root)["entries"].get(parent_zoo[len(PREFIX) :], {})
            return steps + int(entry.get("steps_total") or own)
        steps += own
        if not parent.get("init_from"):
            break
        run = Path(parent["init_from"]).resolve()
        if run in seen or not (run / "parent.json").is_file():
            break
        seen.add(run)
        parent = json.loads((run / "parent.json").read_text())
        parent_zoo = _parent_identity(parent, root)[1]
    return steps


def entry_weights_digest(name: str, root: Path | None = None) -> str:
    """The entry's :func:`weights_digest`, as its provenance records it (computed when it does not)."""
    prov = provenance(name, root)
    return prov.get("weights_sha256") or weights_digest(entry_dir(name, root) / "model.zip")


def add(
    run_dir: str | os.PathLike,
    name: str,
    root: Path | None = None,
    *,
    condition: str | None = None,
    description: str = "",
    commit: str | None = None,
    check_scenes: int = 20,
    force: bool = False,
    parent_name: str | None = None,
) -> dict:
    """Copy a finished run into the zoo as ``name`` and register it; returns its index row.

    The entry is assembled in a temporary directory inside the zoo and moved into place in one
    rename, then the index is rewritten atomically: an interrupted ``add`` leaves the zoo as it was.
    A run trained from the entry it replaces (``force``) needs ``parent_name``: the name its
    provenance records for that parent (e.g. the study plan's training-stage entry), since the
    replaced entry's own name will be the child's.
    """
    from footsim.rl.common import MODEL_FILE, VECNORM_FILE, load_run_config
    from footsim.utils import atomic_write_text

    check_name(name)
    root = (root or zoo_dir()).resolve()
    run = Path(run_dir).expanduser().resolve()
    for needed in (MODEL_FILE, "config.yaml"):
        if not (run / needed).is_file():
            raise ZooError(f"{run} is not a finished run: {needed} is missing")
    index = load_index(root)
    if name in index["entries"] and not force:
        raise ZooError(f"zoo entry {name!r} exists; give force=true to replace it")
    if check_scenes < 1:
        raise ZooError(f"check_scenes must be >= 1, got {check_scenes}")
    cfg = load_run_config(run)
    problem = config_problem(cfg)
    if problem is not None:
        raise ZooError(f"{run}: its config does not compose with this footsim: {problem}")

    root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".{name}.adding-"))
    try:
        parent = json.loads((run / "parent.json").read_text()) if (run / "parent.json").is_file() else None
        parent_digest, parent_zoo = _parent_identity(parent, root)
        if parent_zoo == PREFIX + name:
            if parent_name is None:
                raise ZooError(
                    f"{run} was trained from zoo:{name}, the entry it replaces; give parent_name=NAME, the "
                    "name its provenance records for that parent (e.g. the study plan's training stage)"
                )
            check_name(parent_name)
        elif parent_name is not None:
            raise ZooError(f"parent_name is only for a run trained from the entry it replaces (zoo:{name})")
        shutil.copy2(run / "config.yaml", tmp / "config.yaml")
        if (run / VECNORM_FILE).is_file():
            shutil.copy2(run / VECNORM_FILE, tmp / VECNORM_FILE)
        model = _slim_model(run / MODEL_FILE, tmp / MODEL_FILE)
        summary_path = run / "eval" / SUMMARY_FILE
        summary = json.loads(summary_path.read_text()) if summary_path.is_file() else None
        if summary is not None:
            shutil.copy2(summary_path, tmp / SUMMARY_FILE)
        records = check_episodes(tmp, check_scenes)
        atomic_write_text(tmp / CHECK_FILE, episodes_csv(records))
        curve = _learning_curve(run / "tb")
        if curve is not None:
            atomic_write_text(tmp / CURVE_FILE, curve)
        train_info = json.loads((run / "train_info.json").read_text()) if (run / "train_info.json").is_file() else {}
        # a run initialised from another starts counting at 0: its own steps; the total adds its
        # whole lineage's
        parent_steps = int(parent.get("parent_num_timesteps", 0)) if parent else 0
        lineage_steps = _lineage_steps(parent, parent_zoo, root)
        prov = {
            "name": name,
            "condition": condition,
            "description": description,
            "source_run": str(run),
            "commit": commit_of(commit),
            "seed": int(cfg.seed),
            "backend": cfg.backend.name,
            "task": cfg.task.name,
            "noise": cfg.noise.get("name", "none"),
            "randomization": (cfg.get("randomization") or {}).get("name", "none"),
            "agent": cfg.agent.get("name"),
            "obs_size": model["obs_size"],
            "weights_sha256": weights_digest(tmp / MODEL_FILE),
            "steps": model["num_timesteps"],
            "steps_total": model["num_timesteps"] + lineage_steps,
            "wall_time_s": train_info.get("wall_time_s"),
            "parent": None
            if parent is None
            else {
                "zoo": PREFIX + parent_name if parent_name is not None else parent_zoo,
                "run": parent.get("init_from"),
                "backend": parent.get("parent_backend"),
                "task": parent.get("parent_task"),
                "steps": parent_steps,
                "weights_sha256": parent_digest,
            },
            "library_versions": {
                "at_training (model.zip system_info)": _training_versions(run / MODEL_FILE),
                "at_add": _installed_versions(),
            },
            "check": {"n_scenes": check_scenes, "scenes_seed": STANDARD_SCENES_SEED, "eval_seed": 0},
            "model": "the run's model.zip with a fresh optimizer state (policy and value weights unchanged), deflated",
            "files": {},
        }
        prov["files"] = {p.name: _sha256(p) for p in sorted(tmp.iterdir()) if p.is_file()}
        atomic_write_text(tmp / PROVENANCE_FILE, json.dumps(prov, indent=2) + "\n")
        os.chmod(tmp, 0o755)
        target = root / name
        old = None
        if target.exists():
            old = Path(tempfile.mkdtemp(dir=root, prefix=f".{name}.replaced-"))
            os.replace(target, old / name)
        os.replace(tmp, target)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    row = {
        "condition": condition,
        "seed": prov["seed"],
        "backend": prov["backend"],
        "task": prov["task"],
        "noise": prov["noise"],
        "steps_total": prov["steps_total"],
        "success": None if summary is None else summary.get("success"),
        "description": description,
        "source_run": str(run),
    }
    update_index(root, lambda index: index["entries"].__setitem__(name, row))
    return row


def reevaluate(name: str, root: Path | None = None, n_scenes: int | None = None) -> dict:
    """Run the entry's own evaluation again with this footsim (its config's ``eval`` section: the
    standard scenes of its task, under its noise) and replace ``summary.json``, its digest in the
    provenance and the index's success: the recorded summary then says what the code as it is now
    makes of the policy.  The provenance records the commit that evaluated it (``summary_commit``).
    ``n_scenes`` overrides the scene count (a test's shortcut; the recorded summary takes 500)."""
    from omegaconf import OmegaConf

    from footsim.rl.common import load_run_config, under_noise
    from footsim.rl.evaluate import evaluate_run
    from footsim.utils import atomic_write_texts

    root = (root or zoo_dir()).resolve()
    path = entry_dir(name, root)
    cfg = load_run_config(path)
    asked = {"plot": False, **({} if n_scenes is None else {"n_scenes": n_scenes})}
    cfg_eval = OmegaConf.merge(cfg.eval, asked)
    assert isinstance(cfg_eval, DictConfig)  # a mapping merged over a mapping
    with tempfile.TemporaryDirectory(dir=root, prefix=f".{name}.evaluating-") as out:
        evaluate_run(under_noise(cfg, cfg_eval.get("noise")), path, Path(out), cfg_eval)
        text = (Path(out) / SUMMARY_FILE).read_text()
    summary = json.loads(text)
    prov = json.loads((path / PROVENANCE_FILE).read_text())
    prov["files"][SUMMARY_FILE] = hashlib.sha256(text.encode()).hexdigest()
    prov["summary_commit"] = {
        **commit_of(None),
        "source": "the footsim checkout that evaluated it (footsim-zoo evaluate)",
    }
    # both texts synced to temporary files before either replaces its file: a failed write changes neither
    atomic_write_texts({path / SUMMARY_FILE: text, path / PROVENANCE_FILE: json.dumps(prov, indent=2) + "\n"})
    update_index(root, lambda index: index["entries"][name].__setitem__("success", summary.get("success")))
    return summary


def children(name: str, root: Path | None = None) -> list[str]:
    """The entries that record ``name`` as the zoo entry they were trained from."""
    ref = f"zoo:{name}"
    return [n for n in names(root) if (provenance(n, root).get("parent") or {}).get("zoo") == ref]


def remove(name: str, root: Path | None = None, keep_children: bool = False) -> None:
    """Take ``name`` out of the zoo: the index first (atomically), then its directory.  Refused for
    an entry another one was trained from, unless ``keep_children``: a training stage of a study
    plan (``shipped: false``), whose children's provenance keeps its name, weights digest and steps,
    though the weights themselves are gone."""
    root = (root or zoo_dir()).resolve()
    if name not in names(root):
        entry_dir(name, root)  # fails naming the zoo's entries
    kids = children(name, root)
    if kids and not keep_children:
        raise ZooError(
            f"zoo entry {name!r} is the parent of {', '.join(kids)}; remove those first, or give "
            "keep_children=true to keep them (their provenance keeps its weights digest and steps)"
        )
    update_index(root, lambda index: index["entries"].pop(name, None))
    shutil.rmtree(root / name, ignore_errors=True)


def verify(name: str, root: Path | None = None) -> list[str]:
    """What is wrong with an entry: files whose digest differs from its provenance, missing files,
    a config that no longer composes (empty when all is well)."""
    path = entry_dir(name, root)
    problems = []
    prov = json.loads((path / PROVENANCE_FILE).read_text())
    for file, digest in prov.get("files", {}).items():
        if not (path / file).is_file():
            problems.append(f"{file} is missing")
        elif _sha256(path / file) != digest:
            problems.append(f"{file} differs from the digest recorded in {PROVENANCE_FILE}")
    try:
        check_config(name, root)
    except ZooError as err:
        problems.append(str(err))
    return problems


def total_size(root: Path | None = None) -> int:
    """Bytes of every entry file in the zoo (the index included)."""
    root = root or zoo_dir()
    files = [root / INDEX_FILE] + [p for n in names(root) for p in (root / n).iterdir() if p.is_file()]
    return sum(p.stat().st_size for p in files if p.is_file())
