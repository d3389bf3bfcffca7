"""Sweeps past one machine, end to end: the same two-job ``footsim-train`` sweep through a real local
Ray cluster and through submitit's local executor (SLURM's code path minus ``sbatch``) leaves what
the local (joblib) launcher leaves; the sbatch script of the ``slurm`` preset."""

from __future__ import annotations

import csv
import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from budgets import tiny_training

TINY = tiny_training(256, "eval.n_scenes=3", "eval.plot=false", "seed=0,1")


def _has(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def _fail_msg(proc) -> str:
    return f"rc={proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"


def _sweep(sweep: Path, *launcher_args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        ["footsim-train", "-m", *launcher_args, *TINY, f"hydra.sweep.dir={sweep}"],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert proc.returncode == 0, _fail_msg(proc)
    return proc


def _summary_rows(sweep: Path) -> list[dict]:
    proc = subprocess.run(["footsim-sweep-summary", f"dir={sweep}"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, _fail_msg(proc)
    rows = list(csv.DictReader((sweep / "sweep_summary.csv").open()))
    for row in rows:
        row.pop("launcher", None)  # the +launcher=NAME override itself
    return rows


def _files(job: Path) -> set[str]:
    return {str(p.relative_to(job)) for p in job.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory) -> Path:
    """The reference: the sweep through the local (joblib) launcher."""
    if not _has("hydra_plugins.hydra_joblib_launcher"):
        pytest.skip("hydra-joblib-launcher not installed (pip install 'footsim[joblib]')")
    sweep = tmp_path_factory.mktemp("local") / "sweep"
    _sweep(sweep, "+launcher=local", "hydra.launcher.n_jobs=2")
    return sweep


def _assert_same_as_local(sweep: Path, local: Path) -> None:
    for job in ("0", "1"):
        files = _files(sweep / job)
        assert files == _files(local / job), (job, sorted(files ^ _files(local / job)))
        for name in ("model.zip", "config.yaml", "eval/summary.json", "eval/episodes.csv", ".hydra/overrides.yaml"):
            assert name in files, (job, name)
        for name in ("config.yaml", "eval/summary.json", "eval/episodes.csv"):  # seeded: the same numbers
            assert (sweep / job / name).read_bytes() == (local / job / name).read_bytes(), (job, name)
    rows = _summary_rows(sweep)
    assert [(r["job"], r["status"], r["seed"]) for r in rows] == [("0", "ok", "0"), ("1", "ok", "1")]
    assert rows == _summary_rows(local)


# -- Ray ----------------------------------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def ray_head():
    """A Ray head node on this machine, loopback only; yields (address, env for its clients).

    ``ray start --block`` keeps the node's processes as its children and stops them on SIGTERM,
    so the fixture owns exactly one process.  Ray replaces 127.0.0.1 by the machine's address
    unless RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0 (its single-machine mode); head and clients both need it.
    """
    if not _has("hydra_plugins.hydra_ray_launcher"):
        pytest.skip("hydra-ray-launcher not installed (pip install 'footsim[ray]')")
    ray_cli = Path(sys.executable).with_name("ray")
    ray_cli = ray_cli if ray_cli.is_file() else Path(shutil.which("ray") or "ray")
    env = {**os.environ, "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}
    temp = tempfile.mkdtemp(prefix="ray")  # short: Ray's socket paths live below it
    port = _free_port()
    log = Path(temp) / "head.log"
    args = [
        str(ray_cli),
        "start",
        "--head",
        "--block",
        "--node-ip-address=127.0.0.1",
        f"--port={port}",
        f"--ray-client-server-port={_free_port()}",
        f"--dashboard-agent-listen-port={_free_port()}",
        "--num-cpus=2",
        "--include-dashboard=false",
        "--disable-usage-stats",
        f"--temp-dir={temp}",
    ]
    with log.open("w") as out:
        head = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, env=env)
    try:
        deadline = time.monotonic() + 120
        while "Ray runtime started" not in log.read_text():
            assert head.poll() is None, f"ray start exited with {head.returncode}:\n{log.read_text()[-3000:]}"
            assert time.monotonic() < deadline, f"ray start did not come up in 120 s:\n{log.read_text()[-3000:]}"
            time.sleep(0.5)
        yield f"127.0.0.1:{port}", env
    finally:
        head.send_signal(signal.SIGTERM)
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait(timeout=30)
        shutil.rmtree(temp, ignore_errors=True)


@pytest.mark.slow
def test_ray_sweep_on_a_local_cluster_leaves_what_the_local_launcher_leaves(ray_head, local_sweep, tmp_path):
    address, env = ray_head
    sweep = tmp_path / "ray"
    proc = _sweep(sweep, "+launcher=ray", f"hydra.launcher.ray.init.address={address}", env=env)
    assert f"Connecting to existing Ray cluster at address: {address}" in proc.stdout + proc.stderr
    assert "(_run_job pid=" in proc.stdout + proc.stderr  # the jobs ran as Ray tasks
    _assert_same_as_local(sweep, local_sweep)


# -- submitit -----------------------------------------------------------------------------------------
needs_submitit = pytest.mark.skipif(
    not _has("hydra_plugins.hydra_submitit_launcher"),
    reason="hydra-submitit-launcher not installed (pip install 'footsim[slurm]')",
)


@pytest.mark.slow
@needs_submitit
def test_submitit_local_sweep_leaves_what_the_local_launcher_leaves(local_sweep, tmp_path):
    sweep = tmp_path / "submitit"
    _sweep(sweep, "hydra/launcher=submitit_local")
    job_logs = sorted(p.name for p in (sweep / ".submitit").rglob("*_log.out"))
    assert len(job_logs) == 2, job_logs  # one submitit job (own process) per Hydra job
    _assert_same_as_local(sweep, local_sweep)


FAKE_SBATCH = """#!/bin/sh
cp "$1" "$SBATCH_COPY"
echo "sbatch: error: no SLURM on this machine (script kept in $SBATCH_COPY)" >&2
exit 1
"""


@needs_submitit
def test_slurm_preset_writes_an_sbatch_array_script(tmp_path):
    """The real submission path up to ``sbatch``: a stand-in ``sbatch`` keeps the script submitit
    wrote and refuses the job (``srun`` only has to exist)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "sbatch").write_text(FAKE_SBATCH)
    (bin_dir / "srun").write_text("#!/bin/sh\nexit 1\n")
    for tool in bin_dir.iterdir():
        tool.chmod(0o755)
    script = tmp_path / "sbatch.sh"
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "SBATCH_COPY": str(script)}
    sweep = tmp_path / "sweep"
    proc = subprocess.run(
        ["footsim-train", "-m", "+launcher=slurm", "hydra.launcher.partition=cpu", "hydra.launcher.array_parallelism=2"]
        + ["train.n_envs=4", "seed=0,1,2", f"hydra.sweep.dir={sweep}"],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert proc.returncode != 0 and "no SLURM on this machine" in proc.stderr, _fail_msg(proc)
    text = script.read_text()  # docs/SWEEPS.md shows it
    lines = set(text.splitlines())
    for flag in (
        "--partition=cpu",
        "--cpus-per-task=4",  # ${train.n_envs}
        "--time=240",  # timeout_min
        "--mem=8GB",
        "--array=0-2%2",  # 3 jobs, at most array_parallelism at once
        "--nodes=1",
        "--ntasks-per-node=1",
    ):
        assert f"#SBATCH {flag}" in lines, (flag, text)
    assert f"{sweep}/.submitit/" in text and "-m submitit.core._submit" in text
    assert not (sweep / "0").exists()  # nothing ran
