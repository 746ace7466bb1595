"""Actor-critic networks sharing one interface for feed-forward and recurrent agents.

Every network is a :class:`flax.linen.Module` applied to a whole rollout at once::

    carry, (logits, value) = net.apply(variables, carry, obs, reset)

- ``obs``: an observation pytree whose leaves are shaped ``[T, N, ...]`` (time, envs).
- ``reset``: ``bool[T, N]``, True where a new episode starts at that step; a recurrent net
  re-initialises its carry *before* processing such a step.
- ``logits``: the policy output (:mod:`remidi.engine.core.distributions`), ``f32[T, N, num_actions]``
  logits, or with ``continuous=True`` ``f32[T, N, 2·num_actions]``, the mean and log standard
  deviation of a diagonal Gaussian (the log-std is a state-independent parameter, zeros
  initially); ``value``: ``f32[T, N]``.
- ``carry``: the recurrent state for the ``N`` envs after the last step. Every carry leaf has the
  env axis first, so a PPO minibatch of envs is ``jax.tree.map(lambda x: x[ids], carry)``.

``net.initialize_carry(n)`` returns the initial carry for ``n`` envs and needs no parameters.
Feed-forward nets return a dummy carry (``f32[n]`` zeros) unchanged.

Initialisation follows common PPO practice: orthogonal weights with gain ``sqrt(2)`` in hidden
layers, ``0.01`` on the policy output and ``1.0`` on the value output, zero biases.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from remidi.engine.core.lstm import lstm_over_time
from remidi.errors import one_of

ACTIVATIONS = {"tanh": nn.tanh, "relu": nn.relu}

_HIDDEN_INIT = nn.initializers.orthogonal(np.sqrt(2.0))
_POLICY_INIT = nn.initializers.orthogonal(0.01)
_VALUE_INIT = nn.initializers.orthogonal(1.0)
_ZEROS = nn.initializers.zeros


def _activation(name: str):
    """The activation function called ``name`` (``"tanh"`` or ``"relu"``)."""
    if name not in ACTIVATIONS:
        raise one_of("network.activation", name, sorted(ACTIVATIONS))
    return ACTIVATIONS[name]


def obs_field(obs: Any, name: str):
    """Field ``name`` of an observation given as a dict or as any object with that attribute."""
    return obs[name] if isinstance(obs, dict) else getattr(obs, name)


def flatten_obs(obs: Any) -> jax.Array:
    """Flatten every leaf of ``obs`` (leaves ``[T, N, ...]``) after ``[T, N]`` and concatenate.

    Returns ``f32[T, N, D]`` with leaves in ``jax.tree.leaves`` order.
    """
    leaves = jax.tree.leaves(obs)
    return jnp.concatenate(
        [jnp.reshape(x, x.shape[:2] + (-1,)).astype(jnp.float32) for x in leaves], axis=-1
    )


class ActorCriticHeads(nn.Module):
    """Separate policy and value heads: ``Dense(hidden) -> act -> Dense(out)`` each.

    ``x``: ``f32[..., D]`` -> ``(logits f32[..., num_actions], value f32[...])``; with
    ``continuous`` the policy output is ``f32[..., 2·num_actions]``: the Gaussian mean (the
    Dense output) then a state-independent log-std parameter ``log_std`` (zeros initially).

    The parameters are those of ``nn.Dense`` layers named ``policy_hidden``, ``policy_out``,
    ``value_hidden`` and ``value_out`` (same names, shapes, initialisers and so initial values);
    the two hidden layers are computed as one product with their kernels side by side
    (``[D, 2·hidden]``): one product forward and one backward instead of two each plus a sum.
    """

    num_actions: int
    hidden: int = 32
    activation: str = "relu"
    continuous: bool = False

    @nn.compact
    def __call__(self, x):
        act = _activation(self.activation)
        d = x.shape[-1]
        (pk, pb), (vk, vb) = (_Kernel((d, self.hidden), _HIDDEN_INIT, True, name=f"{head}_hidden")()
                              for head in ("policy", "value"))
        both = act(x @ jnp.concatenate([pk, vk], axis=-1) + jnp.concatenate([pb, vb]))
        pi, v = both[..., :self.hidden], both[..., self.hidden:]
        logits = nn.Dense(self.num_actions, kernel_init=_POLICY_INIT, bias_init=_ZEROS, name="policy_out")(pi)
        if self.continuous:
            log_std = self.param("log_std", _ZEROS, (self.num_actions,))
            logits = jnp.concatenate([logits, jnp.broadcast_to(log_std, logits.shape)], axis=-1)
        value = nn.Dense(1, kernel_init=_VALUE_INIT, bias_init=_ZEROS, name="value_out")(v)
        return logits, jnp.squeeze(value, axis=-1)


class FeedForwardActorCritic(nn.Module):
    """MLP actor-critic: flattened obs -> ``hidden`` trunk -> 32-unit policy and value heads.

    Default: two 256-unit tanh layers (the lever-game agent), tanh in both heads' hidden layers.
    The paper does not name the activation; the authors' lever agent (``ActorCriticFeedForward``
    in their ``lib/common/ppo.py``) has a ReLU trunk, a tanh policy head and a ReLU value head,
    with flax's default initialisation in the trunk. tanh is kept deliberately: in this engine
    ReLU learns the visible levels far more slowly (one untested difference: the lever preset
    plays 16 steps per rollout, the authors' code 256). Measured on ``remidi run lever --algo
    remidi --preset smoke`` (2 seeds), the solve rate on visible levels is about 0.3 with tanh,
    0.06 with ReLU (still below 0.1 after 1000 updates), and 0.15 with the authors' exact
    architecture and initialisation, so the smoke pattern of the paper's Figure 8
    (``tests/test_lever_smoke.py``) holds only with tanh. ``activation="relu"`` is available.
    The carry is a dummy ``f32[N]`` returned unchanged.
    """

    num_actions: int
    hidden: tuple[int, ...] = (256, 256)
    head_hidden: int = 32
    activation: str = "tanh"
    continuous: bool = False

    @nn.nowrap
    def initialize_carry(self, batch_size: int) -> jax.Array:
        """Dummy carry ``f32[batch_size]`` (zeros)."""
        return jnp.zeros((batch_size,), jnp.float32)

    @nn.compact
    def __call__(self, carry, obs, reset):
        del reset  # no state to reset
        act = _activation(self.activation)
        x = flatten_obs(obs)
        for i, width in enumerate(self.hidden):
            x = act(nn.Dense(width, kernel_init=_HIDDEN_INIT, bias_init=_ZEROS, name=f"trunk_{i}")(x))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, self.activation, self.continuous,
                                         name="heads")(x)
        return carry, (logits, value)


def zero_lstm_carry(batch_size: int, features: int) -> tuple[jax.Array, jax.Array]:
    """The initial ``(c, h)`` of :class:`ResetLSTM`, each ``f32[batch_size, features]`` zeros."""
    zeros = jnp.zeros((batch_size, features), jnp.float32)
    return zeros, zeros


class ResetLSTM(nn.Module):
    """An LSTM scanned over time whose carry is zeroed at steps where ``reset`` is True.

    ``carry``: ``(c, h)`` each ``f32[N, features]``; ``inputs``: ``(x f32[T, N, D], reset bool[T, N])``.
    Returns ``(carry, y f32[T, N, features])``.

    The parameters are those of :class:`flax.linen.OptimizedLSTMCell` (submodule ``cell``: input
    kernels ``ii if ig io`` ``[D, features]``, recurrent kernels and biases ``hi hf hg ho``, the
    same initialisers), and so is the arithmetic (:mod:`remidi.engine.core.lstm`). The kernels and
    the bias are joined once, outside the loop over time, into one ``[D + 1 + features,
    4·features]`` matrix that multiplies ``[x, 1, h]`` at each step, and the backward pass
    computes the weight gradients after the loop, as single large products.
    """

    features: int

    @nn.compact
    def __call__(self, carry, inputs):
        x, reset = inputs
        kernel, bias = _LSTMParams(self.features, name="cell")(x.shape[-1])
        return lstm_over_time(kernel, bias, x, reset, carry)


class _LSTMParams(nn.Module):
    """The parameters of :class:`flax.linen.OptimizedLSTMCell` (same names, shapes, initialisers
    and so the same initial values), returned joined: ``(kernel f32[D + H, 4H], bias f32[4H])``,
    gates in the order ``i f g o``."""

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
    """``nn.Conv(features, kernel_size, padding="VALID")`` with the same parameters (``kernel``
    ``[kh, kw, C, features]``, ``bias``), initial values and outputs, computed as one matrix
    product of the image's patches ``[..., kh·kw·C]`` with the kernel. ``x``: ``[..., H, W, C]``
    (any leading axes); returns ``[..., H − kh + 1, W − kw + 1, features]``.

    Why: on a CPU, XLA's convolution of the maze agent's 5×5 views ran at ≈ 3 GFLOP/s (its
    weight gradient alone took 7% of a PPO update); the product runs at the machine's matrix rate.
    """

    features: int
    kernel_size: tuple[int, int]

    @nn.compact
    def __call__(self, x):
        (kh, kw), (height, width, c) = self.kernel_size, x.shape[-3:]
        kernel = self.param("kernel", _HIDDEN_INIT, (kh, kw, c, self.features))
        bias = self.param("bias", _ZEROS, (self.features,))
        oh, ow = height - kh + 1, width - kw + 1
        patches = jnp.stack([x[..., i:i + oh, j:j + ow, :] for i in range(kh) for j in range(kw)], axis=-2)
        patches = patches.reshape(x.shape[:-3] + (oh, ow, kh * kw * c))  # (i, j, channel): the kernel's order
        return patches @ kernel.reshape(kh * kw * c, self.features) + bias


class MazeLSTMActorCritic(nn.Module):
    """The maze agent of the paper (SPEC §5) and of jaxued's maze examples: conv(5x5 view) +
    embedded direction -> LSTM(256) -> 32-unit heads.

    ``obs`` has ``image`` (u8/f32 ``[T, N, 5, 5, 3]``) and ``agent_dir`` (i32 ``[T, N]``, 0..3),
    as attributes (e.g. jaxued's ``Observation``) or dict keys. The image goes through a 3x3
    ``VALID`` conv with 16 channels, is flattened and passes a relu; the direction is one-hot
    encoded and embedded by a linear ``Dense(5)``; their concatenation feeds the LSTM, whose
    output feeds the relu policy and value heads (``Dense(32) -> relu -> Dense``). Carry:
    ``(c, h)`` each ``f32[N, lstm_size]``, zeros initially.
    """

    num_actions: int
    lstm_size: int = 256
    conv_features: int = 16
    dir_embed: int = 5
    head_hidden: int = 32
    continuous: bool = False

    @nn.nowrap
    def initialize_carry(self, batch_size: int) -> tuple[jax.Array, jax.Array]:
        """Zero LSTM state ``(c, h)``, each ``f32[batch_size, lstm_size]``."""
        return zero_lstm_carry(batch_size, self.lstm_size)

    @nn.compact
    def __call__(self, carry, obs, reset):
        image = obs_field(obs, "image").astype(jnp.float32)
        direction = obs_field(obs, "agent_dir")
        lead = image.shape[:2]
        conv = PatchConv(self.conv_features, (3, 3), name="conv")(image)
        image_embed = nn.relu(conv.reshape(lead + (-1,)))
        dir_embed = nn.Dense(self.dir_embed, kernel_init=_HIDDEN_INIT, bias_init=_ZEROS, name="dir_embed")(
            jax.nn.one_hot(direction, 4)
        )
        x = jnp.concatenate([image_embed, dir_embed], axis=-1)
        carry, y = ResetLSTM(self.lstm_size, name="lstm")(carry, (x, reset))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, "relu", self.continuous, name="heads")(y)
        return carry, (logits, value)


class MLPLSTMActorCritic(nn.Module):
    """A recurrent agent for vector observations (the Brax agent): flattened obs -> ``hidden``
    fully-connected layers -> LSTM(``lstm_size``) -> ``head_hidden``-unit policy and value heads.

    Default (the paper's Brax agent, appendix): two 256-unit tanh layers, a 256-unit LSTM, 64-unit
    tanh heads; with ``continuous``
    a Gaussian policy with a state-independent log-std (PureJaxRL's continuous PPO agent, with
    a recurrent cell between trunk and heads). Carry: ``(c, h)`` each ``f32[N, lstm_size]``.
    """

    num_actions: int
    hidden: tuple[int, ...] = (256, 256)
    lstm_size: int = 256
    head_hidden: int = 64
    activation: str = "tanh"
    continuous: bool = False

    @nn.nowrap
    def initialize_carry(self, batch_size: int) -> tuple[jax.Array, jax.Array]:
        """Zero LSTM state ``(c, h)``, each ``f32[batch_size, lstm_size]``."""
        return zero_lstm_carry(batch_size, self.lstm_size)

    @nn.compact
    def __call__(self, carry, obs, reset):
        act = _activation(self.activation)
        x = flatten_obs(obs)
        for i, width in enumerate(self.hidden):
            x = act(nn.Dense(width, kernel_init=_HIDDEN_INIT, bias_init=_ZEROS, name=f"trunk_{i}")(x))
        carry, y = ResetLSTM(self.lstm_size, name="lstm")(carry, (x, reset))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, self.activation, self.continuous,
                                         name="heads")(y)
        return carry, (logits, value)


class GeneratorLSTMActorCritic(nn.Module):
    """The level generator of the reference libraries (JaxUED's ``maze_paired.py`` adversary, as
    DCD's): over a builder's observation (:mod:`remidi.envs.builder`) ``design`` (an image
    ``[T, N, H, W, C]`` goes through a 3x3 ``VALID`` conv with ``conv_features`` channels and a
    relu, anything else is flattened), ``time`` (one-hot ``[T, N, num_steps]``, embedded by a
    linear ``Dense(time_embed)``: an embedding table of the step) and ``noise`` (as it is), all
    concatenated -> LSTM(``lstm_size``) -> relu policy and value heads (``Dense(32)``).
    Carry: ``(c, h)`` each ``f32[N, lstm_size]``, zeros initially."""

    num_actions: int
    lstm_size: int = 256
    conv_features: int = 128
    time_embed: int = 10
    head_hidden: int = 32
    continuous: bool = False

    @nn.nowrap
    def initialize_carry(self, batch_size: int) -> tuple[jax.Array, jax.Array]:
        """Zero LSTM state ``(c, h)``, each ``f32[batch_size, lstm_size]``."""
        return zero_lstm_carry(batch_size, self.lstm_size)

    @nn.compact
    def __call__(self, carry, obs, reset):
        design = obs_field(obs, "design").astype(jnp.float32)
        time, noise = obs_field(obs, "time"), obs_field(obs, "noise")
        lead = time.shape[:2]
        if design.ndim == 5 and min(design.shape[2:4]) >= 3:  # an image [T, N, H, W, C]
            design = nn.relu(PatchConv(self.conv_features, (3, 3), name="conv")(design))
        design = design.reshape(lead + (-1,))
        time = nn.Dense(self.time_embed, kernel_init=_HIDDEN_INIT, bias_init=_ZEROS, name="time_embed")(time)
        x = jnp.concatenate([design, time, noise.astype(jnp.float32)], axis=-1)
        carry, y = ResetLSTM(self.lstm_size, name="lstm")(carry, (x, reset))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, "relu", self.continuous, name="heads")(y)
        return carry, (logits, value)


NETWORKS = {"mlp": FeedForwardActorCritic, "maze_lstm": MazeLSTMActorCritic, "mlp_lstm": MLPLSTMActorCritic}


def make_network(kind: str, num_actions: int, continuous: bool = False, **kwargs) -> nn.Module:
    """Build the network registered as ``kind`` (``"mlp"``, ``"maze_lstm"`` or ``"mlp_lstm"``),
    with a Gaussian policy output if ``continuous`` (``num_actions`` = action dimensions).

    ``kwargs`` are module fields (e.g. ``hidden=(64, 64)`` for ``"mlp"``); lists become tuples.
    Raises :class:`remidi.errors.ConfigError` for an unknown kind, option or activation.
    """
    if kind not in NETWORKS:
        raise one_of("network", kind, sorted(NETWORKS))
    cls = NETWORKS[kind]
    allowed = [f.name for f in dataclasses.fields(cls)
               if f.init and f.name not in ("num_actions", "continuous", "parent", "name")]
    for key in kwargs:
        if key not in allowed:
            raise one_of(f"network.{kind} option", key, allowed)
    if "activation" in kwargs:
        _activation(kwargs["activation"])
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in kwargs.items()}
    return cls(num_actions=num_actions, continuous=continuous, **kwargs)
