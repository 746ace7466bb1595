"""Decision rules on utility tables: the paper's appendix table and brute-force comparisons."""

import numpy as np
import pytest

from remidi.solvers.decision_rules import leximin, minimax, minimax_regret

# rows = states s1..s3, columns = actions a1..a4 (paper appendix)
PAPER = np.array([
    [-100, -100, -101, -101],
    [-90, -2, -1, 1],
    [-90, 0, -1, -2],
])


def test_paper_table():
    assert minimax(PAPER).actions == (0, 1)
    assert minimax(PAPER).value == -100
    assert leximin(PAPER).actions == (1,)
    assert leximin(PAPER).value == (-100, -2, 0)
    assert minimax_regret(PAPER).actions == (2, 3)
    assert minimax_regret(PAPER).value == 2


def test_single_state_rules_agree_on_the_best_action():
    utility = np.array([[3.0, 5.0, 5.0, 1.0]])
    for rule in (minimax, leximin, minimax_regret):
        assert rule(utility).actions == (1, 2)
    assert minimax_regret(utility).value == 0


@pytest.mark.parametrize("seed", range(20))
def test_rules_match_direct_definitions(seed):
    rng = np.random.default_rng(seed)
    utility = rng.integers(-3, 4, size=(rng.integers(1, 5), rng.integers(1, 5)))
    columns = [tuple(utility[:, a]) for a in range(utility.shape[1])]
    worst = [min(c) for c in columns]
    assert minimax(utility).actions == tuple(a for a, w in enumerate(worst) if w == max(worst))
    ordered = [tuple(sorted(c)) for c in columns]
    assert leximin(utility).actions == tuple(a for a, o in enumerate(ordered) if o == max(ordered))
    best = utility.max(axis=1)
    regret = [max(b - u for b, u in zip(best, c)) for c in columns]
    assert minimax_regret(utility).actions == tuple(
        a for a, r in enumerate(regret) if r == min(regret))
    assert minimax_regret(utility).value == min(regret)
