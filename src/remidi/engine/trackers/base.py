"""The distinguishability tracker's protocol.

At every rollout step ReMiDi asks whether the prefix so far could have come from a frozen
adversary; a tracker answers. It is a static object chosen at set-up (``Setup.tracker``); any
state it keeps across updates is a pytree in ``Runner.tracker``.

Per update: :meth:`Tracker.init`, :meth:`Tracker.frozen` (the :class:`Frozen` view a rollout
tracks against; None: nothing frozen), :meth:`Tracker.learn`, :meth:`Tracker.freeze` (at a
switch), :meth:`Tracker.metrics`, :meth:`Tracker.audit`.

* :meth:`Tracker.init`: the state it carries across updates (None: nothing);
* 
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
    """The frozen adversaries' levels as one batch, what a rollout tracks against.

    ``levels`` leaves [F, ...], ``valid`` bool[F], buffer-major (F = B·C). ``params`` (leaves
    [B, ...]; Combine): a step some buffer explains is acted on by the earliest such buffer's policy.
    ``belief``: a learned tracker's frozen models. ``rehearse`` (bool[]; None: never): no step counts
    as explained. ``tracker`` (static): the component stepping beside the envs."""

    levels: Any
    valid: jax.Array
    params: Any = None
    belief: Any = None
    rehearse: Any = None
    tracker: Any = struct.field(pytree_node=False, default=None)


def fresh_levels(proposal) -> jax.Array:
    """bool[]: the update's levels are the generator's fresh ones (no replay, edit or rehearsal)."""
    fresh = ~proposal.replay
    for other in (proposal.edit, proposal.rehearse):
        fresh = fresh if other is None else fresh & ~other
    return fresh


class Tracker:
    """The protocol, with a stateless tracker's behaviour. Subclasses are frozen dataclasses (static)."""

    #: judges by learned models (its work grows with them; evaluation audits it against the exact tracker)
    learns = False

    # ------------------------------------------------------------------ per update
    def init(self, setup, rng):
        """The state carried across updates (``Runner.tracker``); ``rng``: the runner's key, folded."""
        return None

    def frozen(self, setup, runner, proposal=None) -> Frozen | None:
        """The rollout's view of the sequence's frozen levels: every buffer before the active one
        (``runner.adversary``'s buffers, leaves [K, C, ...]) as one batch of F = (K−1)·C,
        buffer-major, with the policies frozen with them under Combine; None with fewer than two
        buffers. On a rehearsal (``proposal.rehearse``) the rollout explains no step: its levels
        are frozen levels, and rehearsal trains on every step to keep what they taught."""
        if setup.cfg.remidi.num_buffers < 2:
            return None
        state = runner.adversary
        buffers = jax.tree.map(lambda x: x[:-1], state.buffers)  # the last buffer is never frozen
        valid = buffers.valid & (jnp.arange(buffers.valid.shape[0]) < state.active)[:, None]
        levels = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), buffers.levels)
        return Frozen(levels=levels, valid=valid.reshape(-1), params=runner.learner.frozen_params, tracker=self,
                      rehearse=None if proposal is None else proposal.rehearse)

    def learn(self, setup, runner, proposal, traj) -> tuple[Any, dict]:
        """After the update's rollout ``traj`` of ``proposal``: ``(state, step metrics)``."""
        return runner.tracker, {}

    def freeze(self, setup, runner, switch):
        """The state after a switch (``switch`` bool[]; ``runner`` after the adversary's update)."""
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
        :class:`~remidi.engine.learner.Stepping`): ``(obs, the environment's state, tracker state)``."""
        obs, state = jax.vmap(envs.raw.reset_to_level, in_axes=(0, 0, None))(reset_keys, levels, envs.params)
        return obs, state, self.start(envs.tracker_env, envs.params, frozen, reset_keys, obs)

    def step(self, envs, frozen: Frozen, env_keys, state, tstate, action):
        """``(next_obs, env state, reward, done, tracker state)``: one step with ``env_keys`` [N]."""
        keys = jax.vmap(jax.random.split)(env_keys)  # each env's key: step, restart (as the rollout's own)
        stepped = jax.vmap(envs.raw.step, in_axes=(0, 0, 0, None))(keys[:, 0], state.env_state, action, envs.params)
        next_obs, state, reward, done, _ = envs.restart_where_done(state, stepped, keys[:, 1])
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
