"""docs/engine.md is the read the trace measures: its path of one ReMiDi update and of one PLR⊥
update names every module and function that update runs, in the order they are first called
(tests/step_trace.py, as ../shared/tools/read_cost.py measures it), and every other engine module
it names exists."""

import re
from pathlib import Path

import pytest
from step_trace import step_trace

ROOT = Path(__file__).resolve().parent.parent
GUIDE = ROOT / "docs" / "engine.md"
SRC = ROOT / "src" / "remidi"
SECTIONS = {"remidi": "## One ReMiDi update", "plr": "## One PLR⊥ update"}


def by_module(trace: list[tuple[str, str]]) -> list[tuple[str, list[str]]]:
    """The trace as ``(module, functions)``, modules in the order first entered, each module's
    functions in the order first called."""
    out: dict[str, list[str]] = {}
    for module, function in trace:
        out.setdefault(module, []).append(function)
    return list(out.items())


def path_lines(trace) -> str:
    """The guide's numbered path lines for ``trace``."""
    return "\n".join(f"{i}. `{module}`: " + ", ".join(f"`{f}`" for f in functions)
                     for i, (module, functions) in enumerate(by_module(trace), 1))


def guide_path(algo: str) -> list[tuple[str, list[str]]]:
    """The numbered ``module: functions`` lines after "Path:" in the algorithm's section."""
    section = GUIDE.read_text().split(SECTIONS[algo], 1)[1]
    block = section.split("Path:", 1)[1].split("\n\n", 2)[1]
    out = []
    for line in block.splitlines():
        m = re.match(r"\d+\. `([\w/]+\.py)`: (.*)", line)
        assert m, f"docs/engine.md: a path line is not `module`: functions: {line!r}"
        out.append((m.group(1), re.findall(r"`([\w.]+)`", m.group(2))))
    return out


@pytest.mark.parametrize("algo", list(SECTIONS))
def test_the_guide_walks_what_one_update_runs(algo):
    want = by_module(step_trace(algo))
    assert guide_path(algo) == want, (f"docs/engine.md's path of one {algo} update is not what the update runs; "
                                      f"it is:\n{path_lines(step_trace(algo))}")


def test_every_engine_module_the_guide_names_exists():
    for module in set(re.findall(r"`(?:engine/)?((?:core|adversaries|trackers|run)/[\w/]+\.py|(?:train|learner|setup)\.py)`",
                                 GUIDE.read_text())):
        assert (SRC / "engine" / module).exists(), module


if __name__ == "__main__":  # the path lines to paste into docs/engine.md
    import sys

    for algo in sys.argv[1:] or SECTIONS:
        print(f"{SECTIONS[algo]}\n{path_lines(step_trace(algo))}\n")
