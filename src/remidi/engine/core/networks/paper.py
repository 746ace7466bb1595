"""The networks of the paper's experiments: the lever agent (``mlp``), the maze agent
(``maze_lstm``), the Brax agent (``mlp_lstm``) and PAIRED's level generator. Each states what it
reads (``reads``, ``check_observation``: :mod:`remidi.engine.core.networks.registry`)."""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from remidi.engine.core.networks.base import (ACTIVATIONS, HIDDEN_INIT, ZEROS, ActorCriticHeads, PatchConv, ResetLSTM,
                                              flat_problem, flatten_obs, has_field, obs_field,
                                              shape_text, zero_lstm_carry)


class FeedForwardActorCritic(nn.Module):
    """MLP actor-critic: flattened obs -> ``hidden`` trunk -> 32-unit policy and value heads; the
    carry is a dummy ``f32[N]`` returned unchanged.

    Default: two 256-unit tanh layers (the lever-game agent), tanh in the heads. The paper names no
    activation and the authors' lever agent has a ReLU trunk, a tanh policy head and a ReLU value
    head; tanh is kept because here ReLU learns the visible levels far more slowly. On ``remidi run
    lever --algo remidi --preset smoke`` (2 seeds; untested difference: 16 steps per rollout, the
    authors' 256) the visible-level solve rate is about 0.3 with tanh, 0.06 with ReLU and 0.15 with
    the authors' exact architecture, so the smoke pattern of the paper's Figure 8
    (``tests/test_lever_smoke.py``) holds only with tanh.
    """

    reads = "any observation: every leaf flattened into one vector"

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """None: every numeric observation can be flattened (:func:`flat_problem`)."""
        return flat_problem(obs)

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
        act = ACTIVATIONS[self.activation]  # checked when the network is made (registry.make_network)
        x = flatten_obs(obs)
        for i, width in enumerate(self.hidden):
            x = act(nn.Dense(width, kernel_init=HIDDEN_INIT, bias_init=ZEROS, name=f"trunk_{i}")(x))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, self.activation, self.continuous,
                                         name="heads")(x)
        return carry, (logits, value)


class MazeLSTMActorCritic(nn.Module):
    """The maze agent of the paper and of jaxued's maze examples: conv(5x5 view) + embedded
    direction -> LSTM(256) -> 32-unit relu heads.

    ``obs`` has ``image`` (u8/f32 ``[T, N, 5, 5, 3]``) and ``agent_dir`` (i32 ``[T, N]``, 0..3), as
    attributes or dict keys. The image passes a 3x3 ``VALID`` conv with 16 channels, is flattened
    and relu'd; the direction is one-hot and embedded by a linear ``Dense(5)``. Carry: ``(c, h)``
    each ``f32[N, lstm_size]``, zeros initially.
    """

    reads = "image [H, W, C] (H, W ≥ 3; the mazes' 5×5×3 view) and agent_dir [] (an integer, 0..3)"

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """Why ``obs`` (one observation) has no ``image [H, W, C]`` with H, W ≥ 3 and scalar
        ``agent_dir``; None if it has them."""
        for name in ("image", "agent_dir"):
            if not has_field(obs, name):
                return f"not a dict or object with a field {name}"
        image, direction = obs_field(obs, "image"), obs_field(obs, "agent_dir")
        if len(image.shape) != 3 or min(image.shape[:2]) < 3:
            return f"its image is {shape_text(image)}, not [H, W, C] with H, W ≥ 3"
        if direction.shape != ():
            return f"its agent_dir is {shape_text(direction)}, not one integer"
        return None

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
        dir_embed = nn.Dense(self.dir_embed, kernel_init=HIDDEN_INIT, bias_init=ZEROS, name="dir_embed")(
            jax.nn.one_hot(direction, 4)
        )
        x = jnp.concatenate([image_embed, dir_embed], axis=-1)
        carry, y = ResetLSTM(self.lstm_size, name="lstm")(carry, (x, reset))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, "relu", self.continuous, name="heads")(y)
        return carry, (logits, value)


class MLPLSTMActorCritic(nn.Module):
    """A recurrent agent for vector observations: flattened obs -> ``hidden`` layers ->
    LSTM(``lstm_size``) -> ``head_hidden``-unit heads. Carry: ``(c, h)`` each ``f32[N, lstm_size]``.

    Default (the paper's Brax agent, appendix): two 256-unit tanh layers, a 256-unit LSTM, 64-unit
    tanh heads; with ``continuous`` a Gaussian policy with a state-independent log-std
    (PureJaxRL's continuous PPO agent, a recurrent cell between trunk and heads).
    """

    reads = "any observation: every leaf flattened into one vector"

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """None: every numeric observation can be flattened (:func:`flat_problem`)."""
        return flat_problem(obs)

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
        act = ACTIVATIONS[self.activation]  # checked when the network is made (registry.make_network)
        x = flatten_obs(obs)
        for i, width in enumerate(self.hidden):
            x = act(nn.Dense(width, kernel_init=HIDDEN_INIT, bias_init=ZEROS, name=f"trunk_{i}")(x))
        carry, y = ResetLSTM(self.lstm_size, name="lstm")(carry, (x, reset))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, self.activation, self.continuous,
                                         name="heads")(y)
        return carry, (logits, value)


class GeneratorLSTMActorCritic(nn.Module):
    """The level generator of JaxUED's ``maze_paired.py`` (as DCD's), over a builder's observation
    (:mod:`remidi.envs.builder`): ``design`` (an image ``[T, N, H, W, C]`` through a 3x3 ``VALID``
    conv of ``conv_features`` channels and a relu, else flattened), ``time`` (one-hot ``[T, N,
    num_steps]`` embedded by a linear ``Dense(time_embed)``) and ``noise``, concatenated ->
    LSTM(``lstm_size``) -> relu heads (``Dense(32)``). Carry: ``(c, h)`` each ``f32[N, lstm_size]``,
    zeros initially."""

    reads = "design (an image [H, W, C] or any array), time (one-hot f32[num_steps]) and noise f32[D]"

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """Why ``obs`` is not a level builder's observation (fields ``design``, ``time``, ``noise``)."""
        missing = [name for name in ("design", "time", "noise") if not has_field(obs, name)]
        return f"it has no field {missing[0]}" if missing else None

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
        time = nn.Dense(self.time_embed, kernel_init=HIDDEN_INIT, bias_init=ZEROS, name="time_embed")(time)
        x = jnp.concatenate([design, time, noise.astype(jnp.float32)], axis=-1)
        carry, y = ResetLSTM(self.lstm_size, name="lstm")(carry, (x, reset))
        logits, value = ActorCriticHeads(self.num_actions, self.head_hidden, "relu", self.continuous, name="heads")(y)
        return carry, (logits, value)
