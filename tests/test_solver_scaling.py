"""Exact solvers on rewards spanning many orders of magnitude: right answers or one-line refusals.

The paper's shared game with one level's rewards blown up to ±1e6 … ±1e308 (its observation game
alone changes: A is dominant there, so the answers are exact), random one-step games whose
observations (or levels) live on scales 1e-6 … 1e9 against an independent solution of each
2-action observation game (the crossing points of its levels' regret lines), and a property test
that every answer either passes a direct check written here from the rewards or is refused with
one line. Nothing here uses the solvers' LPs or checks.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from remidi.cli import main
from remidi.errors import RemidiError
from remidi.solvers import onestep, sequence_form
from remidi.solvers.gamefile import load_game
from remidi.solvers.onestep import OneStepGame
from remidi.solvers.sequence_form import Decision, Terminal, TreeGame, one_step_to_tree

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
EXTREMES = ["1e6", "1e9", "1e12", "1e15", "1e308"]


# ---------------------------------------------------------------- independent reference code


def action_regret(game: OneStepGame) -> np.ndarray:
    """[L, A] regret of each action on each level, ``max_b r_b - r_a``."""
    return game.rewards.max(axis=1, keepdims=True) - game.rewards


def two_action_mmr(rho: np.ndarray) -> tuple[float, float, float]:
    """(value, p, q) of one 2-action observation game with action regrets rho [K, 2]: p = P(action
    1) and q = 1 - p minimise ``max_l q rho[l, 0] + p rho[l, 1]``. The minimum of that convex
    piecewise-linear function is at p = 0, p = 1 or a crossing of two lines; p and q both come
    from the crossing formula, so neither loses precision near 0."""
    a, b = rho[:, 0], rho[:, 1]
    candidates = [(0.0, 1.0), (1.0, 0.0)]
    for i in range(len(a)):
        for j in range(i + 1, len(a)):
            den = (a[i] - a[j]) - (b[i] - b[j])
            if den != 0 and 0 < (a[i] - a[j]) / den < 1:
                candidates.append(((a[i] - a[j]) / den, (b[j] - b[i]) / den))
    return min(((q * a + p * b).max(), p, q) for p, q in candidates)


def reference_blp(game: OneStepGame):
    """BLP of a 2-action one-step game: rounds [(value, support [L] bool)], rows [O, 2], regret [L].

    Every observation is frozen at its own game's MMR row; a round's value is the largest value
    of a free observation game or regret of an uncovered level of a frozen one, and its support
    the levels of the tied observation games whose regret is the value, and the tied levels.
    """
    rho, idx = action_regret(game), game.observation_index()
    solved = [two_action_mmr(rho[idx == o]) for o in range(game.num_observations)]
    values = np.array([v for v, _, _ in solved])
    rows = np.array([[q, p] for _, p, q in solved])
    regret = (rows[idx] * rho).sum(axis=1)
    free, covered, rounds = np.ones(len(values), dtype=bool), np.zeros(game.num_levels, dtype=bool), []
    while not covered.all():
        constant = ~covered & ~free[idx]
        value = max(values[free].max(initial=-np.inf), regret[constant].max(initial=-np.inf))
        tied = free & (values >= value * (1 - 1e-9))
        support = (tied[idx] | constant) & (regret >= value * (1 - 1e-9))
        rounds.append((value, support))
        covered |= support
        free &= ~tied
    return rounds, rows, regret


def scaled_game(rng: np.random.Generator, per_level: bool, n_actions: int = 2) -> OneStepGame:
    """Rewards uniform in [-1, 1] times 10^U(-6, 9), the scale drawn per observation or per level."""
    n_levels, n_obs = int(rng.integers(2, 9)), int(rng.integers(1, 4))
    obs = rng.integers(n_obs, size=n_levels)
    scale = 10.0 ** rng.uniform(-6, 9, size=n_levels if per_level else n_obs)
    scale = scale if per_level else scale[obs]
    return OneStepGame(tuple(f"a{i}" for i in range(n_actions)), tuple(f"l{i}" for i in range(n_levels)),
                       tuple(f"o{o}" for o in obs), scale[:, None] * rng.uniform(-1, 1, size=(n_levels, n_actions)))


def support_sets(result) -> list[set[str]]:
    return [set(r.support) for r in result.rounds]


def assert_matches_reference(game: OneStepGame, result, rows_too: bool = True):
    """The solver's BLP rounds, regrets (and policy rows) are the reference's, to 1e-6."""
    rounds, rows, regret = reference_blp(game)
    names = np.array(game.level_names)
    assert [r.value for r in result.rounds] == pytest.approx([v for v, _ in rounds], rel=1e-6, abs=0)
    assert support_sets(result) == [set(names[s]) for _, s in rounds]
    assert result.regret == pytest.approx(regret, rel=1e-6, abs=0)
    if rows_too:
        policy = result.policy if isinstance(result.policy, np.ndarray) else np.array(
            [[result.policy[(o,)][a] for a in game.actions] for o in game.observation_names])
        assert policy == pytest.approx(rows, rel=1e-6, abs=1e-12)


def refused_in_one_line(call) -> str:
    """Run ``call``, which must raise the project's error; return its one-line message."""
    with pytest.raises(RemidiError) as info:
        call()
    message = str(info.value)
    assert message and "\n" not in message
    return message


# ---------------------------------------------------------------- the paper's game, one level blown up


def extreme_game(tmp_path: Path, reward: str) -> Path:
    """examples/tabular_shared.json with theta1's rewards set to [reward, -reward]."""
    data = json.loads((EXAMPLES / "tabular_shared.json").read_text())
    data["levels"][0]["rewards"] = [float(reward), -float(reward)]
    path = tmp_path / f"shared_{reward}.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize("reward", EXTREMES)
def test_an_extreme_observation_leaves_the_others_exact(tmp_path, reward):
    """A is dominant at h1 (zero regret on theta1 and theta2); h3 and h5 keep their answers."""
    game = load_game(str(extreme_game(tmp_path, reward)))
    result = onestep.solve_blp(game)
    assert result.mmr_value == pytest.approx(1.0, rel=1e-12)
    assert [r.value for r in result.rounds] == pytest.approx([1.0, 0.175, 0.0], rel=1e-12, abs=0)
    assert support_sets(result) == [{"theta5", "theta6"}, {"theta3", "theta4"}, {"theta1", "theta2"}]
    assert [r.adversary for r in result.rounds[:2]] == [
        pytest.approx({"theta5": 0.5, "theta6": 0.5}), pytest.approx({"theta3": 0.125, "theta4": 0.875})]
    assert [r.unique for r in result.rounds] == [True, True, True]
    assert result.policy == pytest.approx(np.array([[1.0, 0.0], [0.125, 0.875], [0.5, 0.5]]), abs=1e-12)
    assert result.regret == pytest.approx([0.0, 0.0, 0.175, 0.175, 1.0, 1.0], rel=1e-12, abs=0)
    mmr = onestep.solve_mmr(game)
    assert mmr.value == pytest.approx(1.0, rel=1e-12)
    assert set(np.flatnonzero(mmr.adversary > 0)) == {4, 5}


@pytest.mark.parametrize("reward", EXTREMES)
def test_remidi_solve_on_an_extreme_game(tmp_path, capsys, reward):
    path = extreme_game(tmp_path, reward)
    assert main(["solve", str(path), "--json"]) == 0
    out, err = capsys.readouterr()
    report = json.loads(out)
    assert report["mmr_value"] == 1.0
    assert [r["value"] for r in report["rounds"]] == [1.0, 0.175, 0.0]
    assert [r["support"] for r in report["rounds"]] == [["theta5", "theta6"], ["theta3", "theta4"],
                                                        ["theta1", "theta2"]]
    assert [r["unique"] for r in report["rounds"]] == [True, True, True]
    assert report["policy"] == {"h1": {"A": 1.0, "B": 0.0}, "h3": {"A": 0.125, "B": 0.875},
                                "h5": {"A": 0.5, "B": 0.5}}
    assert report["regret"]["theta1"] == 0.0 and report["regret"]["theta3"] == 0.175
    assert len(err.splitlines()) == 3  # one progress line per round
    assert main(["solve", str(path)]) == 0
    assert "minimax regret value: 1\n" in capsys.readouterr().out


@pytest.mark.parametrize("reward", EXTREMES)
def test_the_tree_solver_on_an_extreme_game_is_exact_or_refuses(tmp_path, reward):
    """One LP for the whole game: a regret 1e-9 of the largest is invisible to it, so from 1e9 on
    it may only refuse, in one line, never answer 2."""
    tree = one_step_to_tree(load_game(str(extreme_game(tmp_path, reward))))
    if reward == "1e6":
        result = sequence_form.solve_blp(tree)
        assert [r.value for r in result.rounds] == pytest.approx([1.0, 0.175, 0.0], rel=1e-9, abs=1e-12)
        assert result.policy[("h1",)] == pytest.approx({"A": 1.0, "B": 0.0}, abs=1e-9)
        return
    try:
        result = sequence_form.solve_blp(tree)
    except RemidiError as err:
        assert "\n" not in str(err) and "largest regrets range from" in str(err)
        return
    assert [r.value for r in result.rounds] == pytest.approx([1.0, 0.175, 0.0], rel=1e-6, abs=1e-12)


def conflicting_game() -> OneStepGame:
    """h1's levels want opposite actions, their regrets 1.4 and 2e12 apart by 1e12: its value (1.4)
    rests on a level 1e-12 of its LP's scale, which no LP sees."""
    return OneStepGame(("A", "B"), ("t1", "t2", "t3"), ("h1", "h1", "h2"),
                       np.array([[1e12, -1e12], [-0.7, 0.7], [0.3, -0.3]]))


def test_a_game_beyond_the_lps_resolution_is_refused_in_one_line(tmp_path, capsys):
    message = refused_in_one_line(lambda: onestep.solve_blp(conflicting_game()))
    assert "round 1" in message and "from 0.6 to 2e+12" in message
    game = conflicting_game()
    path = tmp_path / "conflict.json"
    path.write_text(json.dumps({"actions": list(game.actions), "levels": [
        {"name": n, "observation": o, "rewards": r.tolist()}
        for n, o, r in zip(game.level_names, game.observations, game.rewards)]}))
    assert main(["solve", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert len(err.splitlines()) == 1 and err.startswith("remidi: error: exact solver: cannot vouch")


def test_non_finite_rewards_are_refused_in_one_line():
    game = OneStepGame(("A", "B"), ("x", "y"), ("o", "o"), np.array([[1.0, np.nan], [0.0, 1.0]]))
    assert "'x'" in refused_in_one_line(lambda: onestep.solve_blp(game))
    assert "'x'" in refused_in_one_line(lambda: onestep.solve_mmr(game))
    tree = TreeGame(("a", "b"), ("p", "q"), (
        Decision("o", {"a": Terminal(0.0), "b": Terminal(1.0)}),
        Decision("o", {"a": Terminal(np.inf), "b": Terminal(1.0)}),
    ))
    assert "'q'" in refused_in_one_line(lambda: sequence_form.solve_blp(tree))


def test_the_tree_solver_centres_each_levels_rewards():
    """x pays 1e12 + (1, 0): only its regrets (1, 0) matter, and y's are as large, so the game is
    well conditioned once each level's rewards are shifted by their midpoint."""
    game = OneStepGame(("A", "B"), ("x", "y", "z"), ("o", "o", "p"),
                       np.array([[1e12 + 1.0, 1e12], [0.0, 0.6], [0.2, -0.2]]))
    result = sequence_form.solve_blp(one_step_to_tree(game))
    assert [r.value for r in result.rounds] == pytest.approx([0.375, 0.0], rel=1e-9, abs=0)
    assert result.policy[("o",)] == pytest.approx({"A": 0.625, "B": 0.375}, rel=1e-9)
    assert result.optimal_return == pytest.approx([1e12 + 1.0, 0.6, 0.2], rel=1e-15)


# ---------------------------------------------------------------- random games across scales


def test_observations_on_scales_1e_6_to_1e9_are_solved_exactly():
    """Each observation game is scaled on its own, so none may be refused."""
    rng = np.random.default_rng(0)
    for i in range(25):
        game = scaled_game(rng, per_level=False)
        assert_matches_reference(game, onestep.solve_blp(game))
        if i % 5 == 0:
            rounds, _, _ = reference_blp(game)
            assert onestep.solve_mmr(game).value == pytest.approx(rounds[0][0], rel=1e-6, abs=0)


def test_levels_on_scales_1e_6_to_1e9_are_solved_exactly_or_refused():
    """Levels of one observation 15 orders of magnitude apart: often beyond any LP (about a
    quarter of these games), but never answered wrongly."""
    rng, answered = np.random.default_rng(10), 0
    for _ in range(40):
        game = scaled_game(rng, per_level=True)
        try:
            result = onestep.solve_blp(game)
        except RemidiError as err:
            assert "\n" not in str(err)
            continue
        assert_matches_reference(game, result)
        answered += 1
    assert answered >= 20


def test_the_tree_solver_is_exact_or_refuses_across_scales():
    """One LP per round for the whole game: observations 15 orders of magnitude apart are often
    beyond it, but it never answers wrongly."""
    rng, answered = np.random.default_rng(20), 0
    for _ in range(16):
        game = scaled_game(rng, per_level=False)
        try:
            result = sequence_form.solve_blp(one_step_to_tree(game))
        except RemidiError as err:
            assert "\n" not in str(err)
            continue
        assert_matches_reference(game, result, rows_too=False)
        answered += 1
    assert answered >= 8


# ---------------------------------------------------------------- every answer passes a direct check


def check_directly(game: OneStepGame, result) -> None:
    """The BLP answer's claims, from the rewards alone: each round's value is the policy's worst
    regret on the levels still available, its support's regret is the value, its adversary is a
    distribution no allowed policy beats by more than the tolerances, values never rise, and the
    rounds cover every level once. 2-action games: the values are the reference's."""
    rho = action_regret(game)
    idx = game.observation_index()
    regret = (result.policy[idx] * rho).sum(axis=1)
    obs_scale = np.array([rho[idx == o].max() for o in range(game.num_observations)])[idx]
    names = np.array(game.level_names)
    assert result.regret == pytest.approx(regret, rel=1e-9, abs=0)
    covered = np.zeros(game.num_levels, dtype=bool)
    previous = np.inf
    for rnd in result.rounds:
        tol = 1e-6 * rnd.value + 1e-15 * rho.max()
        active, support = ~covered, np.isin(names, rnd.support)
        assert not (support & covered).any()
        assert regret[active].max() == pytest.approx(rnd.value, rel=1e-6, abs=1e-15 * rho.max())
        assert regret[support] == pytest.approx(rnd.value, rel=1e-6, abs=1e-15 * rho.max())
        adversary = np.array([rnd.adversary.get(n, 0.0) for n in names])
        assert adversary.sum() == pytest.approx(1.0) and (adversary[support] > 0).all()
        frozen = np.zeros(game.num_observations, dtype=bool)
        frozen[idx[covered]] = True
        # the least expected regret against the adversary: frozen rows as played, free rows at
        # their best action
        guarantee = (adversary * regret)[frozen[idx]].sum() + sum(
            (adversary[idx == o] @ rho[idx == o]).min() for o in np.flatnonzero(~frozen))
        assert guarantee >= rnd.value - tol - 1e-9 * adversary @ obs_scale
        assert rnd.value <= previous + tol
        previous = rnd.value
        covered |= support
    assert covered.all()
    if game.num_actions == 2:
        rounds, _, _ = reference_blp(game)
        assert [r.value for r in result.rounds] == pytest.approx([v for v, _ in rounds], rel=1e-6, abs=0)


@st.composite
def games(draw) -> OneStepGame:
    """1-6 levels over 1-3 observations and 2-3 actions; integer rewards in [-3, 3] (ties and
    dominated actions are common) times 10^k per level, k in [-6, 12]."""
    n_levels = draw(st.integers(1, 6))
    n_actions = draw(st.integers(2, 3))
    obs = draw(st.lists(st.integers(0, 2), min_size=n_levels, max_size=n_levels))
    power = draw(st.lists(st.integers(-6, 12), min_size=n_levels, max_size=n_levels))
    ints = draw(st.lists(st.lists(st.integers(-3, 3), min_size=n_actions, max_size=n_actions),
                         min_size=n_levels, max_size=n_levels))
    rewards = np.array(ints, dtype=float) * 10.0 ** np.array(power, dtype=float)[:, None]
    return OneStepGame(tuple(f"a{i}" for i in range(n_actions)), tuple(f"l{i}" for i in range(n_levels)),
                       tuple(f"o{o}" for o in obs), rewards)


@settings(max_examples=50, deadline=None, database=None, derandomize=True)
@given(games())
def test_every_answer_passes_a_direct_check_or_is_refused(game):
    try:
        result = onestep.solve_blp(game)
    except RemidiError as err:
        assert "\n" not in str(err)
        return
    check_directly(game, result)
