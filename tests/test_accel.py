"""ACCEL and ReMiDi over ACCEL: the level editors keep levels valid and change only what an edit
may; an update after a replay edits that replay's levels, scores them and inserts them without
training; ReMiDi over ACCEL rejects edited levels a frozen buffer explains."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.adversaries import level_buffer as buf
from remidi.engine import train as tr
from remidi.engine.run.validation import validate_ued_config
from remidi.envs.brax import BraxLevel, BraxUED, seed_data
from remidi.envs.maze import maze_task, mutate_maze
from remidi.envs.maze_levels import _tmaze_layout
from remidi.errors import ConfigError
from test_ued_engine import TASK, TINY

R = dataclasses.replace
EDITS = 3


# ---------------------------------------------------------------------------------- editors
@pytest.fixture(scope="module")
def maze_edits():
    """60 generated T-maze task levels and their edits (3 edits each)."""
    task = maze_task("tmaze")
    keys = jax.random.split(jax.random.PRNGKey(0), 60)
    levels = jax.jit(jax.vmap(task.sample_level))(keys)
    edited = jax.jit(jax.vmap(lambda k, lv: mutate_maze(k, lv, EDITS)))(jax.random.split(jax.random.PRNGKey(1), 60),
                                                                         levels)
    return jax.device_get(levels), jax.device_get(edited)


def test_a_maze_edit_changes_at_most_num_edits_cells_and_keeps_the_goal_placeable(maze_edits):
    levels, edited = maze_edits
    changed = (levels.wall_map != edited.wall_map).reshape(60, -1).sum(axis=1)
    assert changed.max() <= EDITS and changed.sum() > 0
    np.testing.assert_array_equal(edited.agent_pos, levels.agent_pos)  # the agent never moves
    np.testing.assert_array_equal(edited.agent_dir, levels.agent_dir)
    for i in range(60):
        gx, gy = edited.goal_pos[i]
        assert not edited.wall_map[i, gy, gx]  # the goal stands on a free cell ...
        assert (gx, gy) != tuple(edited.agent_pos[i])  # ... not the agent's
    ordinary = ~levels.tmaze
    assert np.any((edited.goal_pos != levels.goal_pos).any(axis=1) & ordinary)  # goals do move


def test_a_maze_edit_is_a_no_op_a_wall_flip_or_a_goal_move_with_equal_odds():
    """minimax's and jaxued's maze editor (``move_goal_flip_walls``): each edit draws one of
    NO_OP, FLIP_WALL and MOVE_GOAL uniformly, so one edit leaves a third of the levels as they
    were (and num_edits=5 makes 3.3 real edits on average). A flip or a goal move always changes
    the level (never the agent's or the goal's own cell)."""
    task = maze_task("maze")
    keys = jax.random.split(jax.random.PRNGKey(0), 600)
    levels = jax.jit(jax.vmap(task.sample_level))(keys)
    edited = jax.jit(jax.vmap(lambda k, lv: mutate_maze(k, lv, 1)))(jax.random.split(jax.random.PRNGKey(1), 600),
                                                                    levels)
    walls = np.asarray((levels.wall_map != edited.wall_map).reshape(600, -1).any(axis=1))
    goals = np.asarray((levels.goal_pos != edited.goal_pos).any(axis=1))
    assert not np.any(walls & goals)  # one edit: one kind
    shares = [np.mean(~walls & ~goals), np.mean(walls), np.mean(goals)]
    np.testing.assert_allclose(shares, 1 / 3, atol=0.07)  # 600 draws: 3 standard deviations ≈ 0.058


def test_an_edited_tmaze_stays_a_tmaze_that_plays_like_the_original(maze_edits):
    levels, edited = maze_edits
    tmaze = np.flatnonzero(levels.tmaze)
    assert len(tmaze) > 10
    np.testing.assert_array_equal(edited.tmaze, levels.tmaze)
    np.testing.assert_array_equal(edited.blind, levels.blind)
    _, visible = _tmaze_layout(13, 5)
    for i in tmaze:
        np.testing.assert_array_equal(edited.wall_map[i][visible], levels.wall_map[i][visible])
        np.testing.assert_array_equal(edited.goal_pos[i], levels.goal_pos[i])
    # the same first observation and the same outcome of every first move
    env, params = maze_task("tmaze").env, maze_task("tmaze").params
    pick = lambda tree, i: jax.tree.map(lambda x: x[i], tree)  # noqa: E731
    for i in tmaze[:5]:
        results = []
        for lv in (pick(levels, i), pick(edited, i)):
            obs, state = env.reset_to_level(jax.random.PRNGKey(0), lv, params)
            steps = [env.step(jax.random.PRNGKey(0), state, a, params) for a in range(3)]
            results.append((obs, [(s[0], s[2], s[3]) for s in steps]))
        for a, b in zip(jax.tree.leaves(results[0]), jax.tree.leaves(results[1])):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_lever_edits_move_the_lever_and_keep_visibility():
    levels = jax.jit(jax.vmap(TASK.sample_level))(jax.random.split(jax.random.PRNGKey(0), 200))
    edited = jax.vmap(lambda k, lv: TASK.mutate_level(k, lv, EDITS))(jax.random.split(jax.random.PRNGKey(1), 200),
                                                                     levels)
    np.testing.assert_array_equal(edited.visible, levels.visible)
    moved = (np.asarray(edited.correct) - np.asarray(levels.correct)) % 64
    assert set(moved.tolist()) <= {1, 3, 61, 63}  # three ±1 steps: an odd number of levers away, at most 3
    assert len(set(moved.tolist())) == 4


def test_brax_edits_keep_theta_in_range_and_type_b_canonical():
    env = BraxUED.__new__(BraxUED)  # the editor needs only the action count: no physics model
    env.num_actions = 3
    theta = jnp.array([[0.5, 1.0, 1.5], [1.0, 1.0, 1.0]], jnp.float32)
    levels = BraxLevel(theta=theta, type_b=jnp.array([False, True]), sign=jnp.array([False, True]),
                       seed=jnp.stack([seed_data(0), seed_data(1)]))
    mutate = jax.jit(jax.vmap(lambda key, lv: env.mutate_level(key, lv, 4)))  # one program for the 20 draws
    for k in range(20):
        edited = mutate(jax.random.split(jax.random.PRNGKey(k), 2), levels)
        assert float(edited.theta[0].min()) >= 0.5 and float(edited.theta[0].max()) <= 1.5
        assert int((edited.theta[0] != theta[0]).sum()) <= 3
        np.testing.assert_array_equal(edited.theta[1], np.ones(3))  # type B: θ stays canonical
        assert not bool(edited.sign[0]) and bool(edited.type_b[1]) and not bool(edited.type_b[0])


# ---------------------------------------------------------------------------------- the step
CFG = R(TINY, buffer=R(TINY.buffer, replay_prob=1.0, min_fill=0.25), accel=R(TINY.accel, num_edits=2))


def _jitted_step(setup):
    return jax.jit(lambda r: tr.train_step(setup, r))


def test_the_update_after_a_replay_edits_its_levels_and_inserts_them_without_training():
    # a buffer with room: edits of low-score levels still get in (a full one keeps its best)
    setup = tr.make_setup(TASK, R(CFG, buffer=R(CFG.buffer, capacity=128, min_fill=0.05)), "accel")
    step = _jitted_step(setup)
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    seen, inserted_by_edits = [], 0.0
    for _ in range(12):
        before = runner
        runner, metrics = step(runner)
        seen.append((float(metrics["replay"]), float(metrics["edit"])))
        if metrics["edit"]:
            # edited, not trained: the parameters are those of the update before
            for a, b in zip(jax.tree.leaves(before.learner.train_state.params), jax.tree.leaves(runner.learner.train_state.params)):
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
            assert float(metrics["trained_fraction_masked"]) == 0
            inserted_by_edits += float(metrics["inserted"])
        if metrics["replay"]:
            assert bool(runner.adversary.edit_next)
    # fresh levels until the buffer can replay, then replay and edit alternate
    assert (1.0, 0.0) in seen and (0.0, 1.0) in seen and inserted_by_edits > 0
    for (r0, _), (_, e1) in zip(seen, seen[1:]):
        assert e1 == r0  # an edit follows every replay, and only a replay


def test_remidi_over_accel_rejects_edits_a_frozen_buffer_explains():
    """Buffer 0 (frozen) holds hidden lever levels, which all look alike; the last replay was of
    hidden levels, so their edits are hidden levels again: every one is rejected."""
    cfg = R(CFG, remidi=R(CFG.remidi, num_buffers=2, steps_per_buffer=1000))
    setup = tr.make_setup(TASK, cfg, "remidi-accel")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    n, cap = cfg.num_envs, cfg.remidi.buffer_capacity
    hidden = TASK.env.all_levels(False)
    frozen = jax.tree.map(lambda x: x[:cap], hidden)
    bufs = runner.adversary.buffers
    levels = jax.tree.map(lambda b, f: b.at[0].set(f), bufs.levels, frozen)
    bufs = bufs.replace(levels=levels, valid=bufs.valid.at[0].set(True))
    runner = runner.replace(adversary=runner.adversary.replace(
        buffers=bufs, active=jnp.asarray(1, jnp.int32), edit_next=jnp.asarray(True),
        last_replayed=jax.tree.map(lambda x: x[cap:cap + n], hidden)))
    runner, metrics = _jitted_step(setup)(runner)
    assert float(metrics["edit"]) == 1 and float(metrics["replay"]) == 0
    assert float(metrics["rejected"]) == n and float(metrics["inserted"]) == 0
    assert not bool(buf.select_buffer(runner.adversary.buffers, 1).valid.any())


def test_accel_needs_a_mutator_and_easy_start_an_easy_generator():
    no_mutator = R(TASK, mutate_level=None)
    with pytest.raises(ConfigError, match="--algo: accel edits levels, but this task has no level mutator"):
        validate_ued_config(CFG, "accel", no_mutator)
    validate_ued_config(CFG, "plr", no_mutator)  # the others do not need one
    with pytest.raises(ConfigError, match="accel.easy_start: this task has no easy-level generator"):
        validate_ued_config(R(CFG, accel=R(CFG.accel, easy_start=True)), "accel", TASK)
    with pytest.raises(ConfigError, match="accel.num_edits: must be an integer ≥ 1"):
        validate_ued_config(R(CFG, accel=R(CFG.accel, num_edits=0)), "accel", TASK)


def test_maze_easy_start_levels_have_no_walls_but_the_task_mixture():
    task = maze_task("tmaze")
    levels = jax.vmap(task.easy_level)(jax.random.split(jax.random.PRNGKey(0), 40))
    ordinary = ~np.asarray(levels.tmaze)
    assert 0 < ordinary.sum() < 40
    assert not np.asarray(levels.wall_map)[ordinary].any()
