"""Tests for remidi.engine.core.networks: shapes, carry semantics, registry errors."""

import dataclasses
import functools
from types import SimpleNamespace

import flax.linen
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from remidi.engine.core.networks import MazeLSTMActorCritic, make_network
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


class ScannedFlaxLSTM(flax.linen.Module):
    """flax's ``OptimizedLSTMCell`` scanned over time (without resets)."""

    features: int

    @flax.linen.compact
    def __call__(self, carry, x):
        scan = flax.linen.scan(flax.linen.OptimizedLSTMCell, variable_broadcast="params", split_rngs={"params": False})
        return scan(self.features, name="cell")(carry, x)


def test_reset_lstm_is_flax_optimized_lstm_cell():
    """Our LSTM (one joined kernel, one product per step) against flax's ``OptimizedLSTMCell``
    applied step by step with the same parameters: same parameter tree and initial values, same
    outputs and carries, same gradients (to float rounding)."""
    from remidi.engine.core.networks import ResetLSTM, zero_lstm_carry

    t, n, d, h = 5, 3, 7, 8
    rng = np.random.default_rng(0)
    x = jnp.asarray(rng.normal(size=(t, n, d)), jnp.float32)
    reset = jnp.asarray(rng.random((t, n)) < 0.3)
    carry0 = jax.tree.map(lambda c: jnp.asarray(rng.normal(size=c.shape), jnp.float32), zero_lstm_carry(n, h))
    cell = flax.linen.OptimizedLSTMCell(h)
    ours = ResetLSTM(h)
    variables = ours.init(jax.random.key(1), carry0, (x, reset))
    flax_params = cell.init(jax.random.key(2), carry0, x[0])["params"]
    assert jax.tree.structure(variables["params"]["cell"]) == jax.tree.structure(flax_params)
    # the initialisers are flax's: one key gives the values flax's cell (scanned) starts from
    flax_init = ScannedFlaxLSTM(h).init(jax.random.key(1), carry0, x)["params"]["cell"]
    for a, b in zip(jax.tree.leaves(variables["params"]["cell"]), jax.tree.leaves(flax_init)):
        np.testing.assert_array_equal(a, b)
    variables = jax.tree.map(lambda v: v + jnp.asarray(0.2 * rng.normal(size=v.shape), jnp.float32), variables)

    def reference(params, carry, inputs):
        ys = []
        for k in range(t):
            carry = jax.tree.map(lambda c: jnp.where(reset[k][:, None], 0.0, c), carry)
            carry, y = cell.apply({"params": params["cell"]}, carry, inputs[k])
            ys.append(y)
        return carry, jnp.stack(ys)

    def loss(apply, params, carry, inputs):
        (c, hh), ys = apply(params, carry, inputs)
        return jnp.sum(ys ** 2) + jnp.sum(c * hh)

    def apply_ours(params, carry, inputs):
        return ours.apply({"params": params}, carry, (inputs, reset))

    (c_a, h_a), y_a = apply_ours(variables["params"], carry0, x)
    (c_b, h_b), y_b = reference(variables["params"], carry0, x)
    for a, b in ((y_a, y_b), (c_a, c_b), (h_a, h_b)):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    # the parameters', the initial carry's and the inputs' gradients (the inputs' train the layers below)
    grads_a = jax.grad(functools.partial(loss, apply_ours), argnums=(0, 1, 2))(variables["params"], carry0, x)
    grads_b = jax.grad(functools.partial(loss, reference), argnums=(0, 1, 2))(variables["params"], carry0, x)
    for a, b in zip(jax.tree.leaves(grads_a), jax.tree.leaves(grads_b)):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5)


def test_patch_conv_is_flax_conv():
    from remidi.engine.core.networks import PatchConv

    x = jnp.asarray(np.random.default_rng(0).normal(size=(2, 3, 5, 6, 4)), jnp.float32)
    ours, theirs = PatchConv(8, (3, 2)), flax.linen.Conv(8, (3, 2), padding="VALID",
                                                         kernel_init=flax.linen.initializers.orthogonal(np.sqrt(2.0)))
    variables = ours.init(jax.random.key(0), x)
    for a, b in zip(jax.tree.leaves(variables), jax.tree.leaves(theirs.init(jax.random.key(0), x))):
        np.testing.assert_array_equal(a, b)  # same parameters, same initial values
    variables = jax.tree.map(lambda v: v + 0.5, variables)  # a nonzero bias too
    np.testing.assert_allclose(ours.apply(variables, x), theirs.apply(variables, x), rtol=1e-5, atol=1e-5)


def test_make_network_errors():
    with pytest.raises(ConfigError, match="maze_lstm, mlp"):
        make_network("transformer", 3)
    with pytest.raises(ConfigError, match="activation"):
        make_network("mlp", 3, activation="gelu")
    with pytest.raises(ConfigError, match="hidden"):
        make_network("mlp", 3, widths=(4,))
    assert make_network("mlp", 3, hidden=[8, 8]).hidden == (8, 8)
    assert isinstance(make_network("maze_lstm", 7), MazeLSTMActorCritic)


class _DenseHeads(flax.linen.Module):
    """The heads written with four flax ``Dense`` layers, the reference for ActorCriticHeads."""

    num_actions: int
    continuous: bool

    @flax.linen.compact
    def __call__(self, x):
        dense = lambda n, init, name: flax.linen.Dense(n, kernel_init=init, name=name)  # noqa: E731
        hidden = flax.linen.initializers.orthogonal(np.sqrt(2.0))
        pi = jnp.tanh(dense(32, hidden, "policy_hidden")(x))
        logits = dense(self.num_actions, flax.linen.initializers.orthogonal(0.01), "policy_out")(pi)
        if self.continuous:
            log_std = self.param("log_std", flax.linen.initializers.zeros, (self.num_actions,))
            logits = jnp.concatenate([logits, jnp.broadcast_to(log_std, logits.shape)], axis=-1)
        v = jnp.tanh(dense(32, hidden, "value_hidden")(x))
        return logits, dense(1, flax.linen.initializers.orthogonal(1.0), "value_out")(v)[..., 0]


@pytest.mark.parametrize("continuous", [False, True])
def test_heads_are_flax_dense_layers(continuous):
    """The heads' joined hidden product: same parameters, initial values and outputs as Dense layers."""
    from remidi.engine.core.networks import ActorCriticHeads

    x = jax.random.normal(jax.random.key(3), (7, 5, 48))
    ours, ref = ActorCriticHeads(6, 32, "tanh", continuous), _DenseHeads(6, continuous)
    params = ours.init(jax.random.key(0), x)
    ref_params = ref.init(jax.random.key(0), x)
    assert jax.tree.structure(params) == jax.tree.structure(ref_params)
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(ref_params), strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(ours.apply(params, x), ref.apply(params, x), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6)


def test_brax_agent_has_two_trunk_layers_before_its_lstm():
    """The paper's Brax agent (appendix): two fully-connected layers, then the recurrent cell;
    ``hidden_size`` sets the width of both."""
    from remidi.engine.setup import network_for
    from remidi.experiments.brax import paper_config

    obs = jnp.zeros((1, 2, 13), jnp.float32)
    for hidden_size, width in ((0, 256), (64, 64)):
        cfg = dataclasses.replace(paper_config(), hidden_size=hidden_size)
        task = SimpleNamespace(num_actions=3, continuous=True)
        net = network_for(cfg, task)
        shapes = jax.eval_shape(lambda: net.init(jax.random.PRNGKey(0), net.initialize_carry(2), obs,
                                                 jnp.ones((1, 2), bool)))["params"]
        assert shapes["trunk_0"]["kernel"].shape == (13, width)
        assert shapes["trunk_1"]["kernel"].shape == (width, width)
        assert "trunk_2" not in shapes and "lstm" in shapes
