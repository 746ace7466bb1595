"""Exact minimax regret and BLP for one-step games, one small LP per observation.

A one-step game has levels, each with an observation and a reward per action. A policy is a
distribution over actions per observation. The regret of level ``l`` depends only on the policy
row of its observation ``o(l)``, so the game splits into one independent *observation game* per
observation (its levels, its policy row), and both solutions follow from those:

* **MMR.** ``min_pi max_l R_l = max_o v_o`` with ``v_o`` the minimax regret of observation ``o``'s
  game. An adversary is an equilibrium iff it puts its mass on observation games with
  ``v_o = value``, each conditional an equilibrium of that game; so the maximal-support
  equilibrium adversary is a mixture of theirs.
* **BLP.** In sequence form every observation is an information set below the empty sequence
  (:mod:`remidi.solvers.lp`). A round freezes the observations of the levels its support covers;
  a level of an observation never covered is never covered either, so a free observation's game
  always holds all its levels and its value never changes. Round ``k``'s value is therefore the
  larger of the free observations' ``v_o`` and the (now constant) regrets of the uncovered levels
  of frozen observations; its support is the tied free observations' maximal supports plus the
  tied constant levels. Each observation is frozen at its own game's MMR policy, which is thus
  the BLP policy, and it is also an optimal policy of every round (it is reported as each round's
  policy).

The observation games are solved by the shared HiGHS LPs (:func:`remidi.solvers.lp.solve_regret_game`
with the game-wide payoff scale, so ties and tolerances mean what they mean there); the rounds are
then bookkeeping over arrays. Ties: a free observation or constant level within
``lp._CANDIDATE_GAP`` (normalised) of the round's value is in its support. A round's adversary
gives each tied observation game (its own maximal-support adversary) and each tied constant level
equal weight.

Cost: one MMR LP, one adversary LP per candidate level and 2 uniqueness LPs per action for each
observation, each of the size of one observation's levels; a 10,000-level game with 100
observations and 3 actions solves in seconds. The general sequence-form solver
(:mod:`remidi.solvers.sequence_form`) gives the same values and supports on these games and is
the independent check in the tests.
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

    def observation_index(self) -> np.ndarray:
        """Index [L] of each level's observation in :attr:`observation_names`."""
        position = {o: i for i, o in enumerate(self.observation_names)}
        return np.array([position[o] for o in self.observations], dtype=int)

    @property
    def num_levels(self) -> int:
        return len(self.level_names)

    @property
    def num_observations(self) -> int:
        return len(self.observation_names)

    @property
    def num_actions(self) -> int:
        return len(self.actions)

    def obs_level_matrix(self) -> np.ndarray:
        """f64[O, L]: 1 where level l shows observation o."""
        m = np.zeros((self.num_observations, self.num_levels))
        m[self.observation_index(), np.arange(self.num_levels)] = 1.0
        return m

    def action_regret(self) -> np.ndarray:
        """f64[L, A]: regret of playing action a on level l, ``max_b r(l, b) − r(l, a)``."""
        return self.rewards.max(axis=1, keepdims=True) - self.rewards


@dataclass(frozen=True)
class _ObservationGame:
    """The solved game of one observation, in normalised payoff units: levels [K] (indices into
    the whole game), value, row [A] (its MMR policy), adversary [K] and support [K] bool (maximal
    support), unique (whether every MMR policy of the observation game plays ``row``)."""

    levels: np.ndarray
    value: float
    row: np.ndarray
    adversary: np.ndarray
    support: np.ndarray
    unique: bool


def _solve_observations(game: OneStepGame, scale: float, tol: float) -> list[_ObservationGame]:
    """Every observation's game [O], solved with payoffs divided by ``scale``."""
    n_act = game.num_actions
    actions = np.arange(1, n_act + 1)
    poly = lp.Polytope(1 + n_act, (0,), (tuple(actions),))
    eq = poly.equalities()
    obs_index = game.observation_index()
    solved = []
    for o in range(game.num_observations):
        levels = np.flatnonzero(obs_index == o)
        payoff = np.zeros((len(levels), 1 + n_act))
        payoff[:, 1:] = game.rewards[levels] / scale
        optimal = payoff[:, 1:].max(axis=1)
        every = np.ones(len(levels), dtype=bool)
        raw = lp.solve_regret_game(payoff, optimal, eq, every, tol)
        unique = lp.frozen_plan_is_unique(payoff, optimal, eq, every, raw.value, actions)
        solved.append(_ObservationGame(levels, raw.value, poly.behaviour(raw.plan, 0),
                                       raw.adversary, raw.support, unique))
    return solved


def policy_regret(game: OneStepGame, policy: np.ndarray) -> np.ndarray:
    """Regret [L] of a policy [O, A] (rows over ``observation_names``)."""
    expected = np.einsum("la,la->l", game.rewards, np.asarray(policy)[game.observation_index()])
    return game.rewards.max(axis=1) - expected


def _solve(game: OneStepGame, tol: float):
    """Scale, observation games [O], policy [O, A] (their MMR rows) and its regret [L]."""
    scale = lp.normalise(game.rewards, game.rewards.max(axis=1))
    observations = _solve_observations(game, scale, tol)
    policy = np.array([g.row for g in observations])
    return scale, observations, policy, policy_regret(game, policy)


def _round_adversary(
    n_levels: int, tied: list[_ObservationGame], tied_levels: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Adversary [L] and support [L] bool mixing the tied observation games' maximal-support
    adversaries and point masses on the tied constant levels ``tied_levels`` [K], equally."""
    adversary = np.zeros(n_levels)
    weight = 1.0 / (len(tied) + len(tied_levels))
    for g in tied:
        adversary[g.levels] += weight * g.adversary
    adversary[tied_levels] += weight
    support = np.zeros(n_levels, dtype=bool)
    for g in tied:
        support[g.levels[g.support]] = True
    support[tied_levels] = True
    return np.where(support, adversary, 0.0), support


def solve_mmr(game: OneStepGame, tol: float = 1e-7) -> MMRResult[np.ndarray]:
    """Minimax regret policy [O, A], its value and the maximal-support equilibrium adversary.

    The policy plays every observation's own MMR row (an MMR policy of the whole game).
    """
    scale, observations, policy, regret = _solve(game, tol)
    value = max(g.value for g in observations)
    tied = [g for g in observations if g.value >= value - lp._CANDIDATE_GAP]
    adversary, _ = _round_adversary(len(game.level_names), tied, np.zeros(0, dtype=int))
    return MMRResult(value * scale, policy, adversary, regret, game.rewards.max(axis=1))


def solve_blp(game: OneStepGame, tol: float = 1e-7, progress=None) -> BLPResult[np.ndarray]:
    """Bayesian level-perfect minimax regret by iterated refinement (see the module docstring).

    ``tol`` is the probability below which a level is outside an adversary's support;
    ``progress`` as in :func:`remidi.solvers.lp.solve_blp_plans`.
    """
    scale, observations, policy, regret = _solve(game, tol)
    n_levels = len(game.level_names)
    obs_index = game.observation_index()
    values = np.array([g.value for g in observations])
    regret_n = regret / scale
    free = np.ones(len(observations), dtype=bool)
    covered = np.zeros(n_levels, dtype=bool)
    rounds = []
    while not covered.all():
        constant = ~covered & ~free[obs_index]
        value = max(values[free].max(initial=-np.inf), regret_n[constant].max(initial=-np.inf))
        tied_obs = np.flatnonzero(free & (values >= value - lp._CANDIDATE_GAP))
        tied_levels = np.flatnonzero(constant & (regret_n >= value - lp._CANDIDATE_GAP))
        tied = [observations[o] for o in tied_obs]
        adversary, support = _round_adversary(n_levels, tied, tied_levels)
        covered |= support
        free[tied_obs] = False
        unique = all(g.unique for g in tied)
        members = np.flatnonzero(support)
        rounds.append(Round(value * scale, tuple(game.level_names[i] for i in members),
                            dict(zip((game.level_names[i] for i in members), adversary[members].tolist())),
                            policy, regret, unique))
        if progress is not None:
            progress(value * scale, len(members), int(covered.sum()), n_levels)
    return BLPResult(rounds[0].value, rounds, policy, regret, game.rewards.max(axis=1))
