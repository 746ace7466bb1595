"""The lever agent's MLP: Dense -> activation layers, tanh by default (see its docstring)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.core.networks import make_network


@pytest.mark.parametrize("activation,fn", [(None, np.tanh), ("relu", lambda x: np.maximum(x, 0.0))])
def test_mlp_forward_pass_by_hand(activation, fn):
    kwargs = {} if activation is None else {"activation": activation}
    net = make_network("mlp", 4, hidden=(8, 8), head_hidden=5, **kwargs)
    rng = np.random.default_rng(0)
    obs = jnp.asarray(rng.normal(size=(2, 3, 6)), jnp.float32)  # [T, N, D]
    reset = jnp.zeros((2, 3), bool)
    shapes = jax.eval_shape(net.init, jax.random.key(0), net.initialize_carry(3), obs, reset)
    variables = jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape), jnp.float32), shapes)
    _, (logits, value) = net.apply(variables, net.initialize_carry(3), obs, reset)

    p = jax.tree.map(np.asarray, variables["params"])

    def dense(layer, x):
        return x @ layer["kernel"] + layer["bias"]

    x = fn(dense(p["trunk_1"], fn(dense(p["trunk_0"], np.asarray(obs)))))
    heads = p["heads"]
    want_logits = dense(heads["policy_out"], fn(dense(heads["policy_hidden"], x)))
    want_value = dense(heads["value_out"], fn(dense(heads["value_hidden"], x)))[..., 0]
    np.testing.assert_allclose(logits, want_logits, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(value, want_value, rtol=1e-4, atol=1e-4)
