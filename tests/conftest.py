import os
import subprocess
from pathlib import Path

import pytest
from budgets import tiny_training

import footsim  # noqa: F401  (before the test modules load NumPy: footsim pins OpenBLAS's kernels)

os.environ.setdefault("MUJOCO_GL", "egl")

#: The tiny training budget of the runs ``tiny_runs`` trains (obstacle-free pymunk by default).
TINY_RUN = tiny_training(128, "eval.after_train=false")


@pytest.fixture(scope="session")
def tiny_runs(tmp_path_factory):
    """``tiny_runs(name, *overrides)``: the directory of a tiny ``footsim-train`` run (``TINY_RUN``
    plus ``overrides``), trained at its first request and shared by the session's tests, which
    only read it.  Its users carry ``@pytest.mark.xdist_group("tiny_runs")``: under xdist
    (``--dist loadgroup``) they run on one worker, which trains each run once for all of them."""
    root, runs = tmp_path_factory.mktemp("tiny_runs"), {}

    def get(name: str, *overrides: str) -> Path:
        if name not in runs:
            run_dir = root / name
            proc = subprocess.run(
                ["footsim-train", *TINY_RUN, *overrides, f"hydra.run.dir={run_dir}"],
                capture_output=True,
                text=True,
                timeout=300,
            )
            assert proc.returncode == 0, proc.stderr[-2000:]
            runs[name] = run_dir
        return runs[name]

    return get
