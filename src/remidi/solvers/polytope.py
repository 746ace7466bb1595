"""The sequence-form policy space (:class:`Polytope`), a solved round (:class:`RawRound`), and the
regret quantities computed from the rewards without an LP: best returns, regret gaps and the
least regret against an adversary (what :mod:`remidi.solvers.checks` verifies answers with).
:mod:`remidi.solvers.lp`'s docstring states the conventions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Polytope:
    """Sequence-form policy space.

    ``parent[i]`` is the sequence leading to information set ``i``; ``children[i]`` are the
    sequences ``(i, a)``, one per available action, in action order. Information sets are listed
    so that every one comes after the information set owning its parent sequence.
    """

    n_sequences: int
    parent: tuple[int, ...]
    children: tuple[tuple[int, ...], ...]

    def equalities(self) -> tuple[np.ndarray, np.ndarray]:
        """Constraints ``E @ x = e`` of realisation plans: E [1 + I, S], e [1 + I]."""
        n_infosets = len(self.parent)
        matrix = np.zeros((1 + n_infosets, self.n_sequences))
        matrix[0, 0] = 1.0
        for i, (par, kids) in enumerate(zip(self.parent, self.children)):
            matrix[1 + i, par] = -1.0
            matrix[1 + i, list(kids)] = 1.0
        rhs = np.zeros(1 + n_infosets)
        rhs[0] = 1.0
        return matrix, rhs

    def behaviour(self, plan: np.ndarray, info: int) -> np.ndarray:
        """Action distribution [len(children[info])] the plan [S] plays at an information set.

        Only meaningful where ``plan[parent(info)] > 0``.
        """
        mass = np.clip(plan[list(self.children[info])], 0.0, None)
        return mass / mass.sum()


@dataclass(frozen=True)
class RawRound:
    """One solved regret game: value, adversary [L], support [L] bool, plan [S], regret [L],
    certificate [L] (an optimal vertex adversary: the lower bound on the value that the checks
    use), (BLP rounds only, else None) whether the policy the round freezes is unique, and
    fixed [I] bool, the information sets whose behaviour the round's game takes from the
    previous round's plan (None in round 1)."""

    value: float
    adversary: np.ndarray
    support: np.ndarray
    plan: np.ndarray
    regret: np.ndarray
    certificate: np.ndarray
    unique: bool | None = None
    fixed: np.ndarray | None = None


def _sequence_values(poly: Polytope, payoff: np.ndarray) -> np.ndarray:
    """Best continuation value [L, S] of every sequence on every level, bottom-up.

    With perfect recall the value of a sequence is its own terminal payoff plus, for each
    information set it leads to, the best child sequence.
    """
    value = np.array(payoff, dtype=float)
    for info in reversed(range(len(poly.parent))):
        value[:, poly.parent[info]] += value[:, list(poly.children[info])].max(axis=1)
    return value


def best_response_values(poly: Polytope, payoff: np.ndarray) -> np.ndarray:
    """Best return U*_l on each level alone [L], by backward induction over information sets."""
    return _sequence_values(poly, payoff)[:, 0]


def regret_gaps(poly: Polytope, payoff: np.ndarray) -> np.ndarray:
    """Regret gaps G [L, S] >= 0 with ``R_l(x) = G[l] @ x`` for every realisation plan x.

    ``G[l, (I, a)]`` is how much worse sequence ``(I, a)`` continues than the best action at
    ``I`` (both followed by a best response); the empty sequence's gap is 0. Summing plan-weighted
    gaps gives the regret without subtracting two large returns, so its rounding error is relative
    to the regret (a one-step game's gaps are its action regrets).
    """
    value = _sequence_values(poly, payoff)
    gaps = np.zeros_like(value)
    for kids in poly.children:
        kids = list(kids)
        gaps[:, kids] = value[:, kids].max(axis=1, keepdims=True) - value[:, kids]
    return gaps


def least_regret(
    poly: Polytope, cost: np.ndarray, fixed: np.ndarray | None = None, plan: np.ndarray | None = None
) -> float:
    """``min cost @ x`` over realisation plans x that play like ``plan`` [S] at the ``fixed`` [I]
    information sets; ``cost`` [S] is an adversary's mixture of regret gaps (:func:`regret_gaps`),
    so the result is the least expected regret any such policy achieves against it."""
    value = np.array(cost, dtype=float)
    for info in reversed(range(len(poly.parent))):
        kids = list(poly.children[info])
        if fixed is not None and fixed[info]:
            best = poly.behaviour(plan, info) @ value[kids]
        else:
            best = value[kids].min()
        value[poly.parent[info]] += best
    return float(value[0])


def regret_of_plan(payoff: np.ndarray, optimal: np.ndarray, plan: np.ndarray) -> np.ndarray:
    """Regret [L] of a plan [S], given payoff [L, S] and best returns [L]."""
    return optimal - payoff @ plan
