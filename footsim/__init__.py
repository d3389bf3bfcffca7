"""footsim: footstep-planning RL for a small humanoid on four simulators behind one interface.

``import footsim`` registers ``footsim/FootstepNav-v1`` (the Wolfgang-OP of its public URDF, the
Bit-Bots' gait and physics settings) and ``footsim/FootstepNav-v0`` (footsim 0.x's simplified robot
and tuned settings, for comparisons) with gymnasium and stays light: the simulators, torch and
stable-baselines3 are imported only where they are used.
"""

import os
import platform
import sys
import warnings


def _x86_with_avx2() -> bool:
    """Whether this is an x86-64 CPU with AVX2 and FMA (what OpenBLAS's Haswell kernels need)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    try:
        with open("/proc/cpuinfo") as fh:
            flags = next((line for line in fh if line.startswith("flags")), "").split()
    except OSError:
        return False
    return "avx2" in flags and "fma" in flags


def _pin_openblas_kernels() -> None:
    """NumPy's and SciPy's OpenBLAS choose their kernels by CPU when they load (Haswell, SkylakeX,
    Zen, ...), and the kernels round differently: a 3D walk's small matrix products then differ in
    the last bits between hosts, which a falling robot amplifies into other outcomes (the MuJoCo
    footstep baseline on 100 scenes: 6.35 s with SkylakeX kernels, 6.19 s with Haswell's).  One kernel
    set on every x86-64 CPU with AVX2 keeps the evaluations the same on every such host; a user's
    own OPENBLAS_CORETYPE wins.  It must be set before NumPy loads OpenBLAS: imported after NumPy,
    footsim says so once instead of pinning nothing silently."""
    if "OPENBLAS_CORETYPE" in os.environ or not _x86_with_avx2():
        return
    if "numpy" in sys.modules:
        warnings.warn(
            "footsim was imported after NumPy, so NumPy's OpenBLAS chose its kernels by CPU and 3D "
            "evaluations may differ from docs/RESULTS.md in the last bits and then in outcomes; import "
            "footsim first or set OPENBLAS_CORETYPE=Haswell before starting Python",
            RuntimeWarning,
            stacklevel=3,
        )
    os.environ["OPENBLAS_CORETYPE"] = "Haswell"  # for the subprocesses (env workers, evaluation jobs)


_pin_openblas_kernels()

import gymnasium  # noqa: E402  (after the kernel pin: gymnasium loads NumPy)

__version__ = "0.1.0"

if "footsim/FootstepNav-v1" not in gymnasium.registry:
    gymnasium.register(id="footsim/FootstepNav-v1", entry_point="footsim.env:FootstepEnv")
if "footsim/FootstepNav-v0" not in gymnasium.registry:
    gymnasium.register(id="footsim/FootstepNav-v0", entry_point="footsim.env:footstep_nav_v0")


def make_env(*args, **kwargs):
    """Build a ``FootstepEnv`` from a composed Hydra config (see ``footsim.env.make_env``)."""
    from footsim.env import make_env as _make_env

    return _make_env(*args, **kwargs)
