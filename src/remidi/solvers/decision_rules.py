"""Decision rules under ignorance over pure actions (the paper's appendix table).

All rules take a utility matrix ``utility`` [S, A] (rows = states, columns = actions) and return
the optimal action indices together with the criterion value. Ties are within ``atol``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RuleResult:
    """actions: optimal column indices, ascending; value: the criterion at those actions (for
    leximin, the ascending-sorted utility vector [S] of the optimal actions)."""

    actions: tuple[int, ...]
    value: float | tuple[float, ...]


def _best(scores: np.ndarray, atol: float) -> tuple[int, ...]:
    """Indices whose score [A] is within ``atol`` of the maximum."""
    return tuple(int(i) for i in np.flatnonzero(scores >= scores.max() - atol))


def minimax(utility: np.ndarray, atol: float = 1e-9) -> RuleResult:
    """Maximise the worst-case utility (the "minimax" / maximin rule)."""
    worst = np.asarray(utility, dtype=float).min(axis=0)
    return RuleResult(_best(worst, atol), float(worst.max()))


def leximin(utility: np.ndarray, atol: float = 1e-9) -> RuleResult:
    """Maximise the worst-case utility, break ties by the second worst, and so on."""
    ordered = np.sort(np.asarray(utility, dtype=float), axis=0)  # [S, A], ascending per action
    candidates = np.arange(ordered.shape[1])
    for row in ordered:
        scores = row[candidates]
        candidates = candidates[scores >= scores.max() - atol]
    value = tuple(map(float, ordered[:, candidates[0]]))
    return RuleResult(tuple(int(a) for a in candidates), value)


def minimax_regret(utility: np.ndarray, atol: float = 1e-9) -> RuleResult:
    """Minimise the worst-case regret; the value is that regret."""
    utility = np.asarray(utility, dtype=float)
    worst_regret = (utility.max(axis=1, keepdims=True) - utility).max(axis=0)
    return RuleResult(_best(-worst_regret, atol), float(worst_regret.min()))
