"""Kinetix's observations as the agent reads them, and its action types (components chosen at set-up).

Observations (``kinetix.observation``): ``symbolic_flat`` (Kinetix's ``SYMBOLIC_FLAT``, ``f32[D]``,
D = 140 on size s, for ``mlp``); ``entity`` (``SYMBOLIC_ENTITY`` as remidi's entity convention,
:func:`entity_observation`).

Actions (``kinetix.actions``): ``discrete`` (``DISCRETE``, ``Discrete(11)`` on size s: motor
binding × direction, thruster, or nothing); ``multi_discrete`` (Kinetix's default, one choice per
motor and thruster binding: ``MultiDiscrete((3, 3, 3, 3, 2, 2))`` on size s; all-zero: no-op)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp

from remidi.envs.actions import Discrete, from_env_space

SHAPE_GROUPS = ("polygons", "circles")


def entity_observation(obs: Any) -> dict:
    """Kinetix's ``EntityObservation`` as ``{"entities": {group: {"features": f32[n_g, F_g], "mask": bool[n_g]}}}``.

    * ``polygons`` ``f32[P, 27 + 2(P+C)]``, ``circles`` ``f32[C, 19 + 2(P+C)]``: shape features, then
      the shape's rows of two attention masks over the P + C shapes (joined by joints; touching now);
    * ``joints`` ``f32[2J, 22 + 2(P+C)]``: features (each joint both ways), one-hots of its two shapes;
    * ``thrusters`` ``f32[T, 8 + P+C]``: features, one-hot of its shape;

    each with Kinetix's active mask. The other two mask views add nothing. Unbatched."""
    num_polygons = obs.polygons.shape[0]
    num_shapes = num_polygons + obs.circles.shape[0]
    relations = jnp.concatenate([obs.attention_mask[1], obs.attention_mask[3]], axis=-1).astype(jnp.float32)
    one_hot = lambda index: jax.nn.one_hot(index, num_shapes, dtype=jnp.float32)  # noqa: E731
    links = jnp.concatenate([one_hot(obs.joint_indexes[:, 0]), one_hot(obs.joint_indexes[:, 1])], axis=-1)
    groups = {
        "polygons": (jnp.concatenate([obs.polygons, relations[:num_polygons]], -1), obs.polygon_mask),
        "circles": (jnp.concatenate([obs.circles, relations[num_polygons:]], -1), obs.circle_mask),
        "joints": (jnp.concatenate([obs.joints, links], -1), obs.joint_mask),
        "thrusters": (jnp.concatenate([obs.thrusters, one_hot(obs.thruster_indexes)], -1), obs.thruster_mask),
    }
    return {"entities": {name: {"features": features.astype(jnp.float32), "mask": mask.astype(bool)}
                         for name, (features, mask) in groups.items()}}


@dataclass(frozen=True)
class Observation:
    """An observation component: Kinetix's ``ObservationType`` name and ``adapt`` (env output → network input)."""

    kinetix_type: str
    adapt: Callable[[Any], Any]


@dataclass(frozen=True)
class Actions:
    """An action component: Kinetix's ``ActionType`` name and ``declare`` (its space → ``UEDTask.action_space``)."""

    kinetix_type: str
    declare: Callable[[Any], Any]


OBSERVATIONS = {
    "symbolic_flat": Observation("SYMBOLIC_FLAT", lambda obs: obs),
    "entity": Observation("SYMBOLIC_ENTITY", entity_observation),
}
ACTIONS = {"discrete": Actions("DISCRETE", lambda space: Discrete(int(space.n))),
           "multi_discrete": Actions("MULTI_DISCRETE", from_env_space)}
