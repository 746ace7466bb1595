"""The distinguishability tracker, on hand-built levels whose observation sequences are chosen."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import ExactTracker
from remidi.envs.interface import AutoReplay
from seq_env import SeqEnv, level, stack

ENV = SeqEnv()


def run_tracker(agent_level, frozen_levels, valid=None, mode="prefix", steps=None):
    """Roll a constant-action policy on one agent level; return indist bool[T]."""
    frozen_batch = stack(*frozen_levels)
    valid = jnp.ones(len(frozen_levels), bool) if valid is None else jnp.asarray(valid)

    def apply(variables, carry, obs, reset):
        return carry, (jnp.zeros(obs.shape + (2,)).at[..., 0].set(10.0), jnp.zeros(obs.shape))

    levels = stack(agent_level)
    steps = steps or int(agent_level.length)
    traj, _ = rollout(jax.random.PRNGKey(0), Stepping(ENV, None), Policy(apply, {}, jnp.zeros(1)), levels, steps,
                      Frozen(levels=frozen_batch, valid=valid, tracker=ExactTracker(mode)))
    return np.asarray(traj.indist[:, 0])


def test_prefix_needs_one_level_matching_the_whole_prefix():
    # frozen: [0 1 2] and [0 5 3]; agent sees [0 1 3]: every step matched by SOME frozen level,
    # but no single frozen level produced the whole prefix once the third observation arrives.
    frozen = [level([0, 1, 2]), level([0, 5, 3])]
    agent = level([0, 1, 3])
    np.testing.assert_array_equal(run_tracker(agent, frozen, mode="prefix"), [True, True, False])
    np.testing.assert_array_equal(run_tracker(agent, frozen, mode="per_step"), [True, True, True])


def test_exact_copy_is_indistinguishable_everywhere_and_divergence_is_permanent():
    frozen = [level([4, 1, 2, 7])]
    np.testing.assert_array_equal(run_tracker(level([4, 1, 2, 7]), frozen), [True] * 4)
    # diverges at step 1, matches again at step 2: stays distinguishable
    np.testing.assert_array_equal(run_tracker(level([4, 9, 2, 7]), frozen), [True, False, False, False])
    np.testing.assert_array_equal(run_tracker(level([3, 1, 2, 7]), frozen), [False] * 4)


def test_invalid_frozen_entries_never_match():
    frozen = [level([0, 1, 2])]
    np.testing.assert_array_equal(run_tracker(level([0, 1, 2]), frozen, valid=[False]), [False] * 3)


def test_episode_end_must_coincide():
    # same observations, but the frozen level's episode is longer: the agent's episode ends first,
    # so the frozen level did not produce that trajectory; the next episode starts afresh.
    frozen = [level([0, 1, 2, 3], length=4)]
    agent = level([0, 1, 2, 3], length=2)
    # steps 0,1 indistinguishable (ended episode judged by its prefix); new episode restarts matching
    np.testing.assert_array_equal(run_tracker(agent, frozen, steps=4), [True, True, True, True])
    agent_long = level([0, 1, 2, 3], length=4)
    np.testing.assert_array_equal(run_tracker(agent_long, [level([0, 1, 2, 3], length=2)], steps=4),
                                  [True, True, False, False])


def test_tracker_restarts_with_each_episode():
    frozen = [level([0, 1])]
    agent = level([0, 2])
    # episode 1: [0 → indist, 2 → not]; episode 2 restarts: same again
    np.testing.assert_array_equal(run_tracker(agent, frozen, steps=4), [True, False, True, False])


@pytest.mark.parametrize("deterministic_reset", [False, True])
def test_autoreplay_restarts_the_same_level(deterministic_reset):
    # True: the first state is kept and restored instead of resetting again (same result)
    env = AutoReplay(ENV, deterministic_reset)
    lv = level([5, 6], reward=2.0)
    obs, state = env.reset_to_level(jax.random.PRNGKey(0), lv, None)
    assert (state.start is not None) == deterministic_reset
    seen = [int(obs)]
    rewards, dones = [], []
    for i in range(4):
        obs, state, r, d, _ = env.step(jax.random.PRNGKey(i), state, 0, None)
        seen.append(int(obs)); rewards.append(float(r)); dones.append(bool(d))
    assert seen == [5, 6, 5, 6, 5]
    assert rewards == [0.0, 2.0, 0.0, 2.0] and dones == [False, True, False, True]


def test_the_tracker_is_a_component_chosen_from_the_config():
    from remidi.engine.trackers.exact import CandidateTracker, make_tracker

    assert make_tracker("prefix", 0) == ExactTracker("prefix")
    assert make_tracker("per_step", 0) == ExactTracker("per_step")
    assert make_tracker("prefix", 8) == CandidateTracker(budget=8)
    with pytest.raises(ValueError, match="prefix mode only"):
        make_tracker("per_step", 8)
    with pytest.raises(ValueError, match="tracker mode must be one of"):
        ExactTracker("exact")
