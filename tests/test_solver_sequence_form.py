"""Exact multi-step (sequence-form) solvers: lottery game, agreement with the one-step solver,
brute force over deterministic policies on random trees, BLP invariants.

The reference code here walks the trees itself (information sets, returns, reachability) and
solves the normal-form regret game with its own LP; it shares nothing with the solver but the
game data types.
"""

import itertools
from pathlib import Path

import numpy as np
import pytest

from matrix_game import matrix_game_value, maximal_support
from remidi.solvers import onestep
from remidi.solvers.gamefile import load_game
from remidi.solvers.sequence_form import (
    Chance, Decision, Terminal, TreeGame, build_sequence_form, local_mmr_policy,
    one_step_to_tree, policy_regret, policy_return, solve_blp, solve_mmr,
)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


# ---------------------------------------------------------------- independent reference code


def infosets(game: TreeGame) -> dict[tuple, tuple[str, ...]]:
    """{AOH: available actions} over all decision nodes of all levels."""
    found: dict[tuple, tuple[str, ...]] = {}

    def walk(node, aoh):
        if isinstance(node, Chance):
            for _, child in node.outcomes:
                walk(child, aoh)
        elif isinstance(node, Decision):
            key = aoh + (node.observation,)
            found[key] = tuple(node.children)
            for a, child in node.children.items():
                walk(child, key + (a,))

    for tree in game.trees:
        walk(tree, ())
    return found


def expected_return(node, aoh, policy) -> float:
    """Return of a subtree when the agent plays ``policy`` {AOH: {action: prob}}."""
    if isinstance(node, Terminal):
        return node.reward
    if isinstance(node, Chance):
        return sum(p * expected_return(c, aoh, policy) for p, c in node.outcomes)
    key = aoh + (node.observation,)
    return sum(p * expected_return(node.children[a], key + (a,), policy)
               for a, p in policy.get(key, {}).items() if p > 0)


def reached(node, aoh, policy, prob=1.0, out=None) -> set:
    """AOHs reached with positive probability under ``policy``."""
    out = set() if out is None else out
    if prob <= 1e-9 or isinstance(node, Terminal):
        return out
    if isinstance(node, Chance):
        for p, child in node.outcomes:
            reached(child, aoh, policy, prob * p, out)
        return out
    key = aoh + (node.observation,)
    out.add(key)
    for a, p in policy[key].items():
        reached(node.children[a], key + (a,), policy, prob * p, out)
    return out


def deterministic_policies(game: TreeGame, fixed=None):
    """Every policy that is deterministic outside ``fixed`` {AOH: {action: prob}}."""
    fixed = fixed or {}
    sets = infosets(game)
    keys = [k for k in sets if k not in fixed]
    for choice in itertools.product(*(sets[k] for k in keys)):
        yield {**fixed, **{k: {a: 1.0} for k, a in zip(keys, choice)}}


def returns(game: TreeGame, policy) -> np.ndarray:
    return np.array([expected_return(t, (), policy) for t in game.trees])


def random_node(rng, depth: int):
    """Decision -> (terminal | chance over decisions) trees over observations {x, y}."""
    if depth == 0 or rng.random() < 0.25:
        return Terminal(float(rng.integers(-3, 4)))
    if depth == 1 and rng.random() < 0.5:
        p = float(rng.choice([0.2, 0.5, 0.7]))
        return Chance(((p, random_node(rng, depth)), (round(1 - p, 10), random_node(rng, depth))))
    return Decision(str(rng.choice(["x", "y"])),
                    {a: random_node(rng, depth - 1) for a in ("a", "b")})


def random_game(seed: int) -> TreeGame:
    """A random 2-action tree game with a shared first observation and at most 6 information
    sets (64 deterministic policies)."""
    rng = np.random.default_rng(seed)
    while True:
        n_levels = int(rng.integers(2, 6))
        trees = tuple(Decision("s", {a: random_node(rng, 1) for a in ("a", "b")})
                      for _ in range(n_levels))
        game = TreeGame(("a", "b"), tuple(f"l{i}" for i in range(n_levels)), trees)
        if len(infosets(game)) <= 6:
            return game


def lottery() -> TreeGame:
    game = load_game(str(EXAMPLES / "lottery.json"))
    assert isinstance(game, TreeGame)
    return game


# ---------------------------------------------------------------- lottery (paper appendix)


def test_lottery_global_mmr_is_an_equilibrium_with_regret_two():
    game = lottery()
    table = np.array([returns(game, p) for p in deterministic_policies(game)])  # [P, L]
    optimal = table.max(axis=0)
    regret = optimal - table
    assert matrix_game_value(regret) == pytest.approx(2.0, abs=1e-9)  # the game's MMR value
    result = solve_mmr(game)
    assert result.value == pytest.approx(2.0, abs=1e-9)
    assert result.optimal_return == pytest.approx(optimal)
    achieved = optimal - returns(game, result.policy)
    assert result.regret == pytest.approx(achieved, abs=1e-9)
    assert achieved.max() == pytest.approx(2.0, abs=1e-9)  # worst case = the value: MMR
    # the adversary is an equilibrium one: no policy has expected regret below 2 against it
    assert result.adversary.sum() == pytest.approx(1.0)
    assert (regret @ result.adversary).min() == pytest.approx(2.0, abs=1e-7)
    # Regret is 200 - 198 p - 2 q on thetaA and 2 p + 198 q on thetaB (p = P(a1 | sA),
    # q = P(a1 | sB)), so the MMR policy p = 1, q = 0 is unique, while every adversary with
    # P(thetaA) in [0.01, 0.99] is an equilibrium one.
    assert result.policy[("s0", "a1", "sA")]["a1"] == pytest.approx(1.0)
    assert result.policy[("s0", "a1", "sB")]["a2"] == pytest.approx(1.0)
    assert 0.01 - 1e-9 <= result.adversary[0] <= 0.99 + 1e-9


def test_lottery_local_mmr_has_worst_case_regret_100():
    game = lottery()
    policy = local_mmr_policy(game)
    assert policy[("s0", "a1", "sA")] == pytest.approx({"a1": 0.5, "a2": 0.5})
    assert policy[("s0", "a1", "sB")] == pytest.approx({"a1": 0.5, "a2": 0.5})
    assert policy_regret(game, policy).max() == pytest.approx(100.0)
    assert (100.0 - returns(game, policy)).max() == pytest.approx(100.0)


def test_lottery_blp_is_a_single_round():
    result = solve_blp(lottery())
    assert [r.value for r in result.rounds] == pytest.approx([2.0])
    assert set(result.rounds[0].support) == {"thetaA", "thetaB"}
    assert result.rounds[0].unique  # P(a1 | sA) = 1, P(a1 | sB) = 0 is the only MMR policy


def test_uniqueness_is_checked_on_trees_too():
    game = one_step_to_tree(onestep.OneStepGame(
        ("a1", "a2", "a3"), ("x", "y", "z"), ("o", "o", "o"),
        np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.2]])))
    assert [r.unique for r in solve_blp(game).rounds] == [False, True]


# ---------------------------------------------------------------- one-step games as trees


def paper_onestep(setting: str) -> onestep.OneStepGame:
    rewards = np.array([(-0.1, 0.1), (0.7, -0.7), (-0.7, 0.7), (0.1, -0.1), (-1, 1), (1, -1)])
    obs = ("h1", "h1", "h3", "h3", "h5", "h5") if setting == "shared" else tuple(
        f"h{i}" for i in range(1, 7))
    return onestep.OneStepGame(("A", "B"), tuple(f"theta{i}" for i in range(1, 7)), obs, rewards)


def random_onestep(seed: int) -> onestep.OneStepGame:
    rng = np.random.default_rng(seed)
    n_levels, n_obs = int(rng.integers(2, 7)), int(rng.integers(1, 4))
    return onestep.OneStepGame(
        ("a0", "a1", "a2"), tuple(f"l{i}" for i in range(n_levels)),
        tuple(f"o{rng.integers(n_obs)}" for _ in range(n_levels)),
        rng.integers(-3, 4, size=(n_levels, 3)).astype(float))


@pytest.mark.parametrize("game", [paper_onestep("shared"), paper_onestep("distinct")]
                         + [random_onestep(s) for s in range(10)])
def test_tree_solver_agrees_with_onestep_solver(game):
    tree = one_step_to_tree(game)
    flat_mmr, tree_mmr = onestep.solve_mmr(game), solve_mmr(tree)
    assert tree_mmr.value == pytest.approx(flat_mmr.value, abs=1e-9)
    # equilibrium adversaries need not be unique (the solvers mix theirs differently); their
    # maximal supports are
    assert set(np.flatnonzero(tree_mmr.adversary > 1e-7)) == set(np.flatnonzero(flat_mmr.adversary > 1e-7))
    flat, deep = onestep.solve_blp(game), solve_blp(tree)
    assert [r.value for r in deep.rounds] == pytest.approx([r.value for r in flat.rounds], abs=1e-9)
    assert [r.support for r in deep.rounds] == [r.support for r in flat.rounds]
    if all(r.unique for r in flat.rounds):  # else each may have frozen another optimal policy
        assert deep.regret == pytest.approx(flat.regret, abs=1e-7)


def test_tree_blp_reproduces_shared_paper_values():
    result = solve_blp(one_step_to_tree(paper_onestep("shared")))
    assert [r.value for r in result.rounds] == pytest.approx([1.0, 0.175])
    assert result.regret == pytest.approx([0.175] * 4 + [1.0] * 2)
    assert result.policy[("h1",)]["A"] == pytest.approx(0.875)


# ---------------------------------------------------------------- brute force on random trees


@pytest.mark.parametrize("seed", range(25))
def test_tree_mmr_matches_brute_force(seed):
    game = random_game(seed)
    table = np.array([returns(game, p) for p in deterministic_policies(game)])  # [P, L]
    optimal = table.max(axis=0)
    regret = optimal - table
    value = matrix_game_value(regret)
    result = solve_mmr(game)
    assert result.optimal_return == pytest.approx(optimal, abs=1e-9)
    assert result.value == pytest.approx(value, abs=1e-7)
    achieved = optimal - returns(game, result.policy)
    assert achieved.max() == pytest.approx(value, abs=1e-7)
    assert result.regret == pytest.approx(achieved, abs=1e-7)
    assert policy_regret(game, result.policy) == pytest.approx(achieved, abs=1e-7)
    assert (regret @ result.adversary).min() == pytest.approx(value, abs=1e-7)
    support = np.flatnonzero(result.adversary > 1e-7)
    assert achieved[support] == pytest.approx(value, abs=1e-7)
    assert set(support) == maximal_support(regret, value)


@pytest.mark.parametrize("seed", range(25))
def test_tree_blp_invariants(seed):
    game = random_game(1000 + seed)
    result = solve_blp(game)
    optimal = np.array([returns(game, p) for p in deterministic_policies(game)]).max(axis=0)
    final = optimal - returns(game, result.policy)
    assert result.regret == pytest.approx(final, abs=1e-7)
    covered: set[str] = set()
    for i, rnd in enumerate(result.rounds):
        if i:
            assert rnd.value <= result.rounds[i - 1].value + 1e-9
        # brute-force value and support of the refined game set by the earlier rounds
        prev = result.rounds[i - 1].policy if i else {}
        fixed = {aoh: prev[aoh] for k, n in enumerate(game.level_names) if n in covered
                 for aoh in reached(game.trees[k], (), prev)}
        active = [k for k, n in enumerate(game.level_names) if n not in covered]
        regret = np.array([optimal - returns(game, p)
                           for p in deterministic_policies(game, fixed)])[:, active]
        assert rnd.value == pytest.approx(matrix_game_value(regret), abs=1e-7)
        support = {game.level_names[active[k]] for k in maximal_support(regret, rnd.value)}
        assert support == set(rnd.support)
        assert not covered & set(rnd.support)
        covered |= set(rnd.support)
        idx = [k for k, n in enumerate(game.level_names) if n in covered]
        # the final policy acts like this round's on everything realisable on covered levels ...
        for k in idx:
            for aoh in reached(game.trees[k], (), rnd.policy):
                assert result.policy[aoh] == pytest.approx(rnd.policy[aoh], abs=1e-7)
        # ... so the regret on covered levels never changes again
        assert final[idx] == pytest.approx(rnd.regret[idx], abs=1e-7)
        own = [k for k, n in enumerate(game.level_names) if n in rnd.support]
        assert final[own] == pytest.approx(rnd.value, abs=1e-7)
    assert covered == set(game.level_names)
    assert result.mmr_value == pytest.approx(result.rounds[0].value)


def test_information_sets_span_levels_and_chance_outcomes():
    """Same AOH in two levels and behind two chance outcomes is one information set."""
    leaf = {"a": Terminal(1.0), "b": Terminal(0.0)}
    flip = {"a": Terminal(0.0), "b": Terminal(1.0)}
    game = TreeGame(("a", "b"), ("p", "q"), (
        Chance(((0.5, Decision("o", leaf)), (0.5, Decision("o", flip)))),
        Decision("o", flip),
    ))
    form = build_sequence_form(game)
    assert form.infosets == (("o",),)
    assert form.reach == pytest.approx(np.array([[1.0], [1.0]]))
    result = solve_mmr(game)
    # level p pays 0.5 whatever the agent does, so its regret is 0; q wants b
    assert result.value == pytest.approx(0.0, abs=1e-9)
    assert policy_return(game, result.policy) == pytest.approx([0.5, 1.0])


def test_inconsistent_action_sets_are_rejected():
    game = TreeGame(("a", "b"), ("p", "q"), (
        Decision("o", {"a": Terminal(1.0), "b": Terminal(0.0)}),
        Decision("o", {"a": Terminal(1.0)}),
    ))
    with pytest.raises(ValueError, match="information set 'o'"):
        build_sequence_form(game)
