"""A backstop on the package's layout, well above its sizes: no module over 800 lines, no function
with more than 12 parameters (positional, keyword-only, ``*args`` and ``**kwargs``; ``self`` and
``cls`` not counted). Modules are split or merged by their content, not to meet these numbers;
``python tests/test_layout.py`` prints the report a reader uses for that (the longest modules,
the functions with the most parameters, the count of functions by parameters)."""

import ast
import collections
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "remidi"
MAX_LINES = 800
MAX_PARAMETERS = 12


def modules():
    return sorted(PACKAGE.rglob("*.py"))


def parameter_counts(tree: ast.AST):
    """``(qualified name, parameters)`` of every function and method in ``tree``."""
    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = child.args
                names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
                names += [x.arg for x in (a.vararg, a.kwarg) if x is not None]
                yield prefix + child.name, len([n for n in names if n not in ("self", "cls")])
                yield from visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                yield from visit(child, f"{prefix}{child.name}.")
            else:
                yield from visit(child, prefix)

    yield from visit(tree, "")


def module_lines() -> dict[str, int]:
    return {p.relative_to(PACKAGE).as_posix(): len(p.read_text().splitlines()) for p in modules()}


def function_parameters() -> dict[str, int]:
    return {f"{p.relative_to(PACKAGE).as_posix()}:{name}": n
            for p in modules() for name, n in parameter_counts(ast.parse(p.read_text()))}


def test_no_module_is_over_the_backstop():
    over = {name: n for name, n in module_lines().items() if n > MAX_LINES}
    assert not over, f"modules over {MAX_LINES} lines (split them where their content says): {over}"


def test_no_function_takes_more_parameters_than_the_backstop():
    over = {name: n for name, n in function_parameters().items() if n > MAX_PARAMETERS}
    assert not over, f"functions over {MAX_PARAMETERS} parameters (pass the static setup as one object): {over}"


def test_the_counts_see_every_kind_of_parameter():
    tree = ast.parse("class A:\n    def f(self, a, /, b, *c, d, **e):\n        def g(x): pass\n")
    assert dict(parameter_counts(tree)) == {"A.f": 5, "A.f.g": 1}


def report(top: int = 12) -> str:
    lines, params = module_lines(), function_parameters()
    out = [f"{len(lines)} modules, {sum(lines.values())} lines; the longest:"]
    out += [f"  {n:5d}  {name}" for name, n in sorted(lines.items(), key=lambda kv: -kv[1])[:top]]
    out.append("functions by parameters: " + ", ".join(
        f"{k}: {v}" for k, v in sorted(collections.Counter(params.values()).items())))
    out.append("the most parameters:")
    out += [f"  {n:3d}  {name}" for name, n in sorted(params.items(), key=lambda kv: -kv[1])[:top]]
    return "\n".join(out)


if __name__ == "__main__":
    print(report())
