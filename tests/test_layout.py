"""The package layout, read from the source with ``ast`` (nothing is imported).

(a) No import cycles between modules: the graph of module-level ``footsim.*`` imports is acyclic
    (imports inside functions don't count: they are the lazy imports of optional simulators,
    torch / SB3 and matplotlib).
(b) No private name crosses a module boundary: no ``from footsim.x import _name``.
(c) The package root holds only the modules below both tasks and backends, the env glue and the
    config layer (:data:`ROOT_MODULES`); everything else lives in its domain package.

A finding that is being worked on can be listed in :data:`PENDING` (module -> who moves it and
why); it still fails, with that note.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "footsim"

#: Modules allowed at the package root, and why each belongs there.
ROOT_MODULES = {
    "footsim": "the package: registers the gymnasium env",
    "footsim.compiled": "numba conventions shared by every compiled kernel (walk, tasks, backends)",
    "footsim.geometry": "Pose2D and SE(2) maths, below everything",
    "footsim.scene": "Scene / Obstacle data, below both tasks and backends",
    "footsim.utils": "atomic file writes and key=value parsing, used by every layer",
    "footsim.env": "FootstepEnv: the glue of task, noise, randomizer and backend",
    "footsim.config": "the config layer that composes the Hydra groups into objects",
    "footsim.randomization": "domain-randomization terms, shared by the env and the backends",
    "footsim.schema": "the structured-config schemas of every Hydra group, registered beside the config layer",
}

#: Module -> the move that removes its finding (the lead makes these pass after the merge).
PENDING: dict[str, str] = {}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _module_level(tree: ast.Module):
    """Statements run at import: the module body, into ``if`` / ``try`` blocks, not into
    functions or classes' methods (class bodies run at import, so they count)."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        yield node
        if isinstance(node, (ast.If, ast.Try, ast.With, ast.ClassDef)):
            for field in ("body", "orelse", "finalbody", "handlers"):
                stack.extend(getattr(node, field, []))
        elif isinstance(node, ast.ExceptHandler):
            stack.extend(node.body)


def _absolute(module: str, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    is_package = MODULES[module].name == "__init__.py"
    base = module.split(".")[: len(module.split(".")) - node.level + (1 if is_package else 0)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(module: str) -> list[tuple[str, str | None, int]]:
    """``(imported module, imported name or None, line)`` of each module-level footsim import."""
    tree = ast.parse(MODULES[module].read_text(), str(MODULES[module]))
    found = []
    for node in _module_level(tree):
        if isinstance(node, ast.Import):
            found += [(a.name, None, node.lineno) for a in node.names if a.name.split(".")[0] == "footsim"]
        elif isinstance(node, ast.ImportFrom):
            source = _absolute(module, node)
            if source.split(".")[0] != "footsim":
                continue
            for alias in node.names:
                submodule = f"{source}.{alias.name}"
                if submodule in MODULES:  # ``from package import submodule``
                    found.append((submodule, None, node.lineno))
                else:
                    found.append((source, alias.name, node.lineno))
    return found


def _graph() -> dict[str, set[str]]:
    return {m: {target for target, _, _ in _imports(m) if target in MODULES and target != m} for m in MODULES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return components


def _fail(findings: list[tuple[str, str]], what: str) -> None:
    """Fail listing the findings; those in :data:`PENDING` files say which move fixes them."""
    mine = [text for module, text in findings if module not in PENDING]
    pending = [f"{text}  [pending: {PENDING[module]}]" for module, text in findings if module in PENDING]
    if mine or pending:
        lines = [f"{what}:"] + [f"  {t}" for t in mine]
        if pending:
            lines += ["after the issue-23 merge (the lead makes these pass):"] + [f"  {t}" for t in pending]
        pytest.fail("\n".join(lines))


def test_the_checker_sees_the_package():
    assert {"footsim", "footsim.env", "footsim.walk.engine", "footsim.backends.pymunk2d.backend"} <= set(MODULES)
    # ``from footsim.backends.pymunk2d import collision`` is an edge to the submodule
    assert "footsim.backends.pymunk2d.collision" in _graph()["footsim.backends.pymunk2d.backend"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles_between_modules():
    cycles = _cycles(_graph())
    _fail([(m, " -> ".join(c)) for c in cycles for m in c[:1]], "import cycles (module-level imports)")


def test_no_private_names_imported_across_modules():
    findings = []
    for module in MODULES:
        for source, name, line in _imports(module):
            if name and name.startswith("_") and source != module:
                findings.append(
                    (module, f"{MODULES[module].relative_to(PACKAGE.parent)}:{line} imports {source}.{name}")
                )
    _fail(findings, "private names imported from another module")


def test_only_the_allowed_modules_live_at_the_package_root():
    root = [m for m in MODULES if m.count(".") == 1 and MODULES[m].name != "__init__.py"] + ["footsim"]
    extra = sorted(set(root) - set(ROOT_MODULES))
    _fail(
        [(m, f"{m} (move it into its domain package or add it to ROOT_MODULES with a reason)") for m in extra],
        "modules at the package root outside the allow-list",
    )


def test_every_command_line_lives_in_footsim_tools():
    tomllib = pytest.importorskip("tomllib", reason="tomllib is in the standard library from Python 3.11")
    scripts = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())["project"]["scripts"]
    for name, target in scripts.items():
        module, _, function = target.partition(":")
        assert module in MODULES, f"{name}: {module} is not a footsim module"
        tree = ast.parse(MODULES[module].read_text())
        assert function in {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}, f"{name}: no {target}"
        assert module.startswith("footsim.tools."), f"{name} -> {target}: command lines live in footsim.tools"
