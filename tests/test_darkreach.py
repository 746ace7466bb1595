"""Dark reach (envs/darkreach.py): the environment against hand computations, and the tolerance
tracker on it: dark levels with the same start are a complete overlap of the frozen dark levels
(the exact tracker sees none: their noise differs), lit levels with other goals are not, and on the
variant where every level differs nothing is."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import CandidateTracker
from remidi.engine.trackers.tolerance import ToleranceCandidates
from remidi.envs.darkreach import DarkreachLevel, darkreach_task

TOLERANCE = 0.05  # the experiment's: 5 σ of the noise


def levels(*specs):
    """A batch of levels from ``(start (x, y), goal (x, y), lit, seed)`` tuples."""
    return DarkreachLevel(start=jnp.asarray([s[0] for s in specs], jnp.int32),
                          goal=jnp.asarray([s[1] for s in specs], jnp.float32),
                          lit=jnp.asarray([s[2] for s in specs]), seed=jnp.asarray([s[3] for s in specs], jnp.uint32))


def test_the_environment_by_hand():
    task = darkreach_task()
    env, params = task.env, task.params
    both = levels(((5, 5), (0.8, 0.52), True, 7), ((5, 5), (0.8, 0.52), False, 7))  # lit, dark
    one = lambda i: jax.tree.map(lambda x: x[i], both)  # noqa: E731
    reset, step = jax.jit(env.reset_to_level), jax.jit(env.step)  # one program each, not one per operation
    obs, state = reset(jax.random.PRNGKey(0), one(0), params)
    # position (0.5, 0.5) plus noise of deviation 0.01; the goal shown
    assert np.abs(np.asarray(obs[:2]) - 0.5).max() < 0.05 and np.allclose(obs[2:], [0.8, 0.52])
    dark_obs, _ = reset(jax.random.PRNGKey(1), one(1), params)
    np.testing.assert_array_equal(dark_obs[2:], [0.0, 0.0])
    np.testing.assert_array_equal(dark_obs[:2], obs[:2])  # same seed, same step: the same noise
    # three moves right reach (0.8, 0.5), 0.02 from the goal: 1 − 0.9·3/20
    rewards, dones = [], []
    for _ in range(3):
        obs, state, r, d, _ = step(jax.random.PRNGKey(0), state, 1, params)
        rewards.append(float(r)), dones.append(bool(d))
    assert dones == [False, False, True] and np.isclose(rewards[-1], 1 - 0.9 * 3 / 20)
    assert np.isclose(float(task.optimal_return(one(0))), 1 - 0.9 * 3 / 20)
    # the noise: deviation 0.01, independent of the key, different for another seed
    noise = jax.jit(jax.vmap(lambda s, t: env.observation(state.replace(level=state.level.replace(seed=s), t=t),
                                                          params)))(
        jnp.arange(2000, dtype=jnp.uint32), jnp.arange(2000) % 20)[:, :2] - env.position(state.cell)
    assert 0.009 < float(jnp.std(noise)) < 0.011 and abs(float(jnp.mean(noise))) < 0.001


def constant_up(variables, carry, obs, reset):
    """Always up (action 0): from the centre, along x = 0.5 to the top edge, where it stays."""
    n = reset.shape[1]
    return carry, (jnp.broadcast_to(jnp.asarray([0.0, -1e9, -1e9, -1e9]), (1, n, 4)), jnp.zeros((1, n)))


def uniform(variables, carry, obs, reset):
    n = reset.shape[1]
    return carry, (jnp.zeros((1, n, 4)), jnp.zeros((1, n)))


@functools.partial(jax.jit, static_argnums=(0, 1, 4, 5))
def _indist(task, apply, agents, frozen_levels, tracker, steps):
    n = agents.seed.shape[0]
    frozen = Frozen(levels=frozen_levels, valid=jnp.ones(frozen_levels.seed.shape[0], bool), tracker=tracker)
    traj, _ = rollout(jax.random.PRNGKey(0), Stepping(task.env, task.params, True),
                      Policy(apply, {}, jnp.zeros(n)), agents, steps, frozen)
    return traj.indist, traj.overflow[0]


def indist(task, apply, agents, frozen_levels, tracker, steps):
    """(bool[T, N] indistinguishable steps, i32[N] overflow) of a rollout under ``tracker``."""
    out, overflow = _indist(task, apply, agents, frozen_levels, tracker, steps)
    assert int(overflow.max()) == 0
    return np.asarray(out)


# frozen: four dark levels at the centre (goals off the agent's column x = 0.5), two lit ones, a
# dark one from the corner; agents: two fresh dark levels at the centre, a lit one whose goal is
# 0.1 from every frozen lit goal, the frozen lit level (0.2, 0.5) with its goal 0.01 away and
# another seed, and a dark level from the top-right corner
FROZEN = levels(((5, 5), (0.2, 0.2), False, 1), ((5, 5), (0.8, 0.2), False, 2), ((5, 5), (0.2, 0.8), False, 3),
                ((5, 5), (0.8, 0.8), False, 4), ((5, 5), (0.2, 0.5), True, 5), ((5, 5), (0.8, 0.5), True, 6),
                ((0, 0), (0.3, 0.3), False, 7))
AGENTS = levels(((5, 5), (0.3, 0.7), False, 100), ((5, 5), (0.7, 0.3), False, 101), ((5, 5), (0.3, 0.5), True, 102),
                ((5, 5), (0.21, 0.5), True, 103), ((10, 10), (0.3, 0.3), False, 104))


def test_dark_levels_are_a_complete_overlap_under_the_tolerance_only():
    task = darkreach_task()
    steps = 2 * task.max_episode_steps  # two episodes: the tracker restarts with the second
    exact = indist(task, constant_up, AGENTS, FROZEN, CandidateTracker(budget=8), steps)
    assert not exact.any()  # no two levels' noise is the same: the exact tracker matches nothing
    tolerant = indist(task, constant_up, AGENTS, FROZEN, ToleranceCandidates(budget=8, atol=TOLERANCE), steps)
    rejected = tolerant.all(axis=0)  # every step explained: the rollout's level is rejected as fresh
    np.testing.assert_array_equal(rejected, [True, True, False, True, False])
    assert not tolerant[:, 2].any() and not tolerant[:, 4].any()  # another goal, another start: never matched


def test_where_every_level_differs_the_tolerance_tracker_rejects_none():
    task = darkreach_task(lit_prob=1.0, random_start=True)
    sample = jax.jit(jax.vmap(task.sample_level))
    frozen = sample(jax.random.split(jax.random.PRNGKey(0), 32))
    agents = sample(jax.random.split(jax.random.PRNGKey(1), 16))
    tolerant = indist(task, uniform, agents, frozen, ToleranceCandidates(budget=32, atol=TOLERANCE), 20)
    assert not tolerant.any()  # no step of any level explained, so none rejected and nothing masked


@pytest.mark.slow
def test_the_smoke_preset_rejects_dark_levels_with_the_tolerance_tracker(tmp_path):
    import json

    from remidi.cli import main

    out = tmp_path / "remidi"
    assert main(["run", "darkreach", "--algo", "remidi", "--preset", "smoke", "--seeds", "1", "--out", str(out),
                 "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())["metrics"]
    assert summary["rejected"]["mean"] > 0
