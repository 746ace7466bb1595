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

The observation games are solved by the shared HiGHS LPs (:func:`remidi.solvers.lp.solve_regret_game`),
each in its own units: its levels' action regrets (a per-level shift of the rewards, which leaves
regrets unchanged) divided by their largest, so an observation whose rewards are 1e12 leaves the
others' LPs as well conditioned as if it were absent, and the LP tolerances are relative to each
observation game's own payoff scale. The rounds are then bookkeeping over arrays. Each
observation game's value is bracketed by numbers computed directly from its action regrets: the
worst regret of its policy row (an upper bound, the value reported) and the least expected
regret against its optimal vertex adversary (a lower bound). Ties: a free observation or
constant level is in a round's support if its upper bound reaches the round's largest lower bound
(less ``_TIE_RTOL`` of it), so values of observation games of very different scales are compared
as numbers, not within a tolerance of the larger scale. A round's adversary gives each tied
observation game (its own maximal-support adversary) and each tied constant level equal weight.
Every round is then checked (:func:`remidi.solvers.checks.check_rounds`) against the regrets of the
policy computed from the rewards (:func:`policy_regret`).

Cost: one MMR LP, one adversary LP per candidate level, one support LP per support level of
low probability and 2 uniqueness LPs per action for each observation, each of the size of one
observation's levels, then O(L log L) for the rounds and their checks; a 10,000-level game with
100 observations and 3 actions (9,800 rounds) solves in seconds. The general sequence-form solver
(:mod:`remidi.solvers.sequence_form`) gives the same values and supports on these games and is
the independent check in the tests.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np

from remidi.solvers import checks, lp, polytope
from remidi.solvers.results import BLPResult, MMRResult, Round

#: Observation games whose values agree to this relative accuracy are tied (merged into one round).
_TIE_RTOL = 1e-9


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
    """The solved game of one observation: levels [K] (indices into the whole game), row [A] (its
    MMR policy), adversary [K] and support [K] bool (maximal support), unique (whether every MMR
    policy of the observation game plays ``row``), and in real units: value (the worst regret of
    ``row``), bound (the least expected regret against an optimal vertex adversary, a lower bound
    on the value), guarantee (the same against ``adversary``) and scale (the LP's payoff scale)."""

    levels: np.ndarray
    row: np.ndarray
    adversary: np.ndarray
    support: np.ndarray
    unique: bool
    value: float
    bound: float
    guarantee: float
    scale: float


def _action_regrets(game: OneStepGame) -> tuple[np.ndarray, np.ndarray]:
    """unit [L] and action regrets [L, A] in those units (real regret = unit * regret).

    A level's unit is a power of two of the size of the largest reward magnitude of its
    observation, so dividing by it is exact, no action regret overflows, and each one
    (``max_b r_b - r_a``, one rounding) keeps full relative precision.
    """
    obs_index = game.observation_index()
    largest = np.zeros(game.num_observations)
    np.maximum.at(largest, obs_index, np.abs(game.rewards).max(axis=1, initial=0.0))
    units = np.where(largest > 0, np.ldexp(1.0, np.frexp(largest)[1] - 1), 1.0)[obs_index]
    scaled = game.rewards / units[:, None]
    return units, scaled.max(axis=1, keepdims=True) - scaled


def _real(x: float, unit: float) -> float:
    """``x * unit``, capped at the largest float (scales only bound tolerances)."""
    with np.errstate(over="ignore"):
        return float(min(x * unit, np.finfo(float).max))


def _solve_observations(game: OneStepGame, tol: float) -> list[_ObservationGame]:
    """Every observation's game [O], each solved in its own units (see the module docstring)."""
    n_act = game.num_actions
    actions = np.arange(1, n_act + 1)
    poly = polytope.Polytope(1 + n_act, (0,), (tuple(actions),))
    eq = poly.equalities()
    obs_index = game.observation_index()
    units, regrets = _action_regrets(game)
    solved = []
    for o in range(game.num_observations):
        levels = np.flatnonzero(obs_index == o)
        gaps, unit = regrets[levels], units[levels[0]]
        scale = float(gaps.max(initial=0.0)) or 1.0
        payoff = np.zeros((len(levels), 1 + n_act))
        payoff[:, 1:] = -gaps / scale
        optimal = np.zeros(len(levels))
        every = np.ones(len(levels), dtype=bool)
        raw = lp.solve_regret_game(payoff, optimal, eq, every, tol)
        unique = lp.frozen_plan_is_unique(payoff, optimal, eq, every, raw.value, actions)
        row = poly.behaviour(raw.plan, 0)
        with np.errstate(over="ignore"):  # an overflowing value is refused by the checks
            solved.append(_ObservationGame(
                levels, row, raw.adversary, raw.support, unique,
                value=float((gaps @ row).max() * unit),
                bound=float((raw.certificate @ gaps).min() * unit),
                guarantee=float((raw.adversary @ gaps).min() * unit),
                scale=_real(scale, unit)))
    return solved


def policy_regret(game: OneStepGame, policy: np.ndarray) -> np.ndarray:
    """Regret [L] of a policy [O, A] (rows over ``observation_names``), as the policy-weighted sum
    of the non-negative action regrets ``max_b r_b - r_a`` (inf where one it plays overflows)."""
    rows = np.asarray(policy, dtype=float)[game.observation_index()]
    with np.errstate(over="ignore"):
        gaps = game.action_regret()
    return (rows * np.where(rows > 0, gaps, 0.0)).sum(axis=1)


@dataclass(frozen=True)
class _Solved:
    """Observation games [O], policy [O, A] (their MMR rows), its regret [L] from the rewards,
    each level's LP payoff scale [L] and largest regret [L] (real units)."""

    observations: list[_ObservationGame]
    policy: np.ndarray
    regret: np.ndarray
    scale: np.ndarray
    spread: np.ndarray


def _solve(game: OneStepGame, tol: float) -> _Solved:
    """Check the rewards, then solve every observation game."""
    checks.require_finite(game.level_names, game.rewards)
    observations = _solve_observations(game, tol)
    policy = np.array([g.row for g in observations])
    scale = np.array([g.scale for g in observations])[game.observation_index()]
    units, regrets = _action_regrets(game)
    with np.errstate(over="ignore"):
        spread = np.minimum(regrets.max(axis=1) * units, np.finfo(float).max)
    return _Solved(observations, policy, policy_regret(game, policy), scale, spread)


@dataclass(frozen=True)
class _Rounds:
    """The rounds of the refinement: claims (:class:`remidi.solvers.checks.Claims`, real units) and,
    per round, its tied observation games."""

    claims: checks.Claims
    tied: list[list[_ObservationGame]]


def _rounds(solved: _Solved, obs_index: np.ndarray, limit: int | None = None) -> _Rounds:
    """The refinement's rounds (at most ``limit``), see the module docstring.

    Candidates are the free observation games, bracketed by [bound, value], and the constant
    levels of frozen observations, at their regret. A round ties every candidate whose upper end
    reaches the largest lower end (less ``_TIE_RTOL`` of it); they are taken from a heap ordered
    by upper end, so a game with many constant levels costs O(L log L), not O(L) per round.
    """
    n_levels = len(obs_index)
    heap = [(-g.value, o, -1) for o, g in enumerate(solved.observations)]  # (-upper, obs, level)
    heapq.heapify(heap)

    def lower(item) -> float:
        _, o, l = item
        return solved.observations[o].bound if l < 0 else solved.regret[l]

    round_of = np.full(n_levels, -1)
    adversary = np.zeros(n_levels)
    values, bounds, guarantees, tied_games = [], [], [], []
    while heap and (limit is None or len(values) < limit):
        taken, bound = [], -np.inf
        while heap and -heap[0][0] >= bound - _TIE_RTOL * abs(bound):
            taken.append(heapq.heappop(heap))
            bound = max(bound, lower(taken[-1]))
        tied = [t for t in taken if -t[0] >= bound - _TIE_RTOL * abs(bound)]
        for t in taken[len(tied):]:
            heapq.heappush(heap, t)
        k, weight = len(values), 1.0 / len(tied)
        games = [solved.observations[o] for _, o, l in tied if l < 0]
        levels = np.array([l for _, _, l in tied if l >= 0], dtype=int)
        for g in games:
            members = g.levels[g.support]
            round_of[members] = k
            adversary[members] = weight * g.adversary[g.support]
            for l in g.levels[~g.support]:  # constant from now on
                heapq.heappush(heap, (-solved.regret[l], obs_index[l], int(l)))
        round_of[levels] = k
        adversary[levels] = weight
        values.append(-tied[0][0])
        bounds.append(bound)
        guarantees.append(weight * (sum(g.guarantee for g in games) + solved.regret[levels].sum()))
        tied_games.append(games)
    round_of[round_of < 0] = len(values)
    claims = checks.Claims(np.array(values), np.array(bounds), np.array(guarantees), round_of, adversary,
                       solved.regret, solved.scale)
    return _Rounds(claims, tied_games)


def solve_mmr(game: OneStepGame, tol: float = 1e-7) -> MMRResult[np.ndarray]:
    """Minimax regret policy [O, A], its value and the maximal-support equilibrium adversary.

    The policy plays every observation's own MMR row (an MMR policy of the whole game).
    """
    solved = _solve(game, tol)
    claims = _rounds(solved, game.observation_index(), limit=1).claims
    checks.check_rounds(claims, game.level_names, solved.spread)
    adversary = np.where(claims.round_of == 0, claims.adversary, 0.0)
    return MMRResult(float(claims.value[0]), solved.policy, adversary, solved.regret,
                     game.rewards.max(axis=1))


def solve_blp(game: OneStepGame, tol: float = 1e-7, progress=None) -> BLPResult[np.ndarray]:
    """Bayesian level-perfect minimax regret by iterated refinement (see the module docstring).

    ``tol`` is the probability below which a level is outside an adversary's support;
    ``progress`` as in :func:`remidi.solvers.lp.solve_blp_plans` (called once every round is
    solved and checked).
    """
    solved = _solve(game, tol)
    found = _rounds(solved, game.observation_index())
    claims = found.claims
    checks.check_rounds(claims, game.level_names, solved.spread)
    checks.check_final(claims, solved.regret, game.level_names, solved.spread)
    order = np.argsort(claims.round_of, kind="stable")
    starts = np.searchsorted(claims.round_of[order], np.arange(len(claims.value) + 1))
    rounds = []
    for k, (value, games) in enumerate(zip(claims.value, found.tied)):
        members = order[starts[k]:starts[k + 1]]
        names = tuple(game.level_names[i] for i in members)
        rounds.append(Round(float(value), names, dict(zip(names, claims.adversary[members].tolist())),
                            solved.policy, solved.regret, all(g.unique for g in games)))
        if progress is not None:
            progress(float(value), len(members), int(starts[k + 1]), game.num_levels)
    return BLPResult(rounds[0].value, rounds, solved.policy, solved.regret, game.rewards.max(axis=1))
