"""The distinguishability tracker's protocol: what the train step and the rollout ask of it.

ReMiDi needs to know, at every step of every rollout, whether the trajectory prefix so far could
have come from an earlier (frozen) adversary. A *tracker* answers that. It is chosen once, when
the run is set up (``Setup.tracker``, :func:`remidi.engine.trackers.tracker_for`), and is a static
object: its state, if it keeps one across updates, is a pytree in ``Runner.tracker``.

Per update (the train step, :mod:`remidi.engine.train`):

* :meth:`Tracker.init`: the state it carries across updates (None: nothing);
* :meth:`Tracker.frozen`: the :class:`Frozen` view of the earlier adversaries' levels a rollout
  tracks against (None while nothing is frozen, and for an adversary that freezes nothing);
* :meth:`Tracker.learn`: after a rollout, what it learns from it (a learned model);
* :meth:`Tracker.freeze`: at an adversary switch, what it freezes with the adversary;
* :meth:`Tracker.metrics` and :meth:`Tracker.audit`: what evaluation reports of it.

Per rollout step (:func:`remidi.engine.learner.rollout`, through ``frozen.tracker``):
:meth:`Tracker.reset` and :meth:`Tracker.step` wrap the environments' reset and step (by default
the plain ones, then :meth:`start` / :meth:`observe` beside them), :meth:`indistinguishable` says which
envs' prefixes are indistinguishable before each action, :meth:`overflow` what the tracker could
not follow, :meth:`buffer_match` which frozen buffer explains each prefix (ReMiDi's Combine).

Implementations: :mod:`~remidi.engine.trackers.exact` (the default: the exact prefix tracker, its
reference and candidate-slot variants, and the authors' per-step rule),
:mod:`~remidi.engine.trackers.belief` (a learned model per adversary) and
:mod:`~remidi.engine.trackers.simulated` (the frozen levels simulated with a learnt noise model).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class Frozen:
    """The frozen adversaries' levels as one batch, what a rollout tracks against: ``levels``
    leaves [F, ...], ``valid`` bool[F], buffer-major (F = B·C for B frozen buffers of capacity C).
    With ``params`` (leaves [B, ...]: the policy frozen with each buffer, ReMiDi's ``Combine``),
    a step whose prefix one of those buffers explains is acted on by the policy of the earliest
    such buffer. ``belief``: what a learned tracker reads (its frozen models, thresholds).
    ``rehearse`` (bool[], None: never): the rollout rehearses frozen levels, so no step counts as
    explained (``remidi.rehearsal``: it trains on every step). ``tracker`` (static): the
    component that steps beside the environments."""

    levels: Any
    valid: jax.Array
    params: Any = None
    belief: Any = None
    rehearse: Any = None
    tracker: Any = struct.field(pytree_node=False, default=None)


def fresh_levels(proposal) -> jax.Array:
    """bool[]: the update's levels are the task generator's fresh ones (no replay, no edit, no
    rehearsal): what a reference model of the generator's trajectories learns from."""
    fresh = ~proposal.replay
    for other in (proposal.edit, proposal.rehearse):
        fresh = fresh if other is None else fresh & ~other
    return fresh


class Tracker:
    """The protocol, with the behaviour of a tracker that keeps no state across updates (the
    exact trackers). Subclasses are frozen dataclasses: static, hashable configuration."""

    #: judges by learned models (its work grows with them; evaluation audits it against the exact tracker)
    learns = False

    # ------------------------------------------------------------------ per update
    def init(self, setup, rng):
        """The state carried across updates (``Runner.tracker``); ``rng``: the runner's key, folded."""
        return None

    def frozen(self, setup, runner, earlier) -> Frozen | None:
        """The rollout's view of the earlier adversaries' levels ``earlier = (levels [F, ...],
        valid bool[F])`` (None: nothing frozen), with the policies frozen with them under Combine."""
        if earlier is None:
            return None
        levels, valid = earlier
        return Frozen(levels=levels, valid=valid, params=runner.learner.frozen_params, tracker=self)

    def learn(self, setup, runner, proposal, traj) -> tuple[Any, dict]:
        """After the update's rollout ``traj`` of ``proposal``: ``(state, step metrics)``."""
        return runner.tracker, {}

    def freeze(self, setup, runner, switch):
        """The state after an adversary switch (``switch`` bool[]; ``runner``: after the adversary's update)."""
        return runner.tracker

    def metrics(self, setup, runner) -> dict:
        """What evaluation reports of the tracker's state."""
        return {}

    def audit(self, setup, runner, rng) -> dict:
        """Its judgement against the exact tracker's on one rollout (learned trackers)."""
        return {}

    def at_first_observation(self) -> Tracker:
        """The component that judges first observations for the combined policy at evaluation."""
        return self

    # ------------------------------------------------------------------ per rollout step
    def reset(self, envs, frozen: Frozen, reset_keys, levels):
        """The N envs reset to ``levels`` with ``reset_keys`` [N] (``envs``: the rollout's
        :class:`~remidi.engine.learner.Stepping`): ``(obs, env state, tracker state)``."""
        obs, state = jax.vmap(envs.auto.reset_to_level, in_axes=(0, 0, None))(reset_keys, levels, envs.params)
        return obs, state, self.start(envs.tracker_env, envs.params, frozen, reset_keys, obs)

    def step(self, envs, frozen: Frozen, env_keys, state, tstate, action):
        """One step of the N envs with ``env_keys`` [N], and the tracker beside them:
        ``(next_obs, env state, reward, done, tracker state)``."""
        next_obs, state, reward, done, _ = jax.vmap(envs.auto.step, in_axes=(0, 0, 0, None))(
            env_keys, state, action, envs.params)
        tstate = self.observe(envs.tracker_env, envs.params, frozen, env_keys, tstate, action, next_obs, done)
        return next_obs, state, reward, done, tstate

    def start(self, env, params, frozen, reset_keys, obs, starts=None):
        raise NotImplementedError

    def observe(self, env, params, frozen, env_keys, state, action, next_obs, done):
        raise NotImplementedError

    def indistinguishable(self, state) -> jax.Array:
        raise NotImplementedError

    def overflow(self, state) -> jax.Array:
        """i32[N]: frozen levels the tracker could not follow (none by default)."""
        return jnp.zeros(jax.tree.leaves(state)[0].shape[:1], jnp.int32)

    def buffer_match(self, state, num_buffers: int, capacity: int) -> jax.Array:
        """bool[N, B]: frozen buffer b explains env n's prefix (Combine)."""
        return state.match[:, :num_buffers]
