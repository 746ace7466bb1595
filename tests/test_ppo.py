"""Tests for PPO (remidi.engine.core.ppo, remidi.engine.learner): GAE, masking semantics, reference loss, a
learning sanity check."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax.training.train_state import TrainState

from remidi.engine.core.networks import FeedForwardActorCritic, MazeLSTMActorCritic
from remidi.engine.core.ppo import PPOConfig, create_train_state, make_optimizer, validate_ppo_config
from remidi.engine.learner import Batch, compute_gae, normalize_advantages, ppo_loss, ppo_update
from remidi.errors import ConfigError

T, N, OBS, ACTIONS = 4, 4, 4, 4
NET = FeedForwardActorCritic(num_actions=ACTIONS, hidden=(16,), head_hidden=8)
LSTM = MazeLSTMActorCritic(num_actions=ACTIONS, lstm_size=8)
# Few distinct (config, net, shape) combinations keep the number of XLA compilations down.
FF_CFG = PPOConfig(epochs=2, minibatches=1, lr=1e-2, ent_coef=0.05, total_updates=5)
RNN_CFG = PPOConfig(epochs=2, minibatches=2, lr=1e-2, ent_coef=0.01, total_updates=10)

update = jax.jit(ppo_update, static_argnames=("cfg", "apply_fn"))


def random_batch(seed, t=T, n=N, mask=None, maze=False):
    """A rollout of random numbers (numpy-generated: no per-op compilation)."""
    rng = np.random.default_rng(seed)
    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    if maze:
        obs = {
            "image": jnp.asarray(rng.integers(0, 5, (t, n, 5, 5, 3)), jnp.uint8),
            "agent_dir": jnp.asarray(rng.integers(0, 4, (t, n)), jnp.int32),
        }
    else:
        obs = f32(rng.normal(size=(t, n, OBS)))
    return Batch(
        obs=obs,
        reset=jnp.asarray(rng.random((t, n)) < 0.2).at[0].set(True),
        actions=jnp.asarray(rng.integers(0, ACTIONS, (t, n)), jnp.int32),
        log_probs=f32(-rng.uniform(0.5, 1.5, (t, n))),
        values=f32(rng.normal(size=(t, n))),
        advantages=f32(rng.normal(size=(t, n))),
        targets=f32(rng.normal(size=(t, n))),
        mask=jnp.asarray(rng.random((t, n)) < 0.5) if mask is None else mask,
    )


@functools.cache
def initial_params(net):
    """``create_train_state``'s params for NET; numpy-random params shaped like LSTM's (its
    initialisers are slow to compile and their values do not matter to these tests)."""
    if net is NET:
        return create_train_state(jax.random.key(0), NET, jnp.zeros(OBS), N, FF_CFG).params
    example = jax.tree.map(lambda x: x[:1], random_batch(0, maze=True).obs)
    shapes = jax.eval_shape(LSTM.init, jax.random.key(0), LSTM.initialize_carry(N), example, jnp.ones((1, N), bool))
    rng = np.random.default_rng(0)
    return jax.tree.map(lambda x: jnp.asarray(0.3 * rng.normal(size=x.shape), jnp.float32), shapes["params"])


def make_state(net=NET):
    cfg = FF_CFG if net is NET else RNN_CFG
    return TrainState.create(apply_fn=net.apply, params=initial_params(net), tx=make_optimizer(cfg))


def assert_trees_equal(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def assert_trees_close(a, b, rtol=1e-5, atol=1e-6):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol)


def trained_part(state):
    return state.params, state.opt_state, state.step


# --- GAE ---------------------------------------------------------------------------------------


def test_compute_gae_hand_example():
    # gamma 0.9, lambda 0.5; env 0 ends its episode at t=1, env 1 never ends.
    rewards = jnp.array([[1.0, 0.0], [2.0, 0.0], [3.0, 1.0]])
    values = jnp.array([[0.5, 0.0], [1.0, 0.0], [1.5, 0.0]])
    dones = jnp.array([[False, False], [True, False], [False, False]])
    last_value = jnp.array([2.0, 0.0])
    adv, targets = compute_gae(rewards, values, dones, last_value, 0.9, 0.5)
    # env 0: delta2 = 3 + 0.9*2 - 1.5 = 3.3 -> A2 = 3.3
    #        delta1 = 2 - 1.0 = 1.0 (terminal: no bootstrap, no trace) -> A1 = 1.0
    #        delta0 = 1 + 0.9*1.0 - 0.5 = 1.4 -> A0 = 1.4 + 0.45*1.0 = 1.85
    # env 1: deltas (0, 0, 1) -> A = (0.45^2, 0.45, 1) = (0.2025, 0.45, 1.0)
    expected_adv = np.array([[1.85, 0.2025], [1.0, 0.45], [3.3, 1.0]])
    np.testing.assert_allclose(adv, expected_adv, rtol=1e-6)
    np.testing.assert_allclose(targets, expected_adv + np.asarray(values), rtol=1e-6)


# --- masking -----------------------------------------------------------------------------------


def junk_at_masked(batch, seed, obs=False):
    """``batch`` with garbage (out-of-range, huge, NaN, inf) at every masked step."""
    m = np.asarray(batch.mask)
    junk = lambda x, v: jnp.asarray(np.where(m, np.asarray(x), v), x.dtype)  # noqa: E731
    changed = batch.replace(
        actions=junk(batch.actions, 99),  # out of range on purpose
        log_probs=junk(batch.log_probs, -1e30),
        values=junk(batch.values, np.nan),
        advantages=junk(batch.advantages, 1e6),
        targets=junk(batch.targets, np.inf),
    )
    if obs:
        noise = 7.0 * np.random.default_rng(seed).normal(size=batch.obs.shape)
        changed = changed.replace(obs=jnp.asarray(np.where(m[..., None], np.asarray(batch.obs), noise), jnp.float32))
    return changed


@pytest.mark.parametrize("net", [NET, LSTM], ids=["mlp", "lstm"])
def test_masked_entries_do_not_affect_update(net):
    # The feed-forward net also gets different observations at masked steps; a recurrent net
    # consumes every observation as input, so only the per-step training targets vary for it.
    cfg = FF_CFG if net is NET else RNN_CFG
    batch = random_batch(1, maze=net is LSTM)
    assert 0 < int(batch.mask.sum()) < T * N
    changed = junk_at_masked(batch, 2, obs=net is NET)
    state = make_state(net)
    carry = net.initialize_carry(N)
    new_a, metrics_a = update(state, carry, batch, jax.random.key(3), cfg)
    new_b, metrics_b = update(state, carry, changed, jax.random.key(3), cfg)
    assert_trees_equal(trained_part(new_a), trained_part(new_b))
    assert_trees_equal(metrics_a, metrics_b)
    assert int(new_a.step) == cfg.epochs * cfg.minibatches
    assert all(np.isfinite(v) for v in metrics_a.values())
    policy_out = lambda s: s.params["heads"]["policy_out"]["kernel"]  # noqa: E731
    assert not np.array_equal(policy_out(new_a), policy_out(state))


@pytest.mark.parametrize("net", [NET, LSTM], ids=["mlp", "lstm"])
def test_all_masked_batch_is_a_no_op(net):
    cfg = FF_CFG if net is NET else RNN_CFG
    batch = junk_at_masked(random_batch(4, mask=jnp.zeros((T, N), bool), maze=net is LSTM), 5)
    state = make_state(net)
    new, metrics = update(state, net.initialize_carry(N), batch, jax.random.key(5), cfg)
    assert_trees_equal(trained_part(new), trained_part(state))
    for name, value in metrics.items():  # nothing trained: the diagnostics are undefined, not 0
        assert name == "masked_fraction" or np.isnan(value), name
    assert metrics["masked_fraction"] == 1.0


def test_only_all_masked_minibatches_are_skipped():
    # 2 minibatches x 2 epochs; env 0 is the only env with an unmasked step, so exactly one
    # minibatch per epoch trains and the step counter advances by the number of epochs.
    mask = jnp.zeros((T, N), bool).at[1, 0].set(True)
    batch = random_batch(12, mask=mask, maze=True)
    new, metrics = update(make_state(LSTM), LSTM.initialize_carry(N), batch, jax.random.key(0), RNN_CFG)
    assert int(new.step) == RNN_CFG.epochs
    assert np.isfinite(metrics["total_loss"]) and metrics["grad_norm"] > 0
    np.testing.assert_allclose(metrics["masked_fraction"], 1.0 - 0.5 * (1 / (T * N // 2)), rtol=1e-6)
    # the diagnostics are those of the minibatches that trained, undiluted by the skipped ones:
    # with one epoch, env 0's minibatch sees the initial parameters whatever the order, so its
    # entropy is the policy's at env 0's one unmasked step
    one = dataclasses.replace(RNN_CFG, epochs=1)
    _, metrics = update(make_state(LSTM), LSTM.initialize_carry(N), batch, jax.random.key(0), one)
    carry = jax.tree.map(lambda x: x[:1], LSTM.initialize_carry(N))
    env0 = jax.tree.map(lambda x: x[:, :1], batch)
    _, (logits, _) = LSTM.apply({"params": initial_params(LSTM)}, carry, env0.obs, env0.reset)
    expected = -jnp.sum(jax.nn.softmax(logits[1, 0]) * jax.nn.log_softmax(logits[1, 0]))
    np.testing.assert_allclose(metrics["entropy"], expected, rtol=1e-5)


def test_normalize_advantages_uses_unmasked_entries_only():
    adv = jnp.array([1.0, 2.0, 3.0, 100.0])
    mask = jnp.array([True, True, True, False])
    std = np.std([1.0, 2.0, 3.0])
    np.testing.assert_allclose(normalize_advantages(adv, mask), [-1 / std, 0.0, 1 / std, 0.0], rtol=1e-6)
    one = normalize_advantages(adv, jnp.array([False, True, False, False]))
    np.testing.assert_array_equal(one, [0.0, 0.0, 0.0, 0.0])
    none = normalize_advantages(adv, jnp.zeros(4, bool))
    np.testing.assert_array_equal(none, np.zeros(4))


def test_partially_masked_update_equals_update_on_unmasked_entries():
    # For a feed-forward net every (t, env) entry is independent, so training on a masked batch
    # must equal training on a [1, K] batch holding just its K unmasked entries (1 minibatch):
    # in particular the advantages are normalised over the unmasked entries only.
    batch = random_batch(6)
    keep = np.asarray(batch.mask)
    k = int(keep.sum())
    subset = jax.tree.map(lambda x: jnp.asarray(np.asarray(x)[keep])[None], batch)
    state = make_state(NET)
    new_masked, m_masked = update(state, NET.initialize_carry(N), batch, jax.random.key(7), FF_CFG)
    new_subset, m_subset = update(state, NET.initialize_carry(k), subset, jax.random.key(7), FF_CFG)
    assert_trees_close(new_masked.params, new_subset.params)
    for name in ("total_loss", "policy_loss", "value_loss", "entropy", "approx_kl", "grad_norm"):
        np.testing.assert_allclose(m_masked[name], m_subset[name], rtol=1e-5, atol=1e-6)


# --- reference loss ----------------------------------------------------------------------------


def reference_ppo_loss(params, batch, cfg):
    """Textbook unmasked PPO loss, written independently of remidi.engine.core.ppo."""
    _, (logits, value) = NET.apply({"params": params}, None, batch.obs, batch.reset)
    log_pi = jax.nn.log_softmax(logits)
    new_logp = jnp.take_along_axis(log_pi, batch.actions[..., None], axis=-1)[..., 0]
    ratio = jnp.exp(new_logp - batch.log_probs)
    adv = (batch.advantages - batch.advantages.mean()) / (batch.advantages.std() + 1e-8)
    pg = -jnp.mean(jnp.minimum(ratio * adv, jnp.clip(ratio, 1 - cfg.clip_eps, 1 + cfg.clip_eps) * adv))
    v_clip = batch.values + jnp.clip(value - batch.values, -cfg.clip_eps, cfg.clip_eps)
    vf = 0.5 * jnp.mean(jnp.maximum((value - batch.targets) ** 2, (v_clip - batch.targets) ** 2))
    ent = jnp.mean(-jnp.sum(jax.nn.softmax(logits) * log_pi, axis=-1))
    return pg + cfg.vf_coef * vf - cfg.ent_coef * ent


@functools.partial(jax.jit, static_argnames="cfg")
def reference_training(state, batch, cfg):
    """(ppo_loss, reference loss, state after ``cfg.epochs`` full-batch steps on the reference)."""
    loss, _ = ppo_loss(state.params, NET.apply, NET.initialize_carry(N), batch, cfg)
    expected_loss = reference_ppo_loss(state.params, batch, cfg)
    for _ in range(cfg.epochs):
        state = state.apply_gradients(grads=jax.grad(reference_ppo_loss)(state.params, batch, cfg))
    return loss, expected_loss, state


def test_all_true_mask_matches_reference_ppo():
    batch = random_batch(8, mask=jnp.ones((T, N), bool))
    state = make_state(NET)
    # move params away from init so that ratios differ from 1 and clipping is exercised
    state = state.replace(params=jax.tree.map(lambda p: jnp.asarray(p + 0.3 * np.sign(p)), state.params))
    loss, expected_loss, expected = reference_training(state, batch, FF_CFG)
    np.testing.assert_allclose(loss, expected_loss, rtol=1e-5)
    new, metrics = update(state, NET.initialize_carry(N), batch, jax.random.key(9), FF_CFG)
    assert metrics["clip_frac"] > 0
    assert_trees_close(new.params, expected.params)
    assert int(new.step) == FF_CFG.epochs


# --- config, optimiser, state ------------------------------------------------------------------


def test_validate_ppo_config():
    validate_ppo_config(PPOConfig(minibatches=4), 32)
    with pytest.raises(ConfigError, match="minibatches"):
        validate_ppo_config(PPOConfig(minibatches=3), 32)
    with pytest.raises(ConfigError, match="gamma"):
        validate_ppo_config(PPOConfig(gamma=1.5), 32)
    with pytest.raises(ConfigError, match="minibatches"):
        create_train_state(jax.random.key(0), NET, jnp.zeros(OBS), N, PPOConfig(minibatches=3))


def test_learning_rate_anneals_to_zero():
    cfg = PPOConfig(lr=0.1, epochs=2, minibatches=2, total_updates=3, max_grad_norm=1e9)
    tx = make_optimizer(cfg)
    step = jax.jit(tx.update)
    params = jnp.zeros(2)
    opt_state = tx.init(params)
    sizes = []
    for _ in range(cfg.total_updates * cfg.epochs * cfg.minibatches + 1):
        upd, opt_state = step(jnp.ones(2), opt_state, params)
        sizes.append(float(-upd[0]))
    assert sizes[0] == pytest.approx(0.1, rel=1e-3)
    assert abs(sizes[-1]) < 1e-8 and all(a > b for a, b in zip(sizes[:-2], sizes[1:-1]))


def test_create_train_state_accepts_single_or_rollout_obs():
    rollout = create_train_state(jax.random.key(0), NET, jnp.zeros((1, N, OBS)), N, FF_CFG)
    assert_trees_equal(initial_params(NET), rollout.params)
    assert int(rollout.step) == 0


# --- learning sanity ---------------------------------------------------------------------------


def test_ppo_learns_contextual_bandit():
    # one-step episodes: observe a one-hot context, reward 1 for choosing the action equal to it
    envs = 64
    cfg = PPOConfig(epochs=4, minibatches=2, lr=3e-3, anneal_lr=False)
    state = create_train_state(jax.random.key(0), NET, jnp.zeros(OBS), envs, cfg)
    carry = NET.initialize_carry(envs)
    ones = jnp.ones((1, envs), bool)

    def iteration(state, key):
        k_ctx, k_act, k_upd = jax.random.split(key, 3)
        ctx = jax.random.randint(k_ctx, (1, envs), 0, ACTIONS)
        obs = jax.nn.one_hot(ctx, OBS)
        _, (logits, values) = NET.apply({"params": state.params}, carry, obs, ones)
        actions = jax.random.categorical(k_act, logits)
        log_probs = jnp.take_along_axis(jax.nn.log_softmax(logits), actions[..., None], -1)[..., 0]
        rewards = (actions == ctx).astype(jnp.float32)
        adv, targets = compute_gae(rewards, values, ones, jnp.zeros(envs), cfg.gamma, cfg.gae_lambda)
        batch = Batch(obs, ones, actions, log_probs, values, adv, targets, ones)
        return ppo_update(state, carry, batch, k_upd, cfg)

    @jax.jit
    def train_and_evaluate(state, key):
        state, metrics = jax.lax.scan(iteration, state, jax.random.split(key, 100))
        _, (logits, _) = NET.apply({"params": state.params}, None, jnp.eye(OBS)[None], jnp.ones((1, OBS), bool))
        greedy_accuracy = jnp.mean(jnp.argmax(logits[0], -1) == jnp.arange(OBS))
        return greedy_accuracy, jnp.mean(jnp.diag(jax.nn.softmax(logits[0]))), metrics["total_loss"]

    accuracy, prob_correct, losses = train_and_evaluate(state, jax.random.key(1))
    assert float(accuracy) > 0.9 and float(prob_correct) > 0.9
    assert np.all(np.isfinite(losses))
