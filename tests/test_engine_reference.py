"""Refactors of the engine leave training results unchanged: every algorithm on the lever game's
tiny config (the maze's: ``tests/test_engine_reference_maze.py``) against the values stored in
``tests/data/engine_reference.json``
(``tests/engine_reference.py`` wrote them; it says when to write them again).

Metrics and runner checksums must agree to float32 rounding (a different machine's XLA may
round a reduction differently); discrete outcomes (which updates replayed, which buffer is
active, how many levels were rejected or inserted) exactly.
"""

import json

import numpy as np
import pytest

from engine_reference import CASES, PATH, fingerprint

from remidi.engine.run.checkpoint import current_name

EXACT = ("replay", "active_buffer", "rejected", "inserted", "buffer_size")


@pytest.fixture(scope="module")
def stored():
    return json.loads(PATH.read_text())


def check_against_stored(name: str, stored: dict) -> None:
    """The case's fresh fingerprint equals the stored one (EXACT metrics exactly)."""
    want, got = stored[name], fingerprint(*CASES[name])
    assert got["steps"] == want["steps"]
    for part in ("history", "per_step"):
        assert sorted(got[part]) == sorted(want[part]), part
        for metric, values in want[part].items():
            if metric in EXACT:
                np.testing.assert_array_equal(got[part][metric], values, err_msg=f"{part} {metric}")
            else:
                np.testing.assert_allclose(got[part][metric], values, rtol=2e-5, atol=1e-6, equal_nan=True,
                                           err_msg=f"{part} {metric}")
    # runner leaves by path; paths stored in the runner's earlier layout (one field per feature) are
    # read through the checkpoints' rename (engine/run/checkpoint.py RENAMES)
    stored_runner = {current_name(leaf): sums for leaf, sums in want["runner"].items()}
    assert sorted(got["runner"]) == sorted(stored_runner)
    for leaf, sums in stored_runner.items():
        np.testing.assert_allclose(got["runner"][leaf], sums, rtol=2e-5, atol=1e-5, err_msg=leaf)


#: cases in the slow tier only (the quick tier's time is spent): SFL's, added after the others
SLOW_CASES = ("sfl", "remidi-sfl")


@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.slow) if name in SLOW_CASES else name
                                  for name in CASES if not name.startswith("tmaze-")])
def test_engine_results_match_the_stored_reference(name, stored):
    check_against_stored(name, stored)
