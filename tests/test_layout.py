"""The package's layout rules, checked on the source (issue 12).

* no import cycles between the package's modules (every ``import`` counts, at module level or
  inside a function, except those under ``if TYPE_CHECKING:``);
* no module reads another module's private names (``from m import _x`` or ``m._x`` on an
  imported module);
* no function longer than :data:`MAX_FUNCTION_LINES` lines unless a comment directly above its
  ``def`` (or its decorators) gives the reason;
* every subpackage has a public API (``__all__``) whose names all resolve, and the top-level
  ``grasprom.__all__`` does too;
* the CLI is imported by nothing but ``grasprom.__main__``.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "grasprom"
MAX_FUNCTION_LINES = 80
SUBPACKAGES = ("fe", "surrogate", "chain", "control", "export", "gap", "pipeline")


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted(PKG.rglob("*.py")):
        if "_shipped" in path.parts:
            continue
        rel = path.relative_to(PKG.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


MODULES = _modules()


def _is_type_checking(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _imports(tree: ast.AST):
    """Yield the import nodes of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    stack = [tree]
    while stack:
        node = stack.pop()
        for child in ast.iter_child_nodes(node):
            if _is_type_checking(child):
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                yield child
            stack.append(child)


def _resolve(module: str, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    is_pkg = MODULES[module].name == "__init__.py"
    base = base if is_pkg else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _edges(module: str) -> set[str]:
    """Package modules ``module`` imports (a name that is a submodule counts as that module)."""
    out: set[str] = set()
    for node in _imports(ast.parse(MODULES[module].read_text())):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        else:
            target = _resolve(module, node)
            targets = []
            for a in node.names:
                sub = f"{target}.{a.name}"
                targets.append(sub if sub in MODULES else target)
        out |= {t for t in targets if t in MODULES and t != module}
    return out


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        path.append(n)
        for m in sorted(graph[n]):
            if state.get(m) == 1:
                return path[path.index(m) :] + [m]
            if m not in state and (cyc := visit(m)):
                return cyc
        state[n] = 2
        path.pop()
        return None

    for n in sorted(graph):
        if n not in state and (cyc := visit(n)):
            return cyc
    return None


def test_cycle_finder_finds_a_cycle():
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycles():
    graph = {m: _edges(m) for m in MODULES}
    assert "grasprom.cli" in graph and graph["grasprom.cli"], "the walker found no imports"
    assert _find_cycle(graph) is None, " -> ".join(_find_cycle(graph) or [])


def test_cli_is_imported_by_nothing_but_main():
    users = sorted(m for m in MODULES if "grasprom.cli" in _edges(m))
    assert users == ["grasprom.__main__"], users


def _private_reads(module: str) -> list[str]:
    tree = ast.parse(MODULES[module].read_text())
    bad, module_aliases = [], {}
    for node in _imports(tree):
        if isinstance(node, ast.ImportFrom):
            target = _resolve(module, node)
            if not target.startswith("grasprom"):
                continue
            for a in node.names:
                if a.name.startswith("_") and not a.name.startswith("__"):
                    bad.append(f"{module}: from {target} import {a.name}")
                if f"{target}.{a.name}" in MODULES:
                    module_aliases[a.asname or a.name] = f"{target}.{a.name}"
        else:
            for a in node.names:
                if a.name.startswith("grasprom") and a.asname:
                    module_aliases[a.asname] = a.name
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in module_aliases
            and node.attr.startswith("_")
            and not node.attr.startswith("__")
        ):
            bad.append(f"{module}:{node.lineno}: {node.value.id}.{node.attr}")
    return bad


def test_no_module_reads_another_modules_private_names():
    bad = [b for m in MODULES for b in _private_reads(m)]
    assert not bad, "\n".join(bad)


def _long_functions(path: Path) -> list[str]:
    lines = path.read_text().splitlines()
    out = []
    for node in ast.walk(ast.parse("\n".join(lines))):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        n = node.end_lineno - node.lineno + 1
        if n <= MAX_FUNCTION_LINES:
            continue
        first = min([node.lineno] + [d.lineno for d in node.decorator_list])
        above = lines[first - 2].strip() if first >= 2 else ""
        if not above.startswith("#"):
            out.append(f"{path.relative_to(PKG.parent)}:{node.lineno} {node.name} ({n} lines)")
    return out


def test_long_function_check_sees_a_long_function(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES + 1))
    plain = tmp_path / "grasprom" / "m.py"
    plain.parent.mkdir()
    global PKG
    old, PKG = PKG, tmp_path / "grasprom"
    try:
        plain.write_text(f"def f():\n{body}\n")
        assert _long_functions(plain) == [f"grasprom/m.py:1 f ({MAX_FUNCTION_LINES + 2} lines)"]
        plain.write_text(f"# long: a table of constants\ndef f():\n{body}\n")
        assert _long_functions(plain) == []
    finally:
        PKG = old


def test_no_function_over_the_limit_without_a_reason():
    bad = [b for p in MODULES.values() for b in _long_functions(p)]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("name", ("grasprom", *(f"grasprom.{s}" for s in SUBPACKAGES)))
def test_public_api_resolves(name):
    mod = importlib.import_module(name)
    assert mod.__all__, name
    missing = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not missing, (name, missing)
