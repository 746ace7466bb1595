"""Kinetix's observations as the agent reads them, and its action types.

An *observation* component turns what Kinetix's environment returns into what remidi's network
reads; each is chosen once at set-up (``kinetix.observation``):

* ``symbolic_flat``: Kinetix's ``SYMBOLIC_FLAT`` vector (``f32[D]``, D = 140 on size s), read by
  the ``mlp`` network as it is;
* ``entity``: Kinetix's ``SYMBOLIC_ENTITY`` observation (an ``EntityObservation``) as remidi's
  entity convention, ``{"entities": {group: {"features": f32[n, F], "mask": bool[n]}}}``
  (:func:`entity_observation`), for a network over sets of entities.

An *action* component names Kinetix's action type and declares the task's action space
(``kinetix.actions``, :mod:`remidi.envs.actions`): ``discrete`` is Kinetix's ``DISCRETE``
(``Discrete(11)`` on size s: a motor binding and direction, a thruster binding, or nothing:
2·4 + 2 + 1); ``multi_discrete`` is Kinetix's default ``MULTI_DISCRETE``, one choice per motor
binding (forward, backward, off) and per thruster binding (on, off): ``MultiDiscrete((3, 3, 3,
3, 2, 2))`` on size s, its all-zero action the no-op.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp

from remidi.envs.actions import Discrete, from_env_space

SHAPE_GROUPS = ("polygons", "circles")


def entity_observation(obs: Any) -> dict:
    """Kinetix's ``EntityObservation`` (P polygons, C circles, J joints, T thrusters) as
    ``{"entities": {group: {"features": f32[n_g, F_g], "mask": bool[n_g]}}}``, keeping what the
    observation says:

    * ``polygons`` ``f32[P, 27 + 2(P+C)]``, ``circles`` ``f32[C, 19 + 2(P+C)]``: Kinetix's shape
      features (gravity included), then the shape's rows of two of Kinetix's attention masks over
      the P + C shapes (polygons first): the shapes it is connected to through joints, and the
      shapes it touches now;
    * ``joints`` ``f32[2J, 22 + 2(P+C)]``: Kinetix's joint features (each joint twice, a→b and
      b→a), then one-hots of the two shapes it links;
    * ``thrusters`` ``f32[T, 8 + P+C]``: Kinetix's thruster features, then a one-hot of its shape;

    each with Kinetix's mask (the entity is active). The masks' remaining two views (every active
    shape; one-hop joint links) are what the masks and the joints' one-hots already say. No batch
    axis; vmap it for a batch."""
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
    """An observation component: Kinetix's ``ObservationType`` (its name) and ``adapt``, what
    the environment returns → what the network reads (unbatched)."""

    kinetix_type: str
    adapt: Callable[[Any], Any]


@dataclass(frozen=True)
class Actions:
    """An action component: Kinetix's ``ActionType`` (its name) and ``declare``, Kinetix's action
    space → the task's action space (``UEDTask.action_space``)."""

    kinetix_type: str
    declare: Callable[[Any], Any]


OBSERVATIONS = {
    "symbolic_flat": Observation("SYMBOLIC_FLAT", lambda obs: obs),
    "entity": Observation("SYMBOLIC_ENTITY", entity_observation),
}
ACTIONS = {"discrete": Actions("DISCRETE", lambda space: Discrete(int(space.n))),
           "multi_discrete": Actions("MULTI_DISCRETE", from_env_space)}
