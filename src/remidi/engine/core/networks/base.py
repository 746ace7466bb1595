"""The pieces every network is built from (initialisers, activations, observation fields, the
heads, the LSTM over a rollout, the patch convolution) and the action distributions the policy
head's output parameterises. Initialisation as is common for PPO: orthogonal weights, gain
``sqrt(2)`` in hidden layers, ``0.01`` on the policy output, ``1.0`` on the value output; zero biases.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from remidi.engine.core.lstm import lstm_over_time
from remidi.errors import one_of

ACTIVATIONS = {"tanh": nn.tanh, "relu": nn.relu}

HIDDEN_INIT = nn.initializers.orthogonal(np.sqrt(2.0))
POLICY_INIT = nn.initializers.orthogonal(0.01)
VALUE_INIT = nn.initializers.orthogonal(1.0)
ZEROS = nn.initializers.zeros
_LOG_2PI = math.log(2.0 * math.pi)


def activation_fn(name: str):
    """The activation function called ``name`` (``"tanh"`` or ``"relu"``)."""
    if name not in ACTIVATIONS:
        raise one_of("network.activation", name, sorted(ACTIVATIONS))
    return ACTIVATIONS[name]


def obs_field(obs: Any, name: str):
    """Field ``name`` of an observation given as a dict or as any object with that attribute."""
    return obs[name] if isinstance(obs, dict) else getattr(obs, name)


def has_field(obs: Any, name: str) -> bool:
    """Whether :func:`obs_field` finds ``name``: a dict key, or an attribute of a non-array object."""
    if isinstance(obs, dict):
        return name in obs
    return not hasattr(obs, "shape") and hasattr(obs, name)


def flatten_obs(obs: Any) -> jax.Array:
    """``f32[T, N, D]``: every leaf of ``obs`` (leaves ``[T, N, ...]``) flattened after ``[T, N]``,
    concatenated in ``jax.tree.leaves`` order."""
    leaves = jax.tree.leaves(obs)
    return jnp.concatenate(
        [jnp.reshape(x, x.shape[:2] + (-1,)).astype(jnp.float32) for x in leaves], axis=-1
    )


def dense(features: int, name: str) -> nn.Dense:
    """A hidden ``nn.Dense`` layer with the hidden initialisation (orthogonal √2, zero bias)."""
    return nn.Dense(features, kernel_init=HIDDEN_INIT, bias_init=ZEROS, name=name)


class ActorCriticHeads(nn.Module):
    """Separate policy and value heads, ``Dense(hidden) -> act -> Dense(out)`` each: ``x f32[..., D]
    -> (logits f32[..., num_actions], value f32[...])``; with ``continuous`` the policy output is
    ``f32[..., 2·num_actions]``, the mean then a state-independent ``log_std`` (zeros initially).
    Its parameters are those of ``nn.Dense`` layers ``policy_hidden``, ``policy_out``, ``value_hidden``
    and ``value_out``; the two hidden layers are one product, kernels side by side (``[D, 2·hidden]``):
    one product forward and one backward instead of two plus a sum."""

    num_actions: int
    hidden: int = 32
    activation: str = "relu"
    continuous: bool = False

    @nn.compact
    def __call__(self, x):
        act = ACTIVATIONS[self.activation]  # checked when the network is made (registry.make_network)
        d = x.shape[-1]
        (pk, pb), (vk, vb) = (_Kernel((d, self.hidden), HIDDEN_INIT, True, name=f"{head}_hidden")()
                              for head in ("policy", "value"))
        both = act(x @ jnp.concatenate([pk, vk], axis=-1) + jnp.concatenate([pb, vb]))
        pi, v = both[..., :self.hidden], both[..., self.hidden:]
        logits = nn.Dense(self.num_actions, kernel_init=POLICY_INIT, bias_init=ZEROS, name="policy_out")(pi)
        if self.continuous:
            log_std = self.param("log_std", ZEROS, (self.num_actions,))
            logits = jnp.concatenate([logits, jnp.broadcast_to(log_std, logits.shape)], axis=-1)
        value = nn.Dense(1, kernel_init=VALUE_INIT, bias_init=ZEROS, name="value_out")(v)
        return logits, jnp.squeeze(value, axis=-1)


def zero_lstm_carry(batch_size: int, features: int) -> tuple[jax.Array, jax.Array]:
    """The initial ``(c, h)`` of :class:`ResetLSTM`, each ``f32[batch_size, features]`` zeros."""
    zeros = jnp.zeros((batch_size, features), jnp.float32)
    return zeros, zeros


class ResetLSTM(nn.Module):
    """An LSTM scanned over time, its carry zeroed at steps where ``reset`` is True.

    ``carry``: ``(c, h)`` each ``f32[N, features]``; ``inputs``: ``(x f32[T, N, D], reset bool[T, N])``;
    returns ``(carry, y f32[T, N, features])``. Parameters and arithmetic are
    :class:`flax.linen.OptimizedLSTMCell`'s (submodule ``cell``: input kernels ``ii if ig io``
    ``[D, features]``, recurrent kernels and biases ``hi hf hg ho``), joined once, outside the loop,
    into one ``[D + 1 + features, 4·features]`` matrix multiplying ``[x, 1, h]``; the backward pass
    computes the weight gradients after the loop, as single large products.
    """

    features: int

    @nn.compact
    def __call__(self, carry, inputs):
        x, reset = inputs
        kernel, bias = _LSTMParams(self.features, name="cell")(x.shape[-1])
        return lstm_over_time(kernel, bias, x, reset, carry)


class _LSTMParams(nn.Module):
    """:class:`flax.linen.OptimizedLSTMCell`'s parameters (same names, shapes, initialisers), joined:
    ``(kernel f32[D + H, 4H], bias f32[4H])``, gates in the order ``i f g o``."""

    features: int

    @nn.compact
    def __call__(self, input_size: int):
        h = self.features
        inputs = [_Kernel((input_size, h), nn.initializers.lecun_normal(), False, name=f"i{gate}")()
                  for gate in "ifgo"]
        recurrent = [_Kernel((h, h), nn.initializers.orthogonal(), True, name=f"h{gate}")() for gate in "ifgo"]
        kernel = jnp.concatenate([jnp.concatenate([k for k, _ in inputs], axis=-1),
                                  jnp.concatenate([k for k, _ in recurrent], axis=-1)], axis=0)
        return kernel, jnp.concatenate([b for _, b in recurrent])


class _Kernel(nn.Module):
    """One gate's ``kernel`` (and ``bias``, zeros) as flax's ``Dense`` names them."""

    shape: tuple[int, int]
    initializer: Any
    use_bias: bool

    @nn.compact
    def __call__(self):
        kernel = self.param("kernel", self.initializer, self.shape)
        bias = self.param("bias", nn.initializers.zeros_init(), self.shape[-1:]) if self.use_bias else None
        return kernel, bias


class PatchConv(nn.Module):
    """``nn.Conv(features, kernel_size, padding="VALID")`` (same ``kernel [kh, kw, C, features]``,
    ``bias``, initial values and outputs) as one product of the image's patches ``[..., kh·kw·C]``
    with the kernel. ``x``: ``[..., H, W, C]``; returns ``[..., H − kh + 1, W − kw + 1, features]``.

    Why: on a CPU, XLA's convolution of the maze agent's 5×5 views ran at ≈ 3 GFLOP/s (its weight
    gradient alone 7% of a PPO update); the product runs at the machine's matrix rate.
    """

    features: int
    kernel_size: tuple[int, int]

    @nn.compact
    def __call__(self, x):
        (kh, kw), (height, width, c) = self.kernel_size, x.shape[-3:]
        kernel = self.param("kernel", HIDDEN_INIT, (kh, kw, c, self.features))
        bias = self.param("bias", ZEROS, (self.features,))
        oh, ow = height - kh + 1, width - kw + 1
        patches = jnp.stack([x[..., i:i + oh, j:j + ow, :] for i in range(kh) for j in range(kw)], axis=-2)
        patches = patches.reshape(x.shape[:-3] + (oh, ow, kh * kw * c))  # (i, j, channel): the kernel's order
        return patches @ kernel.reshape(kh * kw * c, self.features) + bias


def lstm_carry_or_dummy(batch_size: int, lstm_size: int):
    """The initial carry for :func:`lstm_and_heads`: zero ``(c, h)``, each ``f32[batch_size,
    lstm_size]``, or with ``lstm_size`` 0 the feed-forward dummy ``f32[batch_size]``."""
    return zero_lstm_carry(batch_size, lstm_size) if lstm_size > 0 else jnp.zeros((batch_size,), jnp.float32)


def lstm_and_heads(net: nn.Module, carry, x, reset):
    """What follows an encoder inside ``net``'s compact ``__call__`` (submodules ``lstm``,
    ``heads``): an LSTM of ``net.lstm_size`` units (none if 0: the carry passes unchanged), then
    the heads (``net.head_hidden`` units, ``net.activation``). ``x``: ``f32[T, N, D]``; ``reset``:
    ``bool[T, N]``. Returns ``(carry, (logits, value))``."""
    if net.lstm_size > 0:
        carry, x = ResetLSTM(net.lstm_size, name="lstm")(carry, (x, reset))
    heads = ActorCriticHeads(net.num_actions, net.head_hidden, net.activation, net.continuous, name="heads")
    return carry, heads(x)


def shape_text(x) -> str:
    """``f32[5, 5, 3]``: an array's (or ``jax.ShapeDtypeStruct``'s) dtype and shape, short."""
    dtype = np.dtype(x.dtype)
    kind = {"f": "f", "i": "i", "u": "u", "b": "bool", "c": "c"}.get(dtype.kind, dtype.kind)
    name = kind if kind == "bool" else f"{kind}{dtype.itemsize * 8}"
    return f"{name}[{', '.join(str(d) for d in x.shape)}]"


def flat_problem(obs) -> str | None:
    """Why ``obs`` cannot be flattened into one vector (:func:`flatten_obs`): no leaves, or a leaf
    that is not a numeric or boolean array; None if it can."""
    leaves = jax.tree.leaves(obs)
    if not leaves:
        return "it has no arrays"
    for leaf in leaves:
        if not hasattr(leaf, "shape") or np.dtype(leaf.dtype).kind not in "biuf":
            return f"a leaf is {type(leaf).__name__}, not a numeric array"
    return None


# ---------------------------------------------------------------------------- the policy's distributions
# what a policy head's output parameterises: sampled in the rollout, scored in PPO's loss


@dataclass(frozen=True)
class Categorical:
    """Softmax over ``out`` (logits ``f32[..., A]``). ``n``: ``A``, the network's logits (None: a
    distribution that only samples and scores, reading ``A`` from ``out``)."""

    n: int | None = None
    continuous = False

    @property
    def network_actions(self) -> int:
        return self.n

    @staticmethod
    def sample(key: jax.Array, out: jax.Array) -> jax.Array:
        """i32[...]: one action per batch entry."""
        return jax.random.categorical(key, out)

    @staticmethod
    def log_prob(out: jax.Array, action: jax.Array) -> jax.Array:
        """f32[...]: log π(action)."""
        log_pi = jax.nn.log_softmax(out)
        return jnp.take_along_axis(log_pi, action[..., None].astype(jnp.int32), axis=-1)[..., 0]

    @staticmethod
    def entropy(out: jax.Array) -> jax.Array:
        """f32[...]: −Σ π log π."""
        log_pi = jax.nn.log_softmax(out)
        return -jnp.sum(jnp.exp(log_pi) * log_pi, axis=-1)

    @staticmethod
    def mode(out: jax.Array) -> jax.Array:
        return jnp.argmax(out, axis=-1)

    @staticmethod
    def probs(out: jax.Array) -> jax.Array:
        """f32[..., A]: the probability of each action."""
        return jax.nn.softmax(out, axis=-1)


@dataclass(frozen=True)
class DiagGaussian:
    """Independent Gaussians per action dimension: ``out = [mean f32[..., A], log_std f32[..., A]]``.
    ``dims``: ``A`` (None: read from ``out``)."""

    dims: int | None = None
    continuous = True

    @property
    def network_actions(self) -> int:
        return self.dims

    @staticmethod
    def split(out: jax.Array) -> tuple[jax.Array, jax.Array]:
        """``(mean, log_std)``, each ``f32[..., A]``."""
        a = out.shape[-1] // 2
        return out[..., :a], out[..., a:]

    @staticmethod
    def sample(key: jax.Array, out: jax.Array) -> jax.Array:
        """f32[..., A]: ``mean + std · ε``."""
        mean, log_std = DiagGaussian.split(out)
        return mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape, mean.dtype)

    @staticmethod
    def log_prob(out: jax.Array, action: jax.Array) -> jax.Array:
        """f32[...]: Σ_d log N(action_d; mean_d, std_d²)."""
        mean, log_std = DiagGaussian.split(out)
        z = (action - mean) * jnp.exp(-log_std)
        return jnp.sum(-0.5 * jnp.square(z) - log_std - 0.5 * _LOG_2PI, axis=-1)

    @staticmethod
    def entropy(out: jax.Array) -> jax.Array:
        """f32[...]: Σ_d (log std_d + ½ log(2πe))."""
        _, log_std = DiagGaussian.split(out)
        return jnp.sum(log_std + 0.5 * (_LOG_2PI + 1.0), axis=-1)

    @staticmethod
    def mode(out: jax.Array) -> jax.Array:
        return DiagGaussian.split(out)[0]


@dataclass(frozen=True)
class MultiCategorical:
    """Independent categoricals: component ``i``'s ``nvec[i]`` logits are the next entries of ``out``
    (``f32[..., Σ nvec]``); an action is ``i32[..., k]``; log-probability and entropy are sums."""

    nvec: tuple[int, ...]
    continuous = False

    @property
    def network_actions(self) -> int:
        return sum(self.nvec)

    def split(self, out: jax.Array) -> list[jax.Array]:
        """The components' logits, ``f32[..., nvec[i]]`` each."""
        starts = [sum(self.nvec[:i]) for i in range(len(self.nvec))]
        return [out[..., s:s + n] for s, n in zip(starts, self.nvec)]

    def sample(self, key: jax.Array, out: jax.Array) -> jax.Array:
        """i32[..., k]: each component drawn with its own key."""
        keys = jax.random.split(key, len(self.nvec))
        return jnp.stack([jax.random.categorical(k, logits) for k, logits in zip(keys, self.split(out))], axis=-1)

    def log_prob(self, out: jax.Array, action: jax.Array) -> jax.Array:
        """f32[...]: Σ_i log π_i(action[..., i])."""
        return sum(Categorical.log_prob(logits, action[..., i]) for i, logits in enumerate(self.split(out)))

    def entropy(self, out: jax.Array) -> jax.Array:
        """f32[...]: Σ_i H(π_i)."""
        return sum(Categorical.entropy(logits) for logits in self.split(out))

    def mode(self, out: jax.Array) -> jax.Array:
        """i32[..., k]: each component's most likely choice."""
        return jnp.stack([jnp.argmax(logits, axis=-1) for logits in self.split(out)], axis=-1)


#: size-free distributions: they sample and score any number of actions (the rollout's and PPO's
#: defaults); :func:`~remidi.engine.core.distributions.for_task` gives the sized one a network is built for
CATEGORICAL = Categorical()
GAUSSIAN = DiagGaussian()
