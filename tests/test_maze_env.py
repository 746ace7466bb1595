"""The maze domain: conformance with jaxued's Maze, T-maze and blindfold semantics, the exact
optimal return (against a brute-force search and a shortest-path-following agent), held-out sets."""

import os
from collections import deque

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jaxued.environments.maze import Maze, make_level_generator
from jaxued.environments.maze.env_solved import MazeSolved
from jaxued.environments.maze.level import Level, prefabs

from remidi.envs import maze as M

ENV = M.MazeEnv()
PARAMS = ENV.default_params
KEY = jax.random.PRNGKey(0)
OPTIMAL = jax.jit(jax.vmap(M.optimal_return))
GAMMA = 0.995  # the maze experiments' ppo.gamma


def stack(levels):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *levels)


def play(env, levels, actions):
    """Step every level of the batch through its action sequence (no resets).
    Returns (image f[N, T+1, ...], dir, reward f[N, T], done b[N, T])."""

    def one(level, acts):
        obs, state = env.reset_to_level(KEY, level, env.default_params)

        def step(state, a):
            obs, state, r, d, _ = env.step(KEY, state, a, env.default_params)
            return state, (obs, r, d)

        _, (obs_t, r, d) = jax.lax.scan(step, state, acts)
        image = jnp.concatenate([obs.image[None], obs_t.image])
        direction = jnp.concatenate([jnp.asarray(obs.agent_dir)[None], obs_t.agent_dir])
        return image, direction, r, d

    # XLA's own fusion emitters where the suite's XLA_FLAGS turned them off (tests/conftest.py):
    # the older ones round jaxued's reward 1 − 0.9·(t+1)/T differently in two programs (6e-8
    # apart), and the conformance test below compares the two bit for bit
    older = "--xla_cpu_use_fusion_emitters=false" in os.environ.get("XLA_FLAGS", "")
    jitted = jax.jit(jax.vmap(one), compiler_options={"xla_cpu_use_fusion_emitters": True} if older else None)
    return jax.tree.map(np.asarray, jitted(levels, actions))


# ------------------------------------------------------------------------- conformance
def test_ordinary_levels_play_exactly_like_jaxued_maze():
    gen = make_level_generator(13, 13, 25)
    keys = jax.random.split(jax.random.PRNGKey(1), 64)
    jaxued_levels = jax.vmap(gen)(keys)
    ours = jax.vmap(M.from_jaxued)(jaxued_levels)
    # mostly forward moves, so that goals get reached; all 7 actions appear
    actions = jax.random.choice(jax.random.PRNGKey(2), 7, (64, 300), p=jnp.array([.15, .15, .5, .05, .05, .05, .05]))
    ref = Maze(max_height=13, max_width=13, agent_view_size=5, normalize_obs=True)
    got, want = play(ENV, ours, actions), play(ref, jaxued_levels, actions)
    for name, a, b in zip(("image", "agent_dir", "reward", "done"), got, want):
        np.testing.assert_array_equal(a, b.astype(a.dtype), err_msg=name)
    assert want[3].any(axis=1).mean() > 0.3  # many episodes end: goals reached and time-outs
    assert (want[2] > 0).any()


def test_sampler_draws_the_same_mazes_as_jaxued():
    key = jax.random.PRNGKey(5)
    a = M.random_maze(key)
    b = make_level_generator(13, 13, 25)(key)
    np.testing.assert_array_equal(a.wall_map, b.wall_map)
    np.testing.assert_array_equal(a.goal_pos, b.goal_pos)
    np.testing.assert_array_equal(a.agent_pos, b.agent_pos)
    assert not bool(a.tmaze) and not bool(a.blind)


# ------------------------------------------------------------------------------ T-maze
TMAZES = stack([M.tmaze_level(k) for k in jax.random.split(jax.random.PRNGKey(3), 8)])
LEFT, RIGHT, FORWARD = 0, 1, 2


def test_tmazes_are_distinct_levels_that_look_identical():
    walls = np.asarray(TMAZES.wall_map).reshape(8, -1)
    assert len({w.tobytes() for w in walls}) == 8  # the never-seen cells differ
    goal_x = np.asarray(TMAZES.goal_pos[:, 0])
    assert set(goal_x) == {2, 10}  # both sides occur
    # any sequence of turns (the only actions that keep the episode going) looks the same everywhere
    turns = jax.random.choice(jax.random.PRNGKey(4), jnp.array([LEFT, RIGHT, 3, 6]), (1, 40))
    image, direction, reward, done = play(ENV, TMAZES, jnp.repeat(turns, 8, axis=0))
    assert (image == image[:1]).all() and (direction == direction[:1]).all()
    assert not done.any() and (reward == 0).all()
    assert not (np.round(image * 10) == 8).any()  # the goal is never drawn


@pytest.mark.parametrize("first_turn, towards_right", [(RIGHT, True), (LEFT, False)])
def test_tmaze_first_move_decides(first_turn, towards_right):
    actions = jnp.tile(jnp.array([first_turn, FORWARD, FORWARD]), (8, 1))
    _, _, reward, done = play(ENV, TMAZES, actions)
    goal_right = np.asarray(TMAZES.goal_pos[:, 0]) > 6
    expected = np.where(goal_right == towards_right, 1.0, -1.0)
    np.testing.assert_array_equal(reward[:, 1], expected)
    assert done[:, 1].all() and not done[:, 0].any()


def test_tmaze_stem_and_blocked_moves():
    # facing up into the wall: forward does not move and does not end the episode
    _, _, reward, done = play(ENV, TMAZES, jnp.tile(jnp.array([FORWARD, RIGHT, RIGHT, FORWARD]), (8, 1)))
    assert not done[:, :3].any() and (reward[:, :3] == 0).all()
    np.testing.assert_array_equal(reward[:, 3], -1.0)  # down the stem: away from either arm
    assert done[:, 3].all()
    np.testing.assert_array_equal(OPTIMAL(TMAZES), 1.0)
    # the agent faces the top wall, so the reward comes at step index 1: discounted optimum γ
    np.testing.assert_allclose(jax.vmap(lambda lv: M.optimal_discounted_return(lv, GAMMA))(TMAZES), GAMMA, rtol=1e-7)


# ----------------------------------------------------------------------------- blindfold
def test_blind_levels_see_zeros_but_play_the_same_maze():
    levels = jax.jit(jax.vmap(M.random_maze))(jax.random.split(jax.random.PRNGKey(6), 16))
    blind = levels.replace(blind=jnp.ones(16, bool))
    actions = jax.random.choice(jax.random.PRNGKey(7), 3, (16, 200))
    seen, dirs, r_seen, d_seen = play(ENV, levels, actions)
    image, direction, reward, done = play(ENV, blind, actions)
    assert (image == 0).all() and (direction == 0).all()
    assert (seen != 0).any(axis=(2, 3, 4)).all()  # an ordinary view is never all zeros
    np.testing.assert_array_equal(reward, r_seen)
    np.testing.assert_array_equal(done, d_seen)
    np.testing.assert_array_equal(OPTIMAL(blind), OPTIMAL(levels))


def test_level_mixtures_and_tags():
    for kind, tag in (("tmaze", "tmaze"), ("blindfold", "blind")):
        task = M.maze_task(kind, 0.5)
        levels = jax.jit(jax.vmap(task.sample_level))(jax.random.split(KEY, 1000))
        flags = np.asarray(jax.vmap(task.level_tags)(levels)[tag])
        assert 0.45 < flags.mean() < 0.55
        assert flags.tolist() == np.asarray(getattr(levels, tag)).tolist()
        other = "blind" if tag == "tmaze" else "tmaze"
        assert not np.asarray(getattr(levels, other)).any()
    none = jax.jit(jax.vmap(M.maze_task("tmaze", 0.0).sample_level))(jax.random.split(KEY, 200))
    assert not np.asarray(none.tmaze).any()


# ------------------------------------------------------------------------- optimal return
def brute_force_steps(walls: np.ndarray, goal, start, direction) -> float:
    """Breadth-first search over (x, y, direction), written independently of the JAX version."""
    h, w = walls.shape
    moves = [(1, 0), (0, 1), (-1, 0), (0, -1)]
    seen = {(start[0], start[1], direction): 0}
    queue = deque([(start[0], start[1], direction)])
    while queue:
        x, y, d = queue.popleft()
        n = seen[(x, y, d)]
        nx, ny = x + moves[d][0], y + moves[d][1]
        if (nx, ny) == tuple(goal):
            return float(n + 1)
        nexts = [(x, y, (d - 1) % 4), (x, y, (d + 1) % 4)]
        if 0 <= nx < w and 0 <= ny < h and not walls[ny, nx]:
            nexts.append((nx, ny, d))
        for s in nexts:
            if s not in seen:
                seen[s] = n + 1
                queue.append(s)
    return float("inf")


@pytest.mark.parametrize("size, walls", [(5, 8), (7, 20), (13, 25), (13, 60)])
def test_shortest_path_matches_brute_force(size, walls):
    levels = jax.jit(jax.vmap(lambda k: M.random_maze(k, size, walls)))(jax.random.split(jax.random.PRNGKey(size + walls), 40))
    got = np.asarray(jax.jit(jax.vmap(M.shortest_path_steps))(levels))
    want = [brute_force_steps(np.asarray(levels.wall_map[i]), np.asarray(levels.goal_pos[i]).tolist(),
                              np.asarray(levels.agent_pos[i]).tolist(), int(levels.agent_dir[i])) for i in range(40)]
    np.testing.assert_array_equal(got, want)
    if walls >= 20:
        assert np.isinf(got).any() and np.isfinite(got).any()  # both cases are exercised
    opt = np.asarray(OPTIMAL(levels))
    np.testing.assert_allclose(opt, np.where(np.isinf(want), 0.0, 1 - 0.9 * np.asarray(want) / 250), rtol=1e-6)


def best_discounted_return_by_brute_force(env, levels, length: int, gamma: float) -> np.ndarray:
    """f[N]: the best Σ_t γ^t r_t over every sequence of ``length`` actions (left, right, forward)
    played in the real environment, rewards after the episode's end ignored."""
    seqs = np.array(np.meshgrid(*[[LEFT, RIGHT, FORWARD]] * length, indexing="ij")).reshape(length, -1).T
    n, m = len(seqs), int(levels.agent_dir.shape[0])
    tiled = jax.tree.map(lambda x: jnp.repeat(x, n, axis=0), levels)
    _, _, reward, done = play(env, tiled, jnp.asarray(np.tile(seqs, (m, 1))))
    alive = np.concatenate([np.ones((len(done), 1), bool), ~np.cumsum(done, axis=1)[:, :-1].astype(bool)], axis=1)
    value = (np.where(alive, reward, 0.0) * gamma ** np.arange(length)).sum(axis=1)
    return value.reshape(m, n).max(axis=1)


@pytest.mark.slow  # 108 programs for a brute force over action sequences: 8 s of a cold quick tier
def test_discounted_optimum_matches_brute_force_over_action_sequences():
    """optimal_discounted_return against the best of all action sequences, played step by step in
    the environment: T-mazes (the optimum is γ: a turn, then the move into the goal arm) and 5×5
    mazes whose goal is at most 7 actions away."""
    np.testing.assert_allclose(best_discounted_return_by_brute_force(ENV, TMAZES, 4, GAMMA),
                               jax.vmap(lambda lv: M.optimal_discounted_return(lv, GAMMA))(TMAZES), rtol=1e-6)
    small = jax.jit(jax.vmap(lambda k: M.random_maze(k, 5, 3)))(jax.random.split(jax.random.PRNGKey(21), 30))
    steps = np.asarray(jax.vmap(M.shortest_path_steps)(small))
    pick = np.flatnonzero(steps <= 7)[:6]
    assert len(pick) == 6 and len(set(steps[pick])) >= 3  # several path lengths
    small = jax.tree.map(lambda x: x[pick], small)
    for gamma in (GAMMA, 0.9):
        want = best_discounted_return_by_brute_force(M.MazeEnv(5), small, 7, gamma)
        np.testing.assert_allclose(jax.vmap(lambda lv: M.optimal_discounted_return(lv, gamma))(small), want, rtol=1e-6)


def test_optimal_return_is_what_a_shortest_path_agent_earns():
    """Follow the cost-to-go greedily in the real environment: its return equals optimal_return;
    jaxued's MazeSolved agrees on the step count but its optimal_value is one step short."""
    names = list(M.PREFAB_NAMES) + ["random"]
    levels = [M.prefab_level(n) for n in M.PREFAB_NAMES] + [M.random_maze(jax.random.PRNGKey(11))]
    step = jax.jit(ENV.step)
    solved = MazeSolved(max_height=13, max_width=13, normalize_obs=True)
    solved_init, costs, optimal = jax.jit(solved.init_state_from_level), jax.jit(M.cost_to_go), jax.jit(M.optimal_return)
    for name, level in zip(names, levels):
        cost = np.asarray(costs(level))
        n = float(cost[int(level.agent_dir), int(level.agent_pos[1]), int(level.agent_pos[0])])
        assert np.isfinite(n), name
        _, state = ENV.reset_to_level(KEY, level, PARAMS)
        total, discounted, t, done = 0.0, 0.0, 0, False
        while not done:
            x, y = np.asarray(state.inner.agent_pos).tolist()
            here = cost[int(state.inner.agent_dir), y, x]
            for a in (LEFT, RIGHT, FORWARD):  # an action that gets one step closer
                _, nxt, r, d, _ = step(KEY, state, a, PARAMS)
                nx, ny = np.asarray(nxt.inner.agent_pos).tolist()
                if (bool(d) and float(r) > 0) or cost[int(nxt.inner.agent_dir), ny, nx] == here - 1:
                    break
            discounted += GAMMA ** t * float(r)
            state, total, t, done = nxt, total + float(r), t + 1, bool(d)
        assert t == n, name
        assert total > 0, name
        np.testing.assert_allclose(total, float(optimal(level)), rtol=1e-6, err_msg=name)
        # the discounted optimum is what the shortest-path agent earns under Σ_t γ^t r_t
        np.testing.assert_allclose(discounted, float(M.optimal_discounted_return(level, GAMMA)), rtol=1e-5,
                                   err_msg=name)
        assert discounted < total
        sstate = solved_init(level)
        assert float(solved.min_steps_to_goal(sstate)) == n
        assert float(solved.optimal_value(sstate, 1.0, PARAMS)) < total


# -------------------------------------------------------------------------- held-out sets
def test_held_out_sets():
    sets = M.held_out_sets()
    assert tuple(sets) == M.HELD_OUT_NAMES and len(sets) == 10
    for name in M.PREFAB_NAMES:
        size, levels = sets[name]
        assert size == 13 and levels.wall_map.shape == (1, 13, 13)
        assert Level.from_str(prefabs[name]).to_str() == prefabs[name]
        np.testing.assert_array_equal(levels.wall_map[0], Level.from_str(prefabs[name]).wall_map)
    for name, size, dead_ends in (("SmallCorridor", 13, 10), ("LargeCorridor", 19, 16)):
        got_size, levels = sets[name]
        assert got_size == size and levels.wall_map.shape == (dead_ends, size, size)
        walls = np.asarray(levels.wall_map[0])
        mid = size // 2
        assert not walls[0].any() and not walls[-1].any() and not walls[:, 0].any() and not walls[:, -1].any()
        assert walls[mid, 1:-1].all()
        np.testing.assert_array_equal(levels.agent_pos, np.tile([0, mid], (dead_ends, 1)))
        np.testing.assert_array_equal(levels.agent_dir, 0)  # facing right, into the middle row's wall (DCD, minimax)
        goals = {tuple(g) for g in np.asarray(levels.goal_pos).tolist()}
        assert len(goals) == dead_ends and all(y in (mid - 1, mid + 1) and x % 2 == 0 for x, y in goals)
        assert np.isfinite(jax.jit(jax.vmap(M.shortest_path_steps))(levels)).all()


def test_large_corridor_is_played_at_its_own_size():
    env = M.MazeEnv(19)
    _, levels = M.held_out_sets()["LargeCorridor"]
    level = jax.tree.map(lambda x: x[0], levels)
    obs, state = env.reset_to_level(KEY, level, PARAMS)
    assert obs.image.shape == (5, 5, 3)
    # face up, then walk the ring clockwise to the far right end: x reaches 18
    for a in [LEFT] + [FORWARD] * 9 + [RIGHT] + [FORWARD] * 18:
        obs, state, _, _, _ = env.step(KEY, state, a, PARAMS)
    assert int(state.inner.agent_pos[0]) == 18
