"""The prose a newcomer reads: a README they finish, whose first commands are the ones CI runs, and
no issue-tracker numbers in the README, the docs pages, the tests or the source (a reader has no
tracker to look them up in; what the issue was about belongs in the sentence).

Not checked: ``docs/notes/`` (notes kept for the record). The README's claims table and the
generated blocks of ``docs/results.md`` come from ``tools/results/`` and are checked with it."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
MAX_README_LINES = 300
MAX_README_BYTES = 12 * 1024  # a page a newcomer finishes; the rest is a page in docs/
DEMO = "pip install -e . && remidi run tabular-shared"
TESTS = 'pip install -e ".[test]" && python -m pytest -n 2 -q -m "not slow"'
#: an issue or pull-request reference: "#" and a number of two digits or more (a one-digit "#3"
#: is an ordinal: "goal #3"), or the word "issue" (or "PR") followed by a number
ISSUE = re.compile(r"(?<![\w&#/])#\d{2,}\b|\b(?:issue|pr|pull request)s?\s+#?\d+\b", re.IGNORECASE)
CLAIMS = re.compile(r"<!-- generated:claims -->.*?<!-- /generated:claims -->", re.DOTALL)


def _code_blocks(text: str) -> list[list[str]]:
    """The fenced code blocks of a Markdown text, each as its lines."""
    return [block.splitlines() for block in re.findall(r"^```[^\n]*\n(.*?)^```", text, re.DOTALL | re.MULTILINE)]


def _issue_refs(paths) -> list[str]:
    found = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        if path == README:
            text = CLAIMS.sub("", text)
        for n, line in enumerate(text.splitlines(), 1):
            found += [f"{path.relative_to(ROOT)}:{n}: {m.group(0)}" for m in ISSUE.finditer(line)]
    return found


def test_the_readme_is_short():
    lines = README.read_text(encoding="utf-8").count("\n")
    assert lines <= MAX_README_LINES, f"README.md has {lines} lines; move sections to docs/ (at most {MAX_README_LINES})"
    size = README.stat().st_size
    assert size <= MAX_README_BYTES, f"README.md has {size} bytes; move sections to docs/ (at most {MAX_README_BYTES})"


def test_the_readmes_first_code_block_is_the_two_set_up_commands():
    blocks = _code_blocks(README.read_text(encoding="utf-8"))
    assert blocks, "README.md has no code block"
    assert [line.strip() for line in blocks[0] if line.strip()] == [DEMO, TESTS]


def _section(text: str, title: str) -> str:
    """The Markdown section ``## title`` of ``text``, up to the next ``## `` heading."""
    return re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.DOTALL | re.MULTILINE).group(1)


def test_the_installation_commands_run_as_written():
    """No placeholder (``<this repository's URL>``) to fill in: the commands start in the clone."""
    install = _section(README.read_text(encoding="utf-8"), "Installation")
    (first, *_) = _code_blocks(install)
    assert not [line for line in first if re.search(r"<[^>]+>", line)], first
    assert first[0].startswith("python3 -m venv") and "clone of this repository" in install


def test_the_readme_says_where_the_compilation_cache_goes_and_how_to_turn_it_off():
    """Runs write JAX's compiled programs outside the run folder (remidi/compile_cache.py): the README
    names the folder and the environment variable that moves it or turns it off."""
    from remidi import compile_cache

    install = " ".join(_section(README.read_text(encoding="utf-8"), "Installation").split())
    assert "~/.cache/remidi/jax/" in install and "$XDG_CACHE_HOME" in install
    assert f"{compile_cache.ENV}=off" in install and f"{compile_cache.ENV}=DIR" in install
    assert "off" in compile_cache.OFF


def test_ci_runs_the_readmes_test_command_first():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    first = next(line.strip() for line in ci if "pytest" in line and not line.lstrip().startswith("#"))
    readme_tests = _code_blocks(README.read_text(encoding="utf-8"))[0]
    assert first == next(line.strip() for line in readme_tests if "pytest" in line) == TESTS


def test_the_claims_table_markers_are_there_once():
    text = README.read_text(encoding="utf-8")
    assert text.count("<!-- generated:claims -->") == text.count("<!-- /generated:claims -->") == 1
    assert CLAIMS.search(text)


def test_no_issue_numbers_in_the_readme_docs_and_tests():
    docs = [p for p in (ROOT / "docs").rglob("*.md") if (ROOT / "docs" / "notes") not in p.parents]
    found = _issue_refs([README, *sorted(docs), *sorted((ROOT / "tests").glob("*.py"))])
    assert not found, "issue numbers:\n" + "\n".join(found)


def test_no_issue_numbers_in_the_source():
    found = _issue_refs(sorted((ROOT / "src").rglob("*.py")) + sorted((ROOT / "tools").rglob("*.py")))
    assert not found, "issue numbers:\n" + "\n".join(found)


def test_no_issue_numbers_in_the_generated_claims_table():
    """The README's claims table is written by the results-page generator (``tools/results/``)."""
    table = CLAIMS.search(README.read_text(encoding="utf-8")).group(0)
    found = [m.group(0) for m in ISSUE.finditer(table)]
    assert not found, f"issue numbers in the README's generated claims table: {found}"
