"""Level-building MDPs (the environment of a learned level generator): every level the task's
sampler produces can be built action by action; invalid placements change nothing; the budget
ends the episode; the generator's noise is not zero."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.envs import maze as M
from remidi.envs.lever import LeverLevel, lever_task

KEY = jax.random.PRNGKey(0)


def fields_equal(a, b):
    return jax.tree.map(lambda x, y: np.array_equal(np.asarray(x), np.asarray(y)), a, b)


def maze_actions(builder: M.MazeBuilder, level: M.MazeLevel) -> np.ndarray:
    """The design actions that build ``level`` (an ordinary, blind or T-maze level)."""
    size = builder.size
    cell = lambda pos: int(pos[1]) * size + int(pos[0])  # noqa: E731
    kind = [int(bool(level.tmaze) or bool(level.blind))] * builder.kind_steps
    walls = [int(i) for i in np.flatnonzero(np.asarray(level.wall_map).reshape(-1))]
    if bool(level.tmaze):
        walls = []
    walls = (walls + [walls[0] if walls else 0] * builder.num_walls)[:builder.num_walls]  # repeats change nothing
    return np.array(kind + [cell(level.goal_pos), cell(level.agent_pos), int(level.agent_dir)] + walls, np.int32)


@pytest.mark.parametrize("kind", ["tmaze", "blindfold", "maze"])
def test_every_level_the_sampler_produces_can_be_built(kind):
    task = M.maze_task(kind)
    builder = task.level_builder
    keys = jax.random.split(jax.random.PRNGKey(1), 24)
    levels = jax.jit(jax.vmap(task.sample_level))(keys)
    build = jax.jit(builder.build)
    kinds = set()
    for i in range(24):
        level = jax.tree.map(lambda x: x[i], levels)
        assert int(np.asarray(level.wall_map).sum()) <= builder.num_walls or bool(level.tmaze)
        # a T-maze's never-seen cells come from the episode's key: the key the sampler drew them with
        k_t = jax.random.split(keys[i], 3)[2]
        built = build(k_t, jnp.asarray(maze_actions(builder, level)))
        same = fields_equal(built, level)
        assert all(jax.tree.leaves(same)), (kind, i, same)
        kinds.add((bool(level.tmaze), bool(level.blind)))
    if kind != "maze":
        assert len(kinds) == 2  # both kinds were built


def test_the_lever_builder_builds_every_level_in_one_step():
    task = lever_task(64)
    builder = task.level_builder
    for correct, visible in ((0, True), (63, True), (5, False), (63, False)):
        action = correct + (0 if visible else 64)
        built = builder.build(KEY, jnp.array([action]))
        assert int(built.correct) == correct and bool(built.visible) == visible
    assert builder.num_steps == 1 and builder.num_actions == 128


def test_invalid_placements_change_nothing():
    b = M.MazeBuilder("tmaze")
    d = b.empty(KEY)
    assert bool(b.place(d, 0, 5).special)  # the kind is the action mod 2: 5 a T-maze
    d = b.place(d, 0, 6)
    assert not bool(d.special)
    d = b.place(d, 1, 20)  # goal on cell 20
    d2 = b.place(d, 2, 20)  # the agent on the goal: nothing
    assert int(d2.agent) == -1
    d = b.place(d, 2, 21)  # the agent on cell 21
    assert int(b.place(d, 3, 9).agent_dir) == 1  # the direction is the action mod 4
    d = b.place(d, 3, 2)
    for t, cell in ((4, 20), (5, 21)):  # walls on the goal and the agent: nothing
        assert not np.asarray(b.place(d, t, cell).wall_map).any()
    d = b.place(d, 4, 30)
    again = b.place(d, 5, 30)  # a wall on a wall: nothing
    assert all(jax.tree.leaves(fields_equal(again, d)))
    lever = lever_task(64).level_builder
    start = lever.empty(KEY)
    assert all(jax.tree.leaves(fields_equal(lever.place(start, 0, jnp.asarray(128)), start)))
    assert isinstance(start, LeverLevel)


def test_the_budget_ends_the_episode_and_the_noise_is_not_zero():
    b = M.maze_task("tmaze").level_builder
    assert b.num_steps == 1 + 3 + 25
    obs, state = b.reset_to_level(KEY, None, None)
    assert obs["noise"].shape == (b.noise_dim,) and float(jnp.abs(obs["noise"]).sum()) > 0
    other, _ = b.reset_to_level(jax.random.PRNGKey(1), None, None)
    assert not np.array_equal(obs["noise"], other["noise"])
    assert obs["design"].shape == (13, 13, 4) and obs["time"].shape == (b.num_steps,)
    dones = []
    for t in range(b.num_steps):
        obs, state, reward, done, _ = b.step(KEY, state, jnp.asarray(t), None)
        dones.append(bool(done))
        assert float(reward) == 0.0
    assert dones == [False] * (b.num_steps - 1) + [True]


def test_the_brax_builder_builds_type_a_on_a_grid_and_both_type_b_signs():
    from remidi.envs.brax import BraxBuilder

    b = BraxBuilder(num_dims=3, theta_low=0.5, theta_high=1.5, bins=11)
    assert b.num_steps == 4 and b.num_actions == 11
    a = b.build(KEY, jnp.array([0, 0, 5, 10]))
    np.testing.assert_allclose(a.theta, [0.5, 1.0, 1.5], rtol=1e-6)
    assert not bool(a.type_b)
    for action, sign in ((1, True), (2, False)):
        lv = b.build(KEY, jnp.array([action, 0, 0, 0]))  # a type B level's θ stays canonical
        assert bool(lv.type_b) and bool(lv.sign) == sign
        np.testing.assert_array_equal(lv.theta, 1.0)
    kept = b.build(KEY, jnp.array([6, 3, 11, 10]))  # kind 6 mod 3 = type A; bin 11 changes nothing
    assert not bool(kept.type_b)
    np.testing.assert_allclose(kept.theta, [0.8, 1.0, 1.5], rtol=1e-6)
