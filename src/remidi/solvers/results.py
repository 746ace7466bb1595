"""Result types shared by the one-step and the multi-step (sequence-form) solvers.

``P`` is the policy type: an array [O, A] for one-step games (rows over observations), a mapping
``{action-observation history: {action: probability}}`` for tree games.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

P = TypeVar("P")


@dataclass(frozen=True)
class Round(Generic[P]):
    """One refinement round of BLP.

    value: the round's minimax regret over the levels still available to the adversary.
    support: names of the levels of the maximal-support equilibrium adversary.
    adversary: that adversary, ``{level name: probability}`` over ``support`` (every other level
        has probability 0; a mapping, not an array [L], so that games with thousands of rounds
        and levels stay small).
    policy: the round's policy; regret: [L] its regret on every level (rounds may share these
        objects: the one-step solver reports the final BLP policy, optimal in every round).
    unique: whether the behaviour this round freezes (its policy on every observation / history
        realisable on the levels covered so far) is the same in every optimal policy of the
        round. If not, later rounds and the final regrets may depend on which optimal policy the
        LP solver returned: a BLP policy need not be unique (:mod:`remidi.solvers.lp`).
    """

    value: float
    support: tuple[str, ...]
    adversary: dict[str, float]
    policy: P
    regret: np.ndarray
    unique: bool


@dataclass(frozen=True)
class MMRResult(Generic[P]):
    """Minimax regret: value, policy, maximal-support equilibrium adversary [L], regret [L] of
    the policy, and optimal_return [L] (U*, the best return on each level alone)."""

    value: float
    policy: P
    adversary: np.ndarray
    regret: np.ndarray
    optimal_return: np.ndarray


@dataclass(frozen=True)
class BLPResult(Generic[P]):
    """Bayesian level-perfect minimax regret by iterated refinement.

    mmr_value: round 1's value; rounds: every round; policy: the final policy; regret [L] and
    optimal_return [L] as in :class:`MMRResult`.
    """

    mmr_value: float
    rounds: list[Round[P]]
    policy: P
    regret: np.ndarray
    optimal_return: np.ndarray
