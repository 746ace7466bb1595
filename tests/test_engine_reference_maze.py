"""Refactors of the engine leave training results unchanged on the maze: every algorithm for a
few updates of the ``tmaze`` experiment's config with a tiny agent (``tests/engine_reference.py``'s
``MAZE_TINY``), against ``tests/data/engine_reference.json``. A file of its own so that its
compiles run beside the lever cases'."""

import pytest

from engine_reference import CASES
from test_engine_reference import check_against_stored, stored  # noqa: F401  (fixture)


@pytest.mark.parametrize("name", [name for name in CASES if name.startswith("tmaze-")])
def test_maze_results_match_the_stored_reference(name, stored):  # noqa: F811
    check_against_stored(name, stored)
