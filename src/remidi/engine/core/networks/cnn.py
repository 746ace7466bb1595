"""An actor-critic over pixels (``network=cnn``): a small strided CNN, as Kinetix's pixel agent
(``ActorCriticPixelsRNN``, its ``impala_fast`` mode) and the NatureCNN family read images.

The image ``[H, W, C]`` is the observation itself when it is one array, else its field ``image``
(a dict key or an attribute: Kinetix's ``PixelsObservation``, jaxued's maze ``Observation``); it
is cast to f32 as it is (scale it in the environment). Each layer is a ``SAME``-padded
convolution with a relu (defaults: Kinetix's ``impala_fast``, 16 channels 8×8 stride 4 then 32
channels 4×4 stride 2; ``SAME`` as flax's default that Kinetix uses, so any image size works).
The features are flattened and concatenated with the observation's other leaves, flattened
(Kinetix's ``global_info``, the mazes' ``agent_dir``), then an optional LSTM and the heads.
Kinetix's defaults for what follows (its 2.0.2 ``model-base.yaml``): tanh, 128-unit heads
(``fc_layer_width``; one hidden layer here, five there), no recurrence (``recurrent_model``).
Convolutions are initialised orthogonal √2 (PureJaxRL's, CleanRL's NatureCNN; Kinetix keeps
flax's default).
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from remidi.engine.core.networks.base import (HIDDEN_INIT, ZEROS, flat_problem, flatten_obs, has_field,
                                              lstm_and_heads, lstm_carry_or_dummy, shape_text)
from remidi.errors import ConfigError


def split_image(obs):
    """``(image, rest)``: the image (``obs`` itself if it is one array, else its field ``image``)
    and the other leaves of ``obs`` as a list (empty for a single array)."""
    if hasattr(obs, "shape"):
        return obs, []
    pairs = jax.tree_util.tree_flatten_with_path(obs)[0]
    first = [getattr(path[0], "key", getattr(path[0], "name", None)) for path, _ in pairs]
    image = [leaf for key, (_, leaf) in zip(first, pairs) if key == "image"]
    return (image[0] if len(image) == 1 else None), [leaf for key, (_, leaf) in zip(first, pairs) if key != "image"]


class CNNActorCritic(nn.Module):
    """Image -> strided convolutions (relu) -> flattened, beside the other leaves -> optional
    LSTM -> heads (module docstring). Carry: ``(c, h)`` each ``f32[N, lstm_size]``, or a dummy
    ``f32[N]`` with ``lstm_size`` 0."""

    reads = "an image [H, W, C]: the observation itself, or its field image with its other fields flattened beside it"

    num_actions: int
    channels: tuple[int, ...] = (16, 32)
    kernels: tuple[int, ...] = (8, 4)
    strides: tuple[int, ...] = (4, 2)
    lstm_size: int = 0
    head_hidden: int = 128
    activation: str = "tanh"
    continuous: bool = False

    def __post_init__(self):
        if not (len(self.channels) == len(self.kernels) == len(self.strides) >= 1):
            raise ConfigError(f"network.channels: channels, kernels and strides must be lists of one length ≥ 1, "
                              f"got {list(self.channels)}, {list(self.kernels)}, {list(self.strides)}")
        for key in ("channels", "kernels", "strides"):
            if not all(isinstance(v, int) and v >= 1 for v in getattr(self, key)):
                raise ConfigError(f"network.{key}: must be integers ≥ 1, got {list(getattr(self, key))}")
        super().__post_init__()

    @nn.nowrap
    def initialize_carry(self, batch_size: int):
        """Zero LSTM state ``(c, h)``, or the dummy ``f32[batch_size]`` without an LSTM."""
        return lstm_carry_or_dummy(batch_size, self.lstm_size)

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """Why ``obs`` (one observation) has no image ``[H, W, C]`` (itself or its field
        ``image``) or other leaves that cannot be flattened; None if it can be read."""
        if not hasattr(obs, "shape") and not has_field(obs, "image"):
            return "neither one array nor a dict or object with a field image"
        image, rest = split_image(obs)
        if image is None or len(image.shape) != 3:
            return f"its image is {shape_text(image) if image is not None else 'not one array'}, not [H, W, C]"
        return flat_problem([image] + rest)

    @nn.compact
    def __call__(self, carry, obs, reset):
        image, rest = split_image(obs)
        x = image.astype(jnp.float32)
        for i, (features, size, stride) in enumerate(zip(self.channels, self.kernels, self.strides)):
            x = nn.relu(nn.Conv(features, (size, size), strides=(stride, stride), padding="SAME",
                                kernel_init=HIDDEN_INIT, bias_init=ZEROS, name=f"conv_{i}")(x))
        x = x.reshape(x.shape[:2] + (-1,))
        if rest:
            x = jnp.concatenate([x, flatten_obs(rest)], axis=-1)
        return lstm_and_heads(self, carry, x, reset)
