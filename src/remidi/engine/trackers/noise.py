"""The simulated tracker's noise model: a table q(o | d, ô¹, ô²) per observation entry, learnt by
counting (agent, copy, copy) triples of one level played three times with the same actions (the
copies under fresh draws of its randomness, ``UEDTask.reseed_level``), and the mixture over a
frozen buffer's levels that scores a prefix with it.

Shapes: E coded entries plus the end entry (E + 1), K categories, F frozen levels, S slots per
env, T steps, N envs."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from remidi.engine.trackers.belief_model import ObsCoding

SMOOTHING = 0.1  # the noise table's Dirichlet prior per cell (log_q)


# ---------------------------------------------------------------------------- the noise table
def init_counts(coding: ObsCoding) -> jax.Array:
    """f32[E + 1, 2, K, K, K]: no triple counted yet (``[e, d, ô¹, ô², o]``)."""
    k = max(coding.num_categories, 2)
    return jnp.zeros((coding.num_entries + 1, 2, k, k, k), jnp.float32)


def agree(sim1, sim2) -> jax.Array:
    """i32[...]: 1 where copies ``sim1``, ``sim2`` i32[..., E + 1] agree on every entry."""
    return jnp.all(sim1 == sim2, axis=-1).astype(jnp.int32)


def count_triples(counts, agent, sim1, sim2, mask=None) -> jax.Array:
    """``counts`` plus the triples ``(agent, sim1, sim2)`` (i32[..., E + 1]) where ``mask`` bool[...] (None: all)."""
    d = agree(sim1, sim2)
    e = jnp.broadcast_to(jnp.arange(agent.shape[-1]), agent.shape)
    weight = jnp.ones(agent.shape[:-1]) if mask is None else mask.astype(jnp.float32)
    weight = jnp.broadcast_to(weight[..., None], agent.shape)
    dd = jnp.broadcast_to(d[..., None], agent.shape)
    return counts.at[e, dd, sim1, sim2, agent].add(weight)


def log_q(counts, smoothing: float = 0.1) -> jax.Array:
    """f32[E + 1, 2, K, K, K]: log q(o | d, ô¹, ô²), frequencies plus ``smoothing`` per cell (unseen: uniform)."""
    k = counts.shape[-1]
    return jnp.log((counts + smoothing) / (jnp.sum(counts, axis=-1, keepdims=True) + smoothing * k))


def step_logq(logq, agent, sim1, sim2) -> jax.Array:
    """f32[...]: log q of ``agent`` i32[..., E + 1] given copies ``sim1``, ``sim2``, summed over entries."""
    agent, sim1, sim2 = jnp.broadcast_arrays(agent, sim1, sim2)
    d = jnp.broadcast_to(agree(sim1, sim2)[..., None], agent.shape)
    e = jnp.broadcast_to(jnp.arange(agent.shape[-1]), agent.shape)
    return jnp.sum(logq[e, d, sim1, sim2, agent], axis=-1)


def with_end(coding: ObsCoding, obs, ended) -> jax.Array:
    """i32[..., E + 1]: ``obs`` coded plus the end entry (``ended`` bool[...]: the step before ended an episode)."""
    return jnp.concatenate([coding.encode(obs), jnp.asarray(ended, jnp.int32)[..., None]], axis=-1)


# ---------------------------------------------------------------------------- simulating a level
def replay_level(env, params, coding: ObsCoding, level, actions, resets, key) -> jax.Array:
    """i32[T, E + 1]: ``level`` replayed with ``actions`` i32[T], restarting where ``resets`` bool[T].

    Coded with the end entry. The reset must ignore its key; ``key``: the steps' randomness."""
    obs0, state0 = env.reset_to_level(key, level, params)

    def body(carry, inp):
        state, k = carry
        action, restart = inp
        k, ks = jax.random.split(k)
        obs, nstate, _, done, _ = env.step(ks, state, action, params)
        obs = jax.tree.map(lambda a, b: jnp.where(restart, a, b), obs0, obs)
        state = jax.tree.map(lambda a, b: jnp.where(restart, a, b), state0, nstate)
        return (state, k), with_end(coding, obs, done)  # the end entry: this copy's own end

    # step t's observation follows action t − 1 (or the agent's restart at t)
    _, later = jax.lax.scan(body, (state0, key), (actions[:-1], resets[1:]))
    return jnp.concatenate([with_end(coding, obs0, False)[None], later])


def recorded_codes(coding: ObsCoding, obs, resets) -> jax.Array:
    """i32[T, N, E + 1]: a rollout's ``obs`` (leaves [T, N, ...]) coded with the end entry."""
    ended = resets.at[0].set(False)
    return with_end(coding, obs, ended)


def count_rollout(counts, env, params, coding: ObsCoding, reseed, levels, traj, key) -> jax.Array:
    """``counts`` with a rollout's triples: each env's level (``levels`` leaves [N, ...]) replayed
    twice with the rollout's (``traj``: a :class:`~remidi.engine.learner.Trajectory`)
    actions i32[T, N] and resets bool[T, N], each copy's randomness drawn afresh (``reseed(key,
    level) -> level``, or None: the level as it is), beside the agent's observations (leaves
    [T, N, ...])."""
    obs, actions, resets = traj.obs, traj.action, traj.reset
    n = actions.shape[1]

    def copies(level, acts, rs, k):
        k1, k2, k3 = jax.random.split(k, 3)
        l1, l2 = (level, level) if reseed is None else (reseed(k1, level), reseed(k2, level))
        return (replay_level(env, params, coding, l1, acts, rs, k3),
                replay_level(env, params, coding, l2, acts, rs, k3))

    s1, s2 = jax.vmap(copies, in_axes=(0, 1, 1, 0), out_axes=1)(levels, actions, resets, jax.random.split(key, n))
    return count_triples(counts, recorded_codes(coding, obs, resets), s1, s2)


# ---------------------------------------------------------------------------- scoring a prefix
def mixture(totals, index, valid, num_buffers: int, capacity: int) -> jax.Array:
    """f32[B]: log mean over each frozen buffer's valid levels of P(prefix | θ).

    From the slots' log-likelihoods ``totals`` f32[S] (``index`` i32[S], −1 empty; ``valid``
    bool[F], buffer-major). Levels without a slot count as 0 (not among the likeliest at the start)."""
    owner = jnp.where(index >= 0, index // capacity, -1)
    mine = owner[None, :] == jnp.arange(num_buffers)[:, None]  # [B, S]
    total = jax.nn.logsumexp(jnp.where(mine, totals[None, :], -jnp.inf), axis=-1)
    n_valid = jnp.sum(valid.reshape(num_buffers, capacity), axis=-1)
    return jnp.where(n_valid > 0, total - jnp.log(jnp.maximum(n_valid, 1)), -jnp.inf)


def candidates(logq, first_agent, first1, first2, valid, budget: int):
    """``(index i32[S], log q f32[S])``: the ``budget`` frozen levels making ``first_agent`` likeliest.

    From their copies' first observations ``first1``, ``first2`` i32[F, E + 1]; highest first, ties
    by index; −1 for an empty slot (no valid level, or log q −inf)."""
    lq = step_logq(logq, first_agent[None], first1, first2)  # [F]
    lq = jnp.where(valid, lq, -jnp.inf)
    top, index = jax.lax.top_k(lq, budget)
    index = jnp.where(jnp.isfinite(top), index, -1)
    return index.astype(jnp.int32), top
