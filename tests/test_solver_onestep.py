"""Exact one-step solvers: paper values, brute-force checks on random games, BLP invariants.

The brute-force checks never use the solver's LPs: they enumerate deterministic policies, build
the normal-form regret matrix (policies x levels) and solve that matrix game with a separate LP.
"""

import itertools

import numpy as np
import pytest

from matrix_game import matrix_game_value, maximal_support
from remidi.solvers.onestep import OneStepGame, solve_blp, solve_mmr

PAPER_REWARDS = [(-0.1, 0.1), (0.7, -0.7), (-0.7, 0.7), (0.1, -0.1), (-1, 1), (1, -1)]
NAMES = tuple(f"theta{i}" for i in range(1, 7))


def paper_game(setting: str) -> OneStepGame:
    obs = ("h1", "h1", "h3", "h3", "h5", "h5") if setting == "shared" else tuple(
        f"h{i}" for i in range(1, 7))
    return OneStepGame(("A", "B"), NAMES, obs, np.array(PAPER_REWARDS))


def random_game(rng: np.random.Generator) -> OneStepGame:
    """Small game with integer rewards (ties and degenerate equilibria are common)."""
    n_levels, n_actions, n_obs = rng.integers(2, 7), rng.integers(2, 4), rng.integers(1, 4)
    obs = tuple(f"o{rng.integers(n_obs)}" for _ in range(n_levels))
    rewards = rng.integers(-3, 4, size=(n_levels, n_actions)).astype(float)
    return OneStepGame(tuple(f"a{i}" for i in range(n_actions)),
                       tuple(f"l{i}" for i in range(n_levels)), obs, rewards)


# ---------------------------------------------------------------- independent reference code


def direct_regret(game: OneStepGame, rows: dict[str, np.ndarray]) -> np.ndarray:
    """Regret [L] of a policy given as {observation: action distribution}."""
    return np.array([
        r.max() - r @ rows[o] for o, r in zip(game.observations, game.rewards)
    ])


def regret_matrix(game: OneStepGame, fixed: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """Regret [P, L] of every deterministic policy on the observations not in ``fixed``
    (those play the given distribution)."""
    fixed = fixed or {}
    free = [o for o in dict.fromkeys(game.observations) if o not in fixed]
    n_act = len(game.actions)
    rows = []
    for choice in itertools.product(range(n_act), repeat=len(free)):
        policy = dict(fixed)
        policy.update({o: np.eye(n_act)[a] for o, a in zip(free, choice)})
        rows.append(direct_regret(game, policy))
    return np.array(rows)


def policy_rows(game: OneStepGame, policy: np.ndarray) -> dict[str, np.ndarray]:
    return dict(zip(game.observation_names, policy))


# ---------------------------------------------------------------- paper values


def test_shared_game_blp_matches_paper():
    result = solve_blp(paper_game("shared"))
    assert result.mmr_value == pytest.approx(1.0, abs=1e-9)
    assert [r.value for r in result.rounds] == pytest.approx([1.0, 0.175], abs=1e-9)
    assert [set(r.support) for r in result.rounds] == [
        {"theta5", "theta6"}, {"theta1", "theta2", "theta3", "theta4"}]
    assert result.regret == pytest.approx([0.175] * 4 + [1.0] * 2, abs=1e-9)
    assert result.policy[0, 0] == pytest.approx(0.875, abs=1e-9)
    assert result.policy[1, 0] == pytest.approx(0.125, abs=1e-9)


def test_shared_game_mmr_alone_only_bounds_regret_by_one():
    result = solve_mmr(paper_game("shared"))
    assert result.value == pytest.approx(1.0, abs=1e-9)
    assert set(np.flatnonzero(result.adversary > 1e-7)) == {4, 5}
    assert result.regret.max() == pytest.approx(1.0, abs=1e-9)


def test_distinct_game_has_zero_regret_in_one_round():
    result = solve_blp(paper_game("distinct"))
    assert result.mmr_value == pytest.approx(0.0, abs=1e-9)
    assert len(result.rounds) == 1
    assert set(result.rounds[0].support) == set(NAMES)
    assert result.regret == pytest.approx(np.zeros(6), abs=1e-9)


def test_adversary_support_is_maximal_with_duplicate_levels():
    """A vertex dual would name only one of two identical levels."""
    game = OneStepGame(("A", "B"), ("x", "y", "y2"), ("h", "h", "h"),
                       np.array([[1.0, -1.0], [-1.0, 1.0], [-1.0, 1.0]]))
    result = solve_mmr(game)
    assert result.value == pytest.approx(1.0)
    assert np.all(result.adversary > 1e-3)
    assert result.adversary.sum() == pytest.approx(1.0)


# ---------------------------------------------------------------- uniqueness of the BLP policy


def ambiguous_game() -> OneStepGame:
    """Round 1 fixes P(a1) = 0.5 on the first two levels; any split of the rest between a2 and a3
    is optimal, and the third level's regret is 0.2 - 0.2 P(a3)."""
    return OneStepGame(("a1", "a2", "a3"), ("x", "y", "z"), ("o", "o", "o"),
                       np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.2]]))


def test_blp_policy_need_not_be_unique():
    game = ambiguous_game()
    result = solve_blp(game)
    assert [r.value for r in result.rounds] == pytest.approx([0.5, result.regret[2]])
    assert [set(r.support) for r in result.rounds] == [{"x", "y"}, {"z"}]
    assert [r.unique for r in result.rounds] == [False, True]
    # two round-1-optimal policies that end with different regret on z
    for policy, z_regret in (([0.5, 0.5, 0.0], 0.2), ([0.5, 0.0, 0.5], 0.1)):
        regret = direct_regret(game, {"o": np.array(policy)})
        assert regret[:2].max() == pytest.approx(result.rounds[0].value)
        assert regret[2] == pytest.approx(z_regret)
    assert 0.1 - 1e-9 <= result.regret[2] <= 0.2 + 1e-9


def test_blp_policy_of_the_shared_game_is_unique():
    assert [r.unique for r in solve_blp(paper_game("shared")).rounds] == [True, True]
    assert [r.unique for r in solve_blp(paper_game("distinct")).rounds] == [True]


# ---------------------------------------------------------------- brute force


@pytest.mark.parametrize("seed", range(25))
def test_mmr_matches_brute_force(seed):
    game = random_game(np.random.default_rng(seed))
    result = solve_mmr(game)
    regret = regret_matrix(game)
    value = matrix_game_value(regret)
    assert result.value == pytest.approx(value, abs=1e-7)
    achieved = direct_regret(game, policy_rows(game, result.policy))
    assert achieved.max() == pytest.approx(value, abs=1e-7)
    assert result.regret == pytest.approx(achieved, abs=1e-9)
    assert result.optimal_return == pytest.approx(game.rewards.max(axis=1))
    # the adversary is an equilibrium: no deterministic policy does better against it
    assert result.adversary.sum() == pytest.approx(1.0)
    assert (regret @ result.adversary).min() == pytest.approx(value, abs=1e-7)
    support = set(np.flatnonzero(result.adversary > 1e-7))
    assert achieved[list(support)] == pytest.approx(value, abs=1e-7)
    assert support == maximal_support(regret, value)


@pytest.mark.parametrize("seed", range(25))
def test_blp_rounds_match_brute_force_and_invariants(seed):
    game = random_game(np.random.default_rng(100 + seed))
    result = solve_blp(game)
    rows = policy_rows(game, result.policy)
    final = direct_regret(game, rows)
    assert result.regret == pytest.approx(final, abs=1e-9)
    covered: set[str] = set()
    for i, rnd in enumerate(result.rounds):
        # each round's value is the brute-force value of the refined game set by earlier rounds
        fixed_obs = {o for n, o in zip(game.level_names, game.observations) if n in covered}
        prev = policy_rows(game, result.rounds[i - 1].policy) if i else {}
        active = [k for k, n in enumerate(game.level_names) if n not in covered]
        regret = regret_matrix(game, {o: prev[o] for o in fixed_obs})[:, active]
        assert rnd.value == pytest.approx(matrix_game_value(regret), abs=1e-7)
        support = {active[k] for k in maximal_support(regret, rnd.value)}
        assert {game.level_names[k] for k in support} == set(rnd.support)
        assert not covered & set(rnd.support)
        covered |= set(rnd.support)
        # the final policy agrees with this round's policy on its realisable observations, so
        # regret on the levels covered so far is unchanged by later rounds
        round_rows = policy_rows(game, rnd.policy)
        realisable = {o for n, o in zip(game.level_names, game.observations) if n in covered}
        for o in realisable:
            assert rows[o] == pytest.approx(round_rows[o], abs=1e-7)
        idx = [k for k, n in enumerate(game.level_names) if n in rnd.support]
        assert final[idx] == pytest.approx(rnd.value, abs=1e-7)
        if i:
            assert rnd.value <= result.rounds[i - 1].value + 1e-9
    assert covered == set(game.level_names)


def continuous_game(seed: int) -> OneStepGame:
    """Uniform rewards (no ties): 12 levels over 3 observations and 3 actions."""
    rng = np.random.default_rng(seed)
    return OneStepGame(("a0", "a1", "a2"), tuple(f"l{i}" for i in range(12)),
                       tuple(f"o{rng.integers(3)}" for _ in range(12)), rng.random((12, 3)))


@pytest.mark.parametrize("seed", range(6))
def test_blp_rounds_of_continuous_games_match_brute_force(seed):
    game = continuous_game(seed)
    result = solve_blp(game)
    covered: set[str] = set()
    for rnd in result.rounds:
        fixed = {o for n, o in zip(game.level_names, game.observations) if n in covered}
        active = [k for k, n in enumerate(game.level_names) if n not in covered]
        regret = regret_matrix(game, {o: policy_rows(game, result.policy)[o] for o in fixed})[:, active]
        assert rnd.value == pytest.approx(matrix_game_value(regret), abs=1e-7)
        assert {game.level_names[active[k]] for k in maximal_support(regret, rnd.value)} == set(rnd.support)
        assert sum(rnd.adversary.values()) == pytest.approx(1.0)
        covered |= set(rnd.support)
    assert covered == set(game.level_names)


def test_observations_whose_values_differ_by_little_are_separate_rounds():
    """Observation games with values 0.5 and c/(1+c) = 0.5 - 2.5e-5: two rounds. (A support test
    on adversary probabilities merges them: 2.5e-5 of value buys the adversary ~1e-6 of mass.)"""
    c = 1.0 - 1e-4
    game = OneStepGame(("a", "b"), ("x1", "x2", "y1", "y2"), ("x", "x", "y", "y"),
                       np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0], [0.0, c]]))
    result = solve_blp(game)
    assert [r.value for r in result.rounds] == pytest.approx([0.5, c / (1 + c)], abs=1e-12)
    assert [set(r.support) for r in result.rounds] == [{"x1", "x2"}, {"y1", "y2"}]
    assert result.policy[1, 0] == pytest.approx(1 / (1 + c), abs=1e-9)
    assert set(np.flatnonzero(solve_mmr(game).adversary > 0)) == {0, 1}
