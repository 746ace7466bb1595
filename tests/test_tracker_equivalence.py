"""The candidate tracker equals the reference tracker (which steps every frozen level), on
random mazes, T-mazes, blind mazes and the lever game, under random actions: the same
indistinguishable steps and, under ``remidi.policy=combine``, the same per-buffer matches (each
frozen buffer's policy prefers its own action, so the actions taken reveal which buffer matched).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import make_tracker
from remidi.envs import maze as M
from remidi.envs import maze_levels
from remidi.envs.lever import lever_task

STEPS = 40


def policy(num_actions):
    """A recurrent-free policy whose logits are its ``bias`` parameter (uniform when zero)."""

    def apply(variables, carry, obs, reset):
        n = reset.shape[1]
        logits = jnp.broadcast_to(variables["params"]["bias"], (1, n, num_actions))
        return carry, (logits, jnp.zeros((1, n)))

    return apply


def run(env, params, agents, frozen_levels, valid, budget, num_actions, combine, seed=0):
    n = jax.tree.leaves(agents)[0].shape[0]
    copies = 3
    frozen_params = None
    if combine:  # buffer b's policy prefers action b + 1
        frozen_params = {"bias": 2.0 * jax.nn.one_hot(jnp.arange(copies) + 1, num_actions)}
    frozen = Frozen(levels=frozen_levels, valid=valid, params=frozen_params, tracker=make_tracker("prefix", budget))
    # the candidate tracker as the engine runs it (these environments reset deterministically):
    # its slots share the envs' reset and environment step; the reference as plainly as it gets
    traj, _ = rollout(jax.random.PRNGKey(seed), Stepping(env, params, budget > 0),
                      Policy(policy(num_actions), {"bias": jnp.zeros(num_actions)}, jnp.zeros(n)), agents, STEPS, frozen)
    return jax.device_get(traj)


def perturbed(level, key):
    """The level with one random non-goal, non-agent cell's wall toggled."""
    size = level.wall_map.shape[0]
    cell = jax.random.randint(key, (2,), 0, size)
    keep = jnp.all(cell == level.goal_pos.astype(jnp.int32)) | jnp.all(cell == level.agent_pos.astype(jnp.int32))
    flipped = level.wall_map.at[cell[1], cell[0]].set(~level.wall_map[cell[1], cell[0]])
    return level.replace(wall_map=jnp.where(keep, level.wall_map, flipped))


def near_goal(level):
    """The level with its goal moved to the cell in front of the agent (when free): episodes
    end (and the tracker restarts) within a few random actions."""
    fwd = jnp.asarray(maze_levels.DIR_TO_VEC)[level.agent_dir].astype(jnp.int32)
    cell = jnp.clip(level.agent_pos.astype(jnp.int32) + fwd, 0, level.wall_map.shape[0] - 1)
    free = ~level.wall_map[cell[1], cell[0]] & ~jnp.all(cell == level.agent_pos.astype(jnp.int32))
    return level.replace(goal_pos=jnp.where(free, cell.astype(jnp.uint32), level.goal_pos))


def wall_behind(level):
    """The level with the wall of the cell behind the agent toggled: the first observation is the
    same, the first turn shows the difference."""
    back = jnp.asarray(maze_levels.DIR_TO_VEC)[(level.agent_dir + 2) % 4].astype(jnp.int32)
    cell = jnp.clip(level.agent_pos.astype(jnp.int32) + back, 0, level.wall_map.shape[0] - 1)
    return level.replace(wall_map=level.wall_map.at[cell[1], cell[0]].set(~level.wall_map[cell[1], cell[0]]))


@functools.lru_cache(maxsize=1)  # three tests use it; building it runs many small programs
def maze_case():
    """16 agent levels and 3 frozen buffers of 24 (shuffled, 8 invalid): copies and one-wall
    perturbations of agent levels, T-mazes, blind mazes, unrelated random mazes."""
    # each level-making function compiled once (run op by op, they dispatch hundreds of programs)
    random_maze = jax.jit(M.random_maze, static_argnums=(1, 2))
    tmaze, near, perturb, behind = (jax.jit(f) for f in (M.tmaze_level, near_goal, perturbed, wall_behind))
    keys = iter(jax.random.split(jax.random.PRNGKey(7), 200))
    rand = [random_maze(next(keys), M.TRAIN_SIZE, 25) for _ in range(4)]
    short = [near(random_maze(next(keys), M.TRAIN_SIZE, 10)) for _ in range(4)]
    tm = [tmaze(next(keys)) for _ in range(4)]
    blind = [near(random_maze(next(keys), M.TRAIN_SIZE, 25)).replace(blind=jnp.asarray(True)) for _ in range(4)]
    agents = rand + short + tm + blind
    frozen = (agents[::2] + [perturb(a, next(keys)) for a in rand + tm + blind for _ in range(2)]
              + [behind(a) for a in short] + [tmaze(next(keys)) for _ in range(4)]
              + [random_maze(next(keys), M.TRAIN_SIZE, 25).replace(blind=jnp.asarray(True)) for _ in range(4)]
              + [random_maze(next(keys), M.TRAIN_SIZE, 25) for _ in range(72 - 8 - 24 - 4 - 4 - 4)])
    order = np.random.default_rng(0).permutation(len(frozen))
    frozen = [frozen[i] for i in order]
    valid = np.ones(len(frozen), bool)
    valid[np.random.default_rng(1).choice(len(frozen), 8, replace=False)] = False
    return maze_levels._stack(agents), maze_levels._stack(frozen), jnp.asarray(valid)


@functools.lru_cache(maxsize=None)  # the masked one serves two tests
def maze_reference(combine):
    """The reference tracker's rollout on :func:`maze_case`."""
    env = M.MazeEnv(M.TRAIN_SIZE)
    agents, frozen, valid = maze_case()
    return run(env, env.default_params, agents, frozen, valid, 0, 7, combine)


@pytest.mark.parametrize("combine", [False, True], ids=["masked", "combine"])
def test_candidate_tracker_equals_reference_on_mazes(combine):
    env = M.MazeEnv(M.TRAIN_SIZE)
    agents, frozen, valid = maze_case()
    ref = maze_reference(combine)
    cand = run(env, env.default_params, agents, frozen, valid, 24, 7, combine)
    assert int(cand.overflow.max()) == 0  # 24 slots hold every frozen level sharing a first observation
    np.testing.assert_array_equal(cand.indist, ref.indist)
    np.testing.assert_array_equal(cand.action, ref.action)
    np.testing.assert_array_equal(cand.done, ref.done)
    # the case is not trivial: some prefixes match then diverge, episodes restart, T-mazes and
    # blind levels match, invalid copies never do
    assert ref.indist.any(axis=0).sum() >= 8 and (ref.indist.any(axis=0) & ~ref.indist.all(axis=0)).any()
    assert ref.done.any(axis=0).sum() >= 4
    assert (~ref.indist[:-1] & ref.indist[1:]).any()  # a diverged level matches again after a restart
    assert ref.indist[0, 8:16].all()  # T-mazes and blind levels share their first observation with frozen ones


def test_too_small_a_budget_is_reported_and_only_misses_matches():
    env = M.MazeEnv(M.TRAIN_SIZE)
    agents, frozen, valid = maze_case()
    ref = maze_reference(False)
    cand = run(env, env.default_params, agents, frozen, valid, 2, 7, False)
    overflow = cand.overflow[0]
    assert (overflow[8:12] > 0).all()  # 6 frozen T-mazes share the agent T-maze's first observation
    assert not (cand.indist & ~ref.indist).any()  # a dropped level can only hide a match
    np.testing.assert_array_equal(cand.indist[:, overflow == 0], ref.indist[:, overflow == 0])


@pytest.mark.parametrize("combine", [False, True], ids=["masked", "combine"])
def test_candidate_tracker_equals_reference_on_the_lever_game(combine):
    task = lever_task(num_levers=8)
    keys = jax.random.split(jax.random.PRNGKey(3), 2)
    agents = jax.jit(jax.vmap(task.sample_level))(jax.random.split(keys[0], 32))
    frozen = jax.jit(jax.vmap(task.sample_level))(jax.random.split(keys[1], 30))
    frozen = frozen.replace(correct=frozen.correct % 4)  # visible levers 4..7 match no frozen level
    valid = jnp.arange(30) % 7 != 3
    ref = run(task.env, task.params, agents, frozen, valid, 0, 8, combine)
    cand = run(task.env, task.params, agents, frozen, valid, 20, 8, combine)
    assert int(cand.overflow.max()) == 0
    np.testing.assert_array_equal(cand.indist, ref.indist)
    np.testing.assert_array_equal(cand.action, ref.action)
    assert ref.indist.any() and not ref.indist.all()
