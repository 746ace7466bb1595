"""The dark room (remidi.envs.darkroom): moves, ends and rewards by hand, dark levels that play
alike whatever their goal, the optimum against a breadth-first search, and the task's checks."""

from collections import deque

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.run.task_checks import validate_task
from remidi.envs.darkroom import DarkroomLevel, darkroom_task, goal_cells

TASK = darkroom_task(5, 12)
ENV, PARAMS = TASK.env, TASK.params
UP, RIGHT, DOWN, LEFT = 0, 1, 2, 3
KEY = jax.random.PRNGKey(0)


def level(start, goal, lit=True):
    return DarkroomLevel(start=jnp.int32(start), goal=jnp.int32(goal), lit=jnp.asarray(lit))


def play(lvl, actions):
    """[(obs, reward, done)] of each step of ``actions`` from the level's start."""
    obs, state = ENV.reset_to_level(KEY, lvl, PARAMS)
    out = []
    for a in actions:
        obs, state, reward, done, _ = ENV.step_env(KEY, state, jnp.int32(a), PARAMS)
        out.append((np.asarray(obs), float(reward), bool(done)))
    return out


def test_goal_cells_are_the_non_corner_border():
    assert sorted(goal_cells(5, 12).tolist()) == [1, 2, 3, 5, 9, 10, 14, 15, 19, 21, 22, 23]
    assert goal_cells(5, 4).tolist() == [1, 9, 23, 15]  # every third, clockwise from the top-left


def test_reaching_the_goal_pays_and_ends():
    goal = int(np.flatnonzero(ENV.goals == 2)[0])  # cell (0, 2)
    steps = play(level(12, goal), [UP, UP])  # from the centre (2, 2)
    assert [d for _, _, d in steps] == [False, True]
    assert steps[0][1] == 0.0
    assert steps[1][1] == pytest.approx(1 - 0.9 * 2 / 15)
    assert float(TASK.optimal_return(level(12, goal))) == pytest.approx(1 - 0.9 * 2 / 15)
    assert float(TASK.optimal_discounted_return(level(12, goal), 0.9)) == pytest.approx(0.9 * (1 - 0.9 * 2 / 15))


def test_a_wrong_goal_ends_with_nothing_and_time_runs_out():
    goal = int(np.flatnonzero(ENV.goals == 2)[0])
    steps = play(level(6, goal), [UP])  # (1, 1) -> (0, 1): another candidate
    assert steps[0][1:] == (0.0, True)
    steps = play(level(6, goal), [LEFT, LEFT])  # (1, 0) is a candidate too: ends at the first move
    assert steps[0][2]
    steps = play(level(6, goal), [RIGHT] + [DOWN, UP] * 7)
    assert [d for _, _, d in steps] == [False] * 14 + [True] and steps[-1][1] == 0.0  # time out


def test_dark_levels_with_one_start_play_alike_lit_ones_show_the_goal():
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 4, 15).tolist()
    a, b = play(level(12, 0, lit=False), actions), play(level(12, 7, lit=False), actions)
    for (oa, _, da), (ob, _, db) in zip(a, b):
        np.testing.assert_array_equal(oa, ob)
        assert da == db
    obs, _ = ENV.reset_to_level(KEY, level(12, 7), PARAMS)
    assert obs.shape == (25 + 13,) and float(obs[12]) == 1.0 and float(obs[25 + 8]) == 1.0
    dark, _ = ENV.reset_to_level(KEY, level(12, 7, lit=False), PARAMS)
    assert float(dark[25]) == 1.0 and float(dark[26:].sum()) == 0.0


def _bfs_distance(start, goal_cell, size=5):
    goals = set(ENV.goals.tolist())
    seen, queue = {start}, deque([(start, 0)])
    while queue:
        cell, d = queue.popleft()
        if cell == goal_cell:
            return d
        if cell in goals:
            continue  # a candidate ends the episode
        r, c = divmod(cell, size)
        for dr, dc in ((-1, 0), (0, 1), (1, 0), (0, -1)):
            rr, cc = min(max(r + dr, 0), size - 1), min(max(c + dc, 0), size - 1)
            if rr * size + cc not in seen:
                seen.add(rr * size + cc)
                queue.append((rr * size + cc, d + 1))


def test_optimal_return_is_the_shortest_path():
    levels = TASK.eval_sets["lit"]
    optimal = np.asarray(jax.vmap(TASK.optimal_return)(levels))
    for i in range(len(optimal)):
        d = _bfs_distance(int(levels.start[i]), int(ENV.goals[int(levels.goal[i])]))
        assert optimal[i] == pytest.approx(1 - 0.9 * d / 15)


def test_task_sets_tags_and_checks():
    validate_task(TASK)
    assert {k: int(v.start.shape[0]) for k, v in TASK.eval_sets.items()} == {"lit": 108, "dark": 108}
    assert bool(jnp.all(TASK.eval_sets["lit"].lit)) and not bool(jnp.any(TASK.eval_sets["dark"].lit))
    assert bool(TASK.level_tags(level(12, 0, lit=False))["dark"]) and not bool(TASK.level_tags(level(12, 0))["dark"])
    levels = jax.vmap(TASK.sample_level)(jax.random.split(KEY, 2000))
    assert set(np.unique(levels.start).tolist()) == set(ENV.starts.tolist())
    assert 0.45 < float(jnp.mean(levels.lit)) < 0.55
    edited = TASK.mutate_level(KEY, level(12, 11, lit=False), 5)
    assert int(edited.start) == 12 and not bool(edited.lit) and 0 <= int(edited.goal) < 12
