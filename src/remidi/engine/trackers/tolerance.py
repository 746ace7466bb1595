"""The tolerance tracker (``remidi.tracker=tolerance``): the exact prefix rule, with observations
compared up to a tolerance, for continuous and noisy observations.

The exact trackers (:mod:`~remidi.engine.trackers.exact`) call a prefix indistinguishable from the
earlier adversaries while ONE frozen level, stepped in lock-step with the agent's actions, has
produced exactly the agent's observations and episode ends so far. On float observations that
judgement matches nothing: a level that carries its own observation noise (a seed) never shows
another level's noise, and positions or lidar readings reached by slightly different states never
repeat bit for bit. The learned trackers read categorical observations only.

This tracker keeps the prefix rule and changes what "the same observation" means: frozen
observation ``b`` and the agent's ``a`` are the same when, leaf by leaf,

* a float leaf: every entry has ``|a − b| ≤ atol + rtol·|b|`` (numpy's ``isclose`` with ``b`` the
  frozen level's; ``a == b`` also counts, so equal infinities match);
* an integer or boolean leaf: every entry is equal;

and the episode ends (``done``) must coincide exactly. The per-level AND over the prefix is the
exact tracker's: one single frozen level must stay close at every step (a prefix close to level 1
on some steps and to level 2 on the others is distinguishable). ``atol = rtol = 0`` is exact
equality, the exact tracker's judgement bit for bit.

The tolerance is in the observation's own units (``remidi.tracker_tolerance`` is ``atol``,
``remidi.tracker_rtol`` is ``rtol``), not in units of the agent's running observation statistics:
the judgement then does not move as the policy visits other states, and the user who knows the
sensor knows its noise. It needs to be wider than the noise (two draws of one state's observation
differ by up to about ``2·3σ`` for Gaussian noise of deviation σ) and narrower than the
differences that carry information (a goal shown at another place): then levels that differ only
in their noise are one level to the tracker (a complete overlap: ReMiDi rejects them) and levels
that show something else are not. Too wide, and a later buffer rejects levels the agent could
tell apart, if only a little (docs/tolerance.md).

Two components, as for the exact tracker: :class:`ToleranceTracker` (every frozen level stepped
beside each env) and :class:`ToleranceCandidates` (slots for the frozen levels whose first
observation is within tolerance of the env's, for a reset that ignores its key); both are the
exact components with :meth:`compare` overridden.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp

from remidi.engine.trackers.exact import CandidateTracker, ExactTracker


def leaf_close(a, b, atol: float, rtol: float) -> jax.Array:
    """bool[]: every entry of the agent's leaf ``a`` is within tolerance of the frozen ``b``
    (float leaves: ``|a − b| ≤ atol + rtol·|b|``, or equal; other dtypes: equal)."""
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
    """The reference tracker (every frozen level stepped) with observations compared up to
    ``atol + rtol·|frozen|``; ``mode`` as the exact tracker's."""

    atol: float = 0.0
    rtol: float = 0.0

    def compare(self, obs_f, obs) -> jax.Array:
        return close_to(obs_f, obs, self.atol, self.rtol)

    def at_first_observation(self) -> ToleranceTracker:
        return ToleranceTracker(mode=self.mode, atol=self.atol, rtol=self.rtol)


@dataclass(frozen=True)
class ToleranceCandidates(CandidateTracker, ToleranceTracker):
    """The candidate tracker (``budget`` slots per env: the frozen levels whose first observation
    is within tolerance of the env's) with :class:`ToleranceTracker`'s comparison (``compare`` and
    ``at_first_observation`` come from it: the candidate tracker defines neither)."""


def make_tolerance_tracker(budget: int, atol: float, rtol: float) -> ExactTracker:
    """The tolerance tracker with ``budget`` candidate slots per env (0: every frozen level)."""
    if budget > 0:
        return ToleranceCandidates(budget=budget, atol=float(atol), rtol=float(rtol))
    return ToleranceTracker(atol=float(atol), rtol=float(rtol))
