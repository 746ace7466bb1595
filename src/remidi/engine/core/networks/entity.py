"""A permutation-invariant actor-critic over entities (``network=entity``), as Kinetix's agents
read its ``symbolic_entity`` observations (Matthews et al., ICLR 2025; ``kinetix/models/``).

The observation (docs/extending.md, *Entity observations*), per env::

    {"entities": {group: {"features": f32[n_g, F_g], "mask": bool[n_g]}, ...}, "globals": f32[G]}

(``globals`` optional; in the network every leaf has ``[T, N]`` in front). Each group (an entity
type) has its own embedding MLP; a masked row is zeroed before it (so its features, even NaN,
never reach the output) and counts for nothing after it. Then, over the valid entities of all
groups together:

- ``encoder="attention"`` (default): ``depth`` pre-LayerNorm blocks, each masked multi-head
  self-attention (a padded entity is no key) and one linear layer, both residual; then pooling;
- ``encoder="pool"``: pooling of the embeddings themselves (a deep set).

Pooling is ``pool="mean"`` (default) or ``"max"`` over the valid entities; with none, zeros. No
position enters anywhere, so the output does not depend on the order of a group's rows. The
pooled vector, concatenated with the embedded ``globals``, feeds an optional LSTM and the heads.

Defaults are Kinetix's entity agent's where it has one (its 2.0.2 ``model-transformer.yaml`` and
``model-base.yaml``): the transformer, its default for ``symbolic_entity`` (``permutation_invariant_mlp``
false); ``depth`` 2 (``transformer_depth``), ``num_heads`` 8, ``qkv_features`` 16
(``transformer_size``), ``embed`` 128 (``transformer_encoder_size``), one Dense + activation per
entity type with the type appended (Kinetix: a 1-d id for shapes, a one-hot of 4 in its
permutation-invariant MLP; here a one-hot of the groups), one linear layer after attention
(``transformer_ffn`` false), mean pooling over the valid entities (``aggregate_mode`` ``dummy_and_mean``
without the dummy token), tanh, 128-unit heads (``fc_layer_width``), no recurrence
(``recurrent_model`` false). Departures: a plain residual instead of Kinetix's GRU-style gating,
one hidden layer per head instead of five, no attention graph over joints and no message passing
along joints and thrusters (an entity observation here carries no such indices: attention sees
every valid entity).
"""

from __future__ import annotations

from collections.abc import Mapping

import flax.linen as nn
import jax.numpy as jnp

from remidi.engine.core.networks.base import (ACTIVATIONS, dense, has_field, lstm_and_heads, lstm_carry_or_dummy,
                                              obs_field, shape_text)
from remidi.errors import ConfigError, choice

ENCODERS = ("attention", "pool")
POOLS = ("mean", "max")


def masked_pool(x, mask, how: str):
    """``x`` ``f32[..., n, D]`` pooled over its valid rows (``mask`` ``bool[..., n]``) by ``how``
    (``"mean"`` or ``"max"``): ``f32[..., D]``, zeros where no row is valid."""
    valid = mask[..., None]
    count = jnp.sum(valid, axis=-2)
    if how == "mean":
        return jnp.sum(jnp.where(valid, x, 0.0), axis=-2) / jnp.maximum(count, 1)
    lowest = jnp.finfo(x.dtype).min
    return jnp.where(count > 0, jnp.max(jnp.where(valid, x, lowest), axis=-2), 0.0)


def entity_groups(obs) -> list[tuple[str, object, object]]:
    """``(name, features, mask)`` of each group of an entity observation, in sorted name order."""
    groups = obs_field(obs, "entities")
    return [(name, obs_field(groups[name], "features"), obs_field(groups[name], "mask")) for name in sorted(groups)]


class EntityActorCritic(nn.Module):
    """Entities (grouped by type, masked) -> embedding per group -> masked self-attention or
    nothing -> masked pooling, with the embedded globals -> optional LSTM -> heads (module
    docstring). Carry: ``(c, h)`` each ``f32[N, lstm_size]``, or a dummy ``f32[N]`` with
    ``lstm_size`` 0."""

    reads = "entities {group: {features f32[n, F], mask bool[n]}} and optionally globals f32[G] (docs/extending.md)"

    num_actions: int
    encoder: str = "attention"
    pool: str = "mean"
    embed: int = 128
    group_layers: int = 1
    depth: int = 2
    num_heads: int = 8
    qkv_features: int = 16
    lstm_size: int = 0
    head_hidden: int = 128
    activation: str = "tanh"
    continuous: bool = False

    def __post_init__(self):
        choice("network.encoder", self.encoder, ENCODERS)
        choice("network.pool", self.pool, POOLS)
        for key in ("embed", "group_layers", "num_heads", "qkv_features", "head_hidden"):
            if not (isinstance(getattr(self, key), int) and getattr(self, key) >= 1):
                raise ConfigError(f"network.{key}: must be an integer ≥ 1, got {getattr(self, key)!r}")
        if self.qkv_features % self.num_heads:
            raise ConfigError(f"network.qkv_features: must be a multiple of num_heads ({self.num_heads}), "
                              f"got {self.qkv_features}")
        super().__post_init__()

    @nn.nowrap
    def initialize_carry(self, batch_size: int):
        """Zero LSTM state ``(c, h)``, or the dummy ``f32[batch_size]`` without an LSTM."""
        return lstm_carry_or_dummy(batch_size, self.lstm_size)

    @nn.nowrap
    def check_observation(self, obs) -> str | None:
        """Why ``obs`` (one observation) does not follow the entity convention; None if it does."""
        if not isinstance(obs, Mapping) or "entities" not in obs:
            return "not a dict with a key entities"
        extra = sorted(set(obs) - {"entities", "globals"})
        if extra:
            return f"it has keys other than entities and globals: {', '.join(map(str, extra))}"
        groups = obs["entities"]
        if not isinstance(groups, Mapping) or not groups:
            return "its entities is not a dict of one or more groups"
        if len(groups) >= self.embed:
            return f"it has {len(groups)} groups, embed ({self.embed}) must exceed their number"
        for name, group in groups.items():
            if not (isinstance(group, Mapping) and has_field(group, "features") and has_field(group, "mask")):
                return f"its group {name} is not a dict with features and mask"
            features, mask = group["features"], group["mask"]
            if len(features.shape) != 2 or features.shape[1] < 1:
                return f"its group {name}'s features are {shape_text(features)}, not [n, F] with F ≥ 1"
            if mask.shape != features.shape[:1] or mask.dtype != bool:
                return f"its group {name}'s mask is {shape_text(mask)}, not bool[{features.shape[0]}]"
        if "globals" in obs and len(obs["globals"].shape) != 1:
            return f"its globals are {shape_text(obs['globals'])}, not one vector [G]"
        return None

    @nn.compact
    def __call__(self, carry, obs, reset):
        act = ACTIVATIONS[self.activation]  # checked when the network is made (registry.make_network)
        groups = entity_groups(obs)
        tokens, masks = [], []
        for g, (_, features, mask) in enumerate(groups):
            x = jnp.where(mask[..., None], features.astype(jnp.float32), 0.0)  # padding never read
            for layer in range(self.group_layers):
                width = self.embed - len(groups) if layer == self.group_layers - 1 else self.embed
                x = act(dense(width, f"group{g}_{layer}")(x))
            kind = jnp.broadcast_to(jnp.eye(len(groups))[g], x.shape[:-1] + (len(groups),))
            tokens.append(jnp.concatenate([x, kind], axis=-1))
            masks.append(mask)
        x, mask = jnp.concatenate(tokens, axis=-2), jnp.concatenate(masks, axis=-1)  # [T, N, n, E], [T, N, n]
        x = jnp.where(mask[..., None], x, 0.0)
        if self.encoder == "attention":
            pairs = (mask[..., :, None] & mask[..., None, :])[..., None, :, :]  # [T, N, 1, n, n]: valid → valid
            for d in range(self.depth):
                h = nn.LayerNorm(name=f"attention_norm_{d}")(x)
                x = x + nn.MultiHeadDotProductAttention(self.num_heads, qkv_features=self.qkv_features,
                                                        out_features=self.embed, name=f"attention_{d}")(h, mask=pairs)
                x = x + nn.Dense(self.embed, name=f"dense_{d}")(nn.LayerNorm(name=f"dense_norm_{d}")(x))
        pooled = masked_pool(x, mask, self.pool)
        if has_field(obs, "globals"):
            embedded = act(dense(self.embed, "globals")(obs_field(obs, "globals").astype(jnp.float32)))
            pooled = jnp.concatenate([pooled, embedded], axis=-1)
        return lstm_and_heads(self, carry, pooled, reset)
