"""The package's import graph: no cycle among its modules, and no function-local imports of
``remidi`` inside the engine (each would hide a cycle or a dependency a reader cannot see at the
top of the module). Read with ``ast``: module-level imports only, ``if TYPE_CHECKING`` blocks
included (they are imports a reader must follow too)."""

import ast
import json
import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parent.parent / "src"
PACKAGE = SRC / "remidi"
ENGINE = PACKAGE / "engine"
#: optional dependencies an engine function may import where it needs them (none today)
OPTIONAL = ()


def module_name(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in PACKAGE.rglob("*.py")}


def _resolve(node: ast.ImportFrom, name: str, here: str, is_package: bool) -> str:
    if node.level == 0:
        return node.module or ""
    base = here.split(".") if is_package else here.split(".")[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def module_level_imports(name: str, path: Path, known: dict) -> set[str]:
    """The package modules ``name`` imports at module level (``from pkg import sub`` names the
    submodule where ``sub`` is one)."""
    tree = ast.parse(path.read_text())
    out = set()
    for node in tree.body:
        nodes = [node] + ([n for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom))]
                          if isinstance(node, (ast.If, ast.Try)) else [])
        for n in nodes:
            if isinstance(n, ast.Import):
                out |= {a.name for a in n.names if a.name in known}
            elif isinstance(n, ast.ImportFrom):
                target = _resolve(n, n.module, name, path.name == "__init__.py")
                for a in n.names:
                    sub = f"{target}.{a.name}"
                    if sub in known:
                        out.add(sub)
                    elif target in known:
                        out.add(target)
    out.discard(name)
    return out


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of modules (first repeated last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_the_package_has_no_import_cycle():
    known = modules()
    graph = {name: module_level_imports(name, path, known) for name, path in known.items()}
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " → ".join(cycle)


def test_the_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_no_function_local_remidi_import_inside_the_engine():
    local = []
    for path in sorted(ENGINE.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                         [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else
                         ["remidi (relative)"] if isinstance(node, ast.ImportFrom) else [])
                for name in names:
                    if name.split(".")[0] == "remidi" or name == "remidi (relative)":
                        if name not in OPTIONAL:
                            local.append(f"{path.relative_to(SRC)}:{node.lineno} {fn.name} imports {name}")
    assert not local, "function-local imports of remidi in the engine:\n" + "\n".join(local)


def test_dir_of_the_package_lists_its_public_names_without_importing_jax():
    """``dir(remidi)`` (tab completion) lists ``__all__``, the lazily imported names included; it
    imports nothing heavy (``import remidi`` stays free of JAX). Before, it listed none of them."""
    probe = ("import sys, json, remidi; names = dir(remidi); "
             "print(json.dumps([names, remidi.__all__, 'jax' in sys.modules]))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    names, public, jax_imported = json.loads(done.stdout.strip().splitlines()[-1])
    assert set(public) <= set(names) and "run_ued" in names and "register_score" in names
    assert not jax_imported
