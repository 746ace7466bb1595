"""docs/engine.md stays true: every engine module it names exists and holds the functions it
names, and the path of one update it walks is at most six modules."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GUIDE = ROOT / "docs" / "engine.md"
SRC = ROOT / "src" / "remidi"


def defined(path: Path) -> set[str]:
    """Module-level functions, classes and names assigned, and ``Class.method`` for methods."""
    tree = ast.parse(path.read_text())
    out = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out.add(node.name)
        if isinstance(node, ast.ClassDef):
            out |= {f"{node.name}.{m.name}" for m in node.body if isinstance(m, ast.FunctionDef)}
        if isinstance(node, ast.Assign):
            out |= {t.id for t in node.targets if isinstance(t, ast.Name)}
    return out


def path_section() -> list[tuple[str, list[str]]]:
    """The numbered ``module: functions`` lines after "Path:"."""
    text = GUIDE.read_text()
    block = text.split("Path:", 1)[1].split("\n\n", 2)[1]
    out = []
    for line in block.splitlines():
        m = re.match(r"\d+\. `(engine/[\w/]+\.py)`: (.*)", line)
        assert m, f"docs/engine.md: a path line is not `module`: functions: {line!r}"
        out.append((m.group(1), re.findall(r"`([\w.]+)`", m.group(2))))
    return out


def test_the_path_names_existing_modules_and_functions_and_is_short():
    path = path_section()
    assert 1 <= len(path) <= 6, f"the path of one update opens {len(path)} modules"
    for module, functions in path:
        file = SRC / module
        assert file.exists(), module
        have = defined(file)
        missing = [f for f in functions if f not in have]
        assert not missing, f"{module} has no {missing}"


def test_every_engine_module_the_guide_names_exists():
    for module in set(re.findall(r"`(?:engine/)?((?:core|adversaries|trackers|run)/\w+\.py|(?:train|learner|setup)\.py)`",
                                 GUIDE.read_text())):
        assert (SRC / "engine" / module).exists(), module


def test_the_named_helpers_exist():
    text = GUIDE.read_text()
    for module, name in re.findall(r"`(\w+)\.(\w+)`", text):
        if name == "py":  # a file name
            continue
        candidates = list((SRC / "engine").rglob(f"{module}.py"))
        if candidates:
            assert any(name in defined(c) or any(d.endswith("." + name) for d in defined(c)) for c in candidates), \
                f"{module}.{name}"
