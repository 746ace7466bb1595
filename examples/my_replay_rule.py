"""A replay rule of your own, registered without editing the library: ``proportional``.

    REMIDI_PLUGINS=my_replay_rule PYTHONPATH=examples remidi run lever --algo plr \\
        --set buffer.prioritization=proportional

PLR's second prioritisation (Jiang et al., 2021): a level is replayed in proportion to its score
raised to 1/temperature, instead of by its rank. The buffer normalises the weights over its valid
levels and mixes them with staleness, ``(1-ρ)·rule + ρ·staleness``, as for ``rank`` and ``topk``.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp

import remidi
from remidi.engine.adversaries.level_buffer import ReplayRule


@dataclass(frozen=True)
class ProportionalReplay(ReplayRule):
    """Weight ∝ max(score, 0)^(1/temperature); a NaN or −inf score weighs nothing."""

    def weights(self, state, config, ranks):
        score = jnp.where(jnp.isfinite(state.scores), jnp.maximum(state.scores, 0.0), 0.0)
        return score ** (1.0 / config.temperature)


remidi.register_replay_rule("proportional", ProportionalReplay())
