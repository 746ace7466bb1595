"""PAIRED's regret estimates against a hand computation on fixed rollouts (negative regret
included), and the generator's sparse reward with no bootstrap past its episode."""

import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine import paired
from remidi.engine import scores as sc
from remidi.engine.ppo import compute_gae

# two levels, 6 steps each; episodes end where done is True
PRO_REWARD = jnp.array([[0, 0], [1, 0], [0, 0], [3, 2], [0, 0], [0, 0]], jnp.float32)
PRO_DONE = jnp.array([[0, 0], [1, 0], [0, 1], [1, 0], [0, 0], [0, 1]], bool)
ANT_REWARD = jnp.array([[5, 0], [0, 0], [2, 0], [0, 1], [0, 0], [0, 0]], jnp.float32)
ANT_DONE = jnp.array([[1, 0], [0, 0], [1, 0], [0, 1], [0, 0], [0, 0]], bool)
# by hand: protagonist level 0 episodes 1, 3 → mean 2, best 3; level 1 episodes 0, 2 → mean 1, best 2
#          antagonist level 0 episodes 5, 2 → mean 3.5, best 5; level 1 episode 1 (and a tail of 0) → 1, 1
OPTIMAL = jnp.array([4.0, 0.5])


def returns(reward, done):
    mean, best, _ = sc.episode_returns(reward, done)
    return mean, best


def test_the_three_regret_estimates_equal_a_hand_computation():
    pm, pb = returns(PRO_REWARD, PRO_DONE)
    am, ab = returns(ANT_REWARD, ANT_DONE)
    np.testing.assert_allclose(pm, [2.0, 1.0])
    np.testing.assert_allclose(pb, [3.0, 2.0])
    np.testing.assert_allclose(am, [3.5, 1.0])
    np.testing.assert_allclose(ab, [5.0, 1.0])
    est = lambda kind, **kw: np.asarray(paired.regret_estimate(kind, pm, pb, am, ab, OPTIMAL, **kw))  # noqa: E731
    np.testing.assert_allclose(est("paired"), [5 - 2, 1 - 1])
    np.testing.assert_allclose(est("flexible"), [5 - (3.5 + 2) / 2, 2 - (1 + 1) / 2])
    np.testing.assert_allclose(est("perfect"), [4 - 2, 0.5 - 1])  # negative: the protagonist beats the optimum given
    np.testing.assert_allclose(est("perfect", clip_negative=True), [2.0, 0.0])
    with pytest.raises(ValueError, match="regret estimator must be one of"):
        paired.regret_estimate("max", pm, pb, am, ab)


def test_negative_paired_regret_is_passed_on_unless_clipped():
    pm, pb = jnp.array([3.0]), jnp.array([3.0])
    am, ab = jnp.array([1.0]), jnp.array([2.0])
    assert float(paired.regret_estimate("paired", pm, pb, am, ab)[0]) == -1.0
    assert float(paired.regret_estimate("paired", pm, pb, am, ab, clip_negative=True)[0]) == 0.0


def test_the_generator_is_paid_on_its_last_step_and_never_bootstraps_past_it():
    regret = jnp.array([2.0, -1.0])
    rewards, dones = paired.generator_rewards(regret, 4)
    np.testing.assert_array_equal(rewards, [[0, 0], [0, 0], [0, 0], [2, -1]])
    np.testing.assert_array_equal(dones, [[0, 0], [0, 0], [0, 0], [1, 1]])
    values = jnp.array([[0.5, 0.1], [0.4, 0.2], [0.3, 0.3], [0.2, 0.4]])
    for last_value in (jnp.zeros(2), jnp.array([100.0, -100.0])):  # what follows the episode does not count
        adv, _ = compute_gae(rewards, values, dones, last_value, gamma=0.9, lam=1.0)
        np.testing.assert_allclose(adv[-1], regret - values[-1], rtol=1e-6)
        # before the last step: the discounted regret to come minus the value (λ = 1: Monte Carlo)
        np.testing.assert_allclose(adv[0], 0.9 ** 3 * regret - values[0], rtol=1e-6)
