"""Tests for remidi.engine.networks: shapes, carry semantics, registry errors."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from remidi.engine.networks import MazeLSTMActorCritic, make_network
from remidi.errors import ConfigError

T, N = 6, 3
SMALL_LSTM = MazeLSTMActorCritic(num_actions=7, lstm_size=32)
apply_small = jax.jit(SMALL_LSTM.apply)


@struct.dataclass
class MazeObs:
    """Stand-in for jaxued's maze Observation (fields ``image`` and ``agent_dir``)."""

    image: jax.Array
    agent_dir: jax.Array


def maze_obs(seed, t=T, n=N):
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 11, (t, n, 5, 5, 3)).astype(np.uint8)
    return MazeObs(image=jnp.asarray(image), agent_dir=jnp.asarray(rng.integers(0, 4, (t, n)), jnp.int32))


def random_variables(net, obs, seed=0):
    """Variables shaped like ``net.init``'s, filled from numpy (skips compiling the initialisers)."""
    reset = jnp.zeros(jax.tree.leaves(obs)[0].shape[:2], bool)
    shapes = jax.eval_shape(net.init, jax.random.key(0), net.initialize_carry(reset.shape[1]), obs, reset)
    rng = np.random.default_rng(seed)
    return jax.tree.map(lambda x: jnp.asarray(0.3 * rng.normal(size=x.shape), jnp.float32), shapes)


@functools.cache
def small_lstm_params():
    return random_variables(SMALL_LSTM, maze_obs(0))


def test_mlp_shapes_and_carry_independence():
    net = make_network("mlp", 5, hidden=(16, 16))
    a = jnp.asarray(np.random.default_rng(1).normal(size=(T, N, 3)), jnp.float32)
    obs = {"a": a, "b": jnp.ones((T, N, 2, 2), jnp.int32)}
    no_reset = jnp.zeros((T, N), bool)
    variables = random_variables(net, obs)
    assert variables["params"]["trunk_0"]["kernel"].shape == (7, 16)
    apply = jax.jit(net.apply)
    carry, (logits, value) = apply(variables, net.initialize_carry(N), obs, no_reset)
    assert logits.shape == (T, N, 5) and logits.dtype == jnp.float32
    assert value.shape == (T, N) and value.dtype == jnp.float32
    assert carry.shape == (N,)
    other_carry = jnp.full((N,), 3.0)
    carry_b, (logits_b, value_b) = apply(variables, other_carry, obs, jnp.ones((T, N), bool))
    np.testing.assert_array_equal(logits, logits_b)
    np.testing.assert_array_equal(value, value_b)
    np.testing.assert_array_equal(carry_b, other_carry)


def test_default_maze_lstm_shapes():
    net = MazeLSTMActorCritic(num_actions=7)
    obs = maze_obs(0)
    reset = jnp.zeros((T, N), bool)
    variables = jax.eval_shape(net.init, jax.random.key(0), net.initialize_carry(N), obs, reset)
    (c, h), (logits, value) = jax.eval_shape(net.apply, variables, net.initialize_carry(N), obs, reset)
    assert c.shape == h.shape == (N, 256)
    assert logits.shape == (T, N, 7) and value.shape == (T, N)
    params = variables["params"]
    assert params["conv"]["kernel"].shape == (3, 3, 3, 16)
    assert params["dir_embed"]["kernel"].shape == (4, 5)
    assert params["lstm"]["cell"]["hi"]["kernel"].shape == (256, 256)
    assert params["heads"]["policy_hidden"]["kernel"].shape == (256, 32)
    assert params["heads"]["value_hidden"]["kernel"].shape == (256, 32)


def test_maze_obs_as_struct_or_dict():
    variables = small_lstm_params()
    obs = maze_obs(5)
    reset = jnp.zeros((T, N), bool)
    carry = SMALL_LSTM.initialize_carry(N)
    _, (expected, _) = apply_small(variables, carry, obs, reset)
    as_dict = {"image": obs.image.astype(jnp.float32), "agent_dir": obs.agent_dir}
    _, (logits, _) = apply_small(variables, carry, as_dict, reset)
    np.testing.assert_allclose(logits, expected, rtol=1e-6, atol=1e-6)


def test_lstm_reset_restarts_from_fresh_carry():
    variables = small_lstm_params()
    k = 3
    obs = maze_obs(2)
    reset = jnp.zeros((T, N), bool).at[k, 0].set(True)  # only env 0 restarts at step k
    rng = np.random.default_rng(3)
    start = jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape), jnp.float32), SMALL_LSTM.initialize_carry(N))

    carry_full, (logits_full, value_full) = apply_small(variables, start, obs, reset)
    suffix = jax.tree.map(lambda x: x[k:], obs)
    carry_suf, (logits_suf, value_suf) = apply_small(
        variables, SMALL_LSTM.initialize_carry(N), suffix, jnp.zeros((T - k, N), bool)
    )
    np.testing.assert_allclose(logits_full[k:, 0], logits_suf[:, 0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(value_full[k:, 0], value_suf[:, 0], rtol=1e-5, atol=1e-6)
    for a, b in zip(carry_full, carry_suf):
        np.testing.assert_allclose(a[0], b[0], rtol=1e-5, atol=1e-6)
    # envs without a reset keep their history, so they differ from the fresh-carry run
    assert not np.allclose(logits_full[k:, 1:], logits_suf[:, 1:], atol=1e-6)


def test_lstm_reset_at_first_step_ignores_incoming_carry():
    variables = small_lstm_params()
    obs = maze_obs(4)
    reset = jnp.zeros((T, N), bool).at[0].set(True)
    junk = jax.tree.map(lambda x: x + 5.0, SMALL_LSTM.initialize_carry(N))
    _, (logits_a, _) = apply_small(variables, junk, obs, reset)
    _, (logits_b, _) = apply_small(variables, SMALL_LSTM.initialize_carry(N), obs, reset)
    np.testing.assert_allclose(logits_a, logits_b, rtol=1e-6, atol=1e-6)
    _, (logits_c, _) = apply_small(variables, junk, obs, jnp.zeros((T, N), bool))
    assert not np.allclose(logits_a, logits_c, atol=1e-6)


def test_make_network_errors():
    with pytest.raises(ConfigError, match="maze_lstm, mlp"):
        make_network("transformer", 3)
    with pytest.raises(ConfigError, match="activation"):
        make_network("mlp", 3, activation="gelu")
    with pytest.raises(ConfigError, match="hidden"):
        make_network("mlp", 3, widths=(4,))
    assert make_network("mlp", 3, hidden=[8, 8]).hidden == (8, 8)
    assert isinstance(make_network("maze_lstm", 7), MazeLSTMActorCritic)
