"""The tolerance tracker (``remidi.tracker=tolerance``): the exact prefix rule with observations
compared up to a tolerance, for continuous and noisy observations (exact equality never matches
them; the learned trackers read categorical observations only).

Frozen observation ``b`` and the agent's ``a`` are the same when, leaf by leaf, every float entry
has ``|a − b| ≤ atol + rtol·|b|`` (or ``a == b``: equal infinities match) and every integer or
boolean entry is equal; episode ends must coincide exactly. As in the exact tracker one single
frozen level must stay close at every step. ``atol = rtol = 0`` is the exact tracker bit for bit.

Units are the observation's own (``remidi.tracker_tolerance`` = atol, ``remidi.tracker_rtol`` =
rtol), not the running statistics', so the judgement does not drift with the policy. It should
be wider than the noise (about ``2·3σ`` for Gaussian σ) and narrower than informative differences;
too wide, and a later buffer rejects levels the agent could tell apart (docs/tolerance.md)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.engine.trackers.exact import CandidateTracker, ExactTracker


def leaf_close(a, b, atol: float, rtol: float) -> jax.Array:
    """bool[]: every entry of leaf ``a`` is within tolerance of the frozen ``b`` (non-floats: equal)."""
    if not (jnp.issubdtype(jnp.result_type(a), jnp.inexact) or jnp.issubdtype(jnp.result_type(b), jnp.inexact)):
        return jnp.all(a == b)
    return jnp.all((a == b) | (jnp.abs(a - b) <= atol + rtol * jnp.abs(b)))


def tree_close(a, b, atol: float, rtol: float) -> jax.Array:
    """bool[]: every leaf of observation ``a`` is :func:`leaf_close` to ``b``'s."""
    leaves = jax.tree.leaves(jax.tree.map(functools.partial(leaf_close, atol=atol, rtol=rtol), a, b))
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


def close_to(obs_f, obs, atol: float, rtol: float) -> jax.Array:
    """bool[F]: frozen observation f (leaves [F, ...]) is within tolerance of the agent's ``obs``."""
    return jax.vmap(lambda b: tree_close(obs, b, atol, rtol))(obs_f)


@dataclass(frozen=True)
class ToleranceTracker(ExactTracker):
    """The reference tracker (every frozen level stepped) comparing up to ``atol + rtol·|frozen|``."""

    atol: float = 0.0
    rtol: float = 0.0

    def compare(self, obs_f, obs) -> jax.Array:
        return close_to(obs_f, obs, self.atol, self.rtol)

    def at_first_observation(self) -> ToleranceTracker:
        return ToleranceTracker(mode=self.mode, atol=self.atol, rtol=self.rtol)


@dataclass(frozen=True)
class ToleranceCandidates(CandidateTracker, ToleranceTracker):
    """The candidate tracker (``budget`` slots per env) with :class:`ToleranceTracker`'s comparison."""


def make_tolerance_tracker(budget: int, atol: float, rtol: float) -> ExactTracker:
    """The tolerance tracker with ``budget`` candidate slots per env (0: every frozen level)."""
    if budget > 0:
        return ToleranceCandidates(budget=budget, atol=float(atol), rtol=float(rtol))
    return ToleranceTracker(atol=float(atol), rtol=float(rtol))
