"""Tabular UED: exact quantities, the ReMiDi switching rule and Combine, and the paper's pattern."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.solvers.onestep import OneStepGame
from remidi.tabular.games import PAPER_REWARDS, paper_game
from remidi.tabular.learner import (
    TabularUEDConfig, agent_action_values, combined_probs, game_arrays, init_state, level_regret,
    maybe_switch, obs_regret, train,
)

SHARED = paper_game("shared")
DISTINCT = paper_game("distinct")
# 12 + 12 levels: six copies each of θ1, θ2 behind observation "easy", of θ5, θ6 behind "hard".
# An adversary spread over the 12 hard levels gives each less than 0.1.
WIDE = OneStepGame(
    actions=("A", "B"),
    level_names=tuple(f"{name}_{i}" for name in ("theta1", "theta2", "theta5", "theta6") for i in range(6)),
    observations=("easy",) * 12 + ("hard",) * 12,
    rewards=np.repeat(PAPER_REWARDS[[0, 1, 4, 5]], 6, axis=0),
)


def test_level_regret_matches_hand_values():
    g = game_arrays(SHARED)
    probs = jnp.array([[0.875, 0.125], [0.5, 0.5], [1.0, 0.0]])  # P(A), P(B) at h1, h3, h5
    # θ1: best B (0.1); playing A w.p. .875 loses .2 → .175. θ2: best A; B w.p. .125 loses 1.4 → .175.
    expected = [0.175, 0.175, 0.7, 0.1, 2.0, 0.0]
    np.testing.assert_allclose(level_regret(g, probs), expected, atol=1e-6)
    np.testing.assert_allclose(obs_regret(g, probs), [0.175, 0.7, 2.0], atol=1e-6)


def test_agent_reward_is_weighted_not_renormalised():
    g = game_arrays(SHARED)
    adv = jnp.array([0.1, 0.0, 0.0, 0.0, 0.45, 0.45])
    q = np.asarray(agent_action_values(g, adv))
    # h1: only θ1 has mass 0.1; A causes regret 0.2 on θ1 → −0.02; B none.
    np.testing.assert_allclose(q[0], [-0.02, 0.0], atol=1e-7)
    np.testing.assert_allclose(q[1], [0.0, 0.0], atol=1e-7)  # h3 unsampled: no signal
    np.testing.assert_allclose(q[2], [-0.9, -0.9], atol=1e-6)


def test_switch_freezes_support_observations_and_restricts_next_adversary():
    cfg = TabularUEDConfig(iters_per_adversary=10, support_threshold=0.1)
    g = game_arrays(SHARED)
    state = init_state(jax.random.PRNGKey(0), g, cfg, 3)
    # adversary 0 puts its mass on θ5/θ6
    state = state._replace(adv_logits=state.adv_logits.at[0].set(jnp.array([-9, -9, -9, -9, 3.0, 3.0])))
    not_due = maybe_switch(state, g, cfg, 5)
    assert int(not_due.stage) == 0
    s = maybe_switch(state, g, cfg, 10)
    assert int(s.stage) == 1
    np.testing.assert_array_equal(np.asarray(s.owner), [3, 3, 0])  # h5 frozen to policy 0
    np.testing.assert_array_equal(np.asarray(s.allowed[1]), [1, 1, 1, 1, 0, 0])
    np.testing.assert_array_equal(np.asarray(s.agent_logits[1]), np.asarray(state.agent_logits[0]))
    # Combine: h5 is played by policy 0 whatever policy 1 does there
    s2 = s._replace(agent_logits=s.agent_logits.at[1, 2].set(jnp.array([5.0, -5.0])))
    np.testing.assert_allclose(combined_probs(s2)[2], combined_probs(s)[2])


def test_support_is_scale_free_with_many_levels():
    cfg = TabularUEDConfig(iters_per_adversary=10)
    g = game_arrays(WIDE)
    state = init_state(jax.random.PRNGKey(0), g, cfg, 2)
    hard = jnp.concatenate([jnp.full(12, -9.0), jnp.zeros(12)])  # ≈ 1/12 < 0.1 on each hard level
    s = maybe_switch(state._replace(adv_logits=state.adv_logits.at[0].set(hard)), g, cfg, 10)
    assert int(s.stage) == 1
    np.testing.assert_array_equal(np.asarray(s.owner), [2, 0])  # "hard" frozen to policy 0
    np.testing.assert_array_equal(np.asarray(s.allowed[1]), np.repeat([1, 0], 12))


def test_support_keeps_levels_within_the_threshold_of_the_largest():
    cfg = TabularUEDConfig(iters_per_adversary=10, support_threshold=0.1)
    g = game_arrays(SHARED)
    state = init_state(jax.random.PRNGKey(0), g, cfg, 2)
    # probabilities ∝ [1, 0.01, 0.11, 0.09, 0.01, 0.01]: θ1 (h1) and θ3 (h3, prob 0.089 but
    # 0.11 × the largest) are in the support; θ4 (0.09 × the largest) and θ5, θ6 (h5) are not
    logits = jnp.log(jnp.array([1.0, 0.01, 0.11, 0.09, 0.01, 0.01]))
    s = maybe_switch(state._replace(adv_logits=state.adv_logits.at[0].set(logits)), g, cfg, 10)
    np.testing.assert_array_equal(np.asarray(s.owner), [0, 0, 2])


def test_no_switch_when_every_level_is_covered():
    cfg = TabularUEDConfig(iters_per_adversary=10, support_threshold=0.1)
    g = game_arrays(DISTINCT)
    state = init_state(jax.random.PRNGKey(0), g, cfg, 2)
    state = state._replace(adv_logits=state.adv_logits.at[0].set(jnp.zeros(6)))  # uniform: all in support
    s = maybe_switch(state, g, cfg, 10)
    assert int(s.stage) == 0
    np.testing.assert_array_equal(np.asarray(s.owner), [2] * 6)


def test_seed_result_does_not_depend_on_companions():
    cfg = TabularUEDConfig(iterations=50, log_every=10)
    _, alone = train([3], SHARED, cfg, 1)
    _, together = train([0, 3, 7], SHARED, cfg, 1)
    np.testing.assert_allclose(alone["regret"][0], together["regret"][1], rtol=1e-5, atol=1e-6)


SMOKE = TabularUEDConfig(iterations=1500, iters_per_adversary=500)


def test_distinct_mmr_reaches_zero_regret():
    _, h = train(range(5), DISTINCT, SMOKE, 1)
    assert h["regret"][:, -1].max() < 0.05


def test_shared_mmr_stagnates_and_remidi_reaches_blp():
    seeds = range(5)
    _, mmr = train(seeds, SHARED, SMOKE, 1)
    final = mmr["regret"][:, -1]  # [S, O]
    assert (final[:, :2] > 0.4).all(), "MMR should stagnate well above 0.175 on h1, h3"
    assert (mmr["adversary_prob"][:, -1, 4:].sum(-1) > 0.9).all(), "MMR adversary should sit on θ5/θ6"

    _, rem = train(seeds, SHARED, SMOKE, 3)
    final = rem["regret"][:, -1]
    np.testing.assert_allclose(final[:, :2], 0.175, atol=0.03)
    np.testing.assert_allclose(final[:, 2], 1.0, atol=0.05)
    # regret on the first adversary's support (h5) is frozen after the switch
    switch = 500 // SMOKE.log_every + 1
    h5_policy = rem["policy"][:, switch:, 2, 0]
    np.testing.assert_array_equal(h5_policy, h5_policy[:, :1].repeat(h5_policy.shape[1], 1))
    assert (rem["stage"][:, -1] == 1).all()  # θ1..θ4 all in the second support: nothing left


def test_remidi_on_twelve_plus_twelve_levels_freezes_the_hard_observation():
    states, h = train(range(3), WIDE, SMOKE, 2)
    np.testing.assert_array_equal(np.asarray(states.owner), [[2, 0]] * 3)  # "hard" owned by policy 0
    final = h["regret"][:, -1]
    assert (final[:, 0] < 0.25).all(), "the second adversary should bring 'easy' towards 0.175"
    np.testing.assert_allclose(final[:, 1], 1.0, atol=0.05)


@pytest.mark.parametrize("b1", [0.9])
def test_momentum_makes_play_cycle(b1):
    """Documents why the default is adam_b1=0: with momentum h5 does not settle at 1.0."""
    cfg = dataclasses.replace(SMOKE, adam_b1=b1)
    _, h = train(range(5), SHARED, cfg, 1)
    assert h["regret"][:, -30:, 2].max() > 1.2
