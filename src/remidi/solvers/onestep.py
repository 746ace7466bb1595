"""Exact minimax regret and BLP for one-step games.

A one-step game has levels, each with an observation and a reward per action. A policy is a
distribution over actions per observation. In sequence form each observation is an information set
below the empty sequence, so the realisation plan is ``[1, policy rows...]`` and every observation
is realisable (with probability 1) on each level that emits it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from remidi.solvers import lp
from remidi.solvers.results import BLPResult, MMRResult, Round


@dataclass(frozen=True)
class OneStepGame:
    """actions [A] names; level_names [L]; observations [L] (the observation id each level
    emits); rewards [L, A]."""

    actions: tuple[str, ...]
    level_names: tuple[str, ...]
    observations: tuple[str, ...]
    rewards: np.ndarray

    def __post_init__(self):
        rewards = np.asarray(self.rewards, dtype=float)
        shape = (len(self.level_names), len(self.actions))
        if rewards.shape != shape or len(self.observations) != shape[0]:
            raise ValueError(
                f"OneStepGame: rewards {rewards.shape} and observations ({len(self.observations)})"
                f" must match {len(self.level_names)} levels x {len(self.actions)} actions"
            )
        object.__setattr__(self, "rewards", rewards)

    @property
    def observation_names(self) -> tuple[str, ...]:
        """Distinct observations [O] in order of first appearance."""
        return tuple(dict.fromkeys(self.observations))


def _sequence_form(game: OneStepGame) -> tuple[lp.Polytope, np.ndarray, np.ndarray]:
    """Polytope, payoff [L, 1 + O*A] and reach [L, O] of a one-step game.

    Sequence ``1 + o * A + a`` is "play a at observation o".
    """
    n_obs, n_act = len(game.observation_names), len(game.actions)
    children = tuple(tuple(1 + o * n_act + a for a in range(n_act)) for o in range(n_obs))
    poly = lp.Polytope(1 + n_obs * n_act, (0,) * n_obs, children)
    obs_index = np.array([game.observation_names.index(o) for o in game.observations])
    reach = np.zeros((len(game.level_names), n_obs))
    reach[np.arange(len(obs_index)), obs_index] = 1.0
    payoff = np.zeros((len(game.level_names), poly.n_sequences))
    for level, o in enumerate(obs_index):
        payoff[level, list(children[o])] = game.rewards[level]
    return poly, payoff, reach


def _policy(game: OneStepGame, plan: np.ndarray) -> np.ndarray:
    """Policy [O, A] from a realisation plan [1 + O*A] (rows renormalised against LP noise)."""
    rows = np.clip(plan[1:], 0.0, None).reshape(len(game.observation_names), len(game.actions))
    return rows / rows.sum(axis=1, keepdims=True)


def policy_regret(game: OneStepGame, policy: np.ndarray) -> np.ndarray:
    """Regret [L] of a policy [O, A] (rows over ``observation_names``)."""
    obs_index = [game.observation_names.index(o) for o in game.observations]
    expected = np.einsum("la,la->l", game.rewards, np.asarray(policy)[obs_index])
    return game.rewards.max(axis=1) - expected


def _support_names(game: OneStepGame, support: np.ndarray) -> tuple[str, ...]:
    """Names of the levels where support [L] is true."""
    return tuple(n for n, s in zip(game.level_names, support) if s)


def solve_mmr(game: OneStepGame, tol: float = 1e-7) -> MMRResult[np.ndarray]:
    """Minimax regret policy [O, A], its value and the maximal-support equilibrium adversary."""
    poly, payoff, _ = _sequence_form(game)
    raw = lp.solve_mmr_plan(poly, payoff, tol)
    policy = _policy(game, raw.plan)
    return MMRResult(raw.value, policy, raw.adversary, policy_regret(game, policy),
                     game.rewards.max(axis=1))


def solve_blp(game: OneStepGame, tol: float = 1e-7, progress=None) -> BLPResult[np.ndarray]:
    """Bayesian level-perfect minimax regret by iterated refinement (see :mod:`remidi.solvers.lp`).

    ``tol`` is the probability below which a level is outside an adversary's support;
    ``progress`` as in :func:`remidi.solvers.lp.solve_blp_plans`.
    """
    poly, payoff, reach = _sequence_form(game)
    rounds = []
    for raw in lp.solve_blp_plans(poly, payoff, reach, tol, progress):
        policy = _policy(game, raw.plan)
        rounds.append(Round(raw.value, _support_names(game, raw.support), raw.adversary, policy,
                            policy_regret(game, policy), raw.unique))
    final = rounds[-1]
    return BLPResult(rounds[0].value, rounds, final.policy, final.regret, game.rewards.max(axis=1))
