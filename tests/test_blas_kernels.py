"""``import footsim`` pins NumPy's OpenBLAS to one kernel set on x86-64 hosts with AVX2, so that a
3D evaluation gives the same episodes on every such host (footsim/__init__.py says why).  Checked
against OpenBLAS's own report of the kernels it loaded, in a fresh interpreter."""

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

from footsim import _x86_with_avx2

REPORT = """
import ctypes, glob, os, sys
{imports}
import numpy
libs = glob.glob(os.path.join(os.path.dirname(numpy.__file__), "..", "numpy.libs", "lib*openblas*"))
for lib in libs:
    for symbol in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename"):
        fn = getattr(ctypes.CDLL(lib), symbol, None)
        if fn is not None:
            fn.restype = ctypes.c_char_p
            print(fn().decode())
            sys.exit(0)
print("unknown")
"""


pytestmark = pytest.mark.skipif(not _x86_with_avx2(), reason="the kernel pin applies to x86-64 CPUs with AVX2")


def _corename(imports: str, **env: str) -> str:
    environ = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"} | env
    out = subprocess.run(
        [sys.executable, "-c", REPORT.format(imports=imports)], capture_output=True, text=True, env=environ, check=True
    ).stdout.strip()
    if out == "unknown":
        pytest.skip("this NumPy's OpenBLAS does not report its kernels")
    return out


def test_import_footsim_loads_the_haswell_kernels():
    assert _corename("import footsim").lower() == "haswell"


def test_a_users_own_kernel_choice_wins():
    assert _corename("import footsim", OPENBLAS_CORETYPE="Sandybridge").lower() == "sandybridge"


def test_imported_after_numpy_footsim_warns_instead_of_pinning_silently():
    environ = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    run = [sys.executable, "-W", "error::RuntimeWarning", "-c"]
    after = subprocess.run([*run, "import numpy, footsim"], capture_output=True, text=True, env=environ)
    assert after.returncode != 0 and "footsim was imported after NumPy" in after.stderr
    before = subprocess.run([*run, "import footsim, numpy"], capture_output=True, text=True, env=environ)
    assert before.returncode == 0, before.stderr


SCRIPTS = sorted((Path(__file__).parents[1] / "scripts").glob("*.py"))


@pytest.mark.parametrize("script", SCRIPTS, ids=[s.name for s in SCRIPTS])
def test_each_script_imports_footsim_before_numpy(script):
    """A script's imports, in its order, in a fresh interpreter: the kernel pin applies (no warning)."""
    tree = ast.parse(script.read_text())
    imports = "\n".join(ast.unparse(n) for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom)))
    environ = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    proc = subprocess.run(
        [sys.executable, "-W", "error::RuntimeWarning", "-c", imports],
        capture_output=True,
        text=True,
        env=environ,
        cwd=script.parent,
    )
    assert proc.returncode == 0, proc.stderr[-1500:]
