"""Evaluation of a trained agent: the first-episode returns of sampled attempts on levels, and
the metrics of a task's evaluation sets (solve rate, return, discounted return, regret)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from remidi.engine.adversaries import scores as sc
from remidi.engine.core.distributions import acting
from remidi.engine.learner import Policy, Stepping, combine, combines, policy_apply, rollout
from remidi.engine.run.buffer_eval import buffer_solve_rates
from remidi.engine.setup import Setup
from remidi.engine.train import Runner
from remidi.envs.interface import UEDTask


def first_episode_return(reward: jax.Array, done: jax.Array, gamma: float = 1.0) -> jax.Array:
    """f32[N]: return of each env's first episode (``reward``, ``done`` [T, N]), discounted Σ_t γ^t r_t
    for ``gamma`` < 1."""
    ended_before = jnp.cumsum(done, axis=0) - done  # episodes finished before step t
    discount = jnp.power(jnp.float32(gamma), jnp.arange(reward.shape[0], dtype=jnp.float32))[:, None]
    return jnp.sum(jnp.where(ended_before == 0, discount * reward, 0.0), axis=0)


def first_episode_flag(done: jax.Array, flags: jax.Array) -> jax.Array:
    """bool[N]: ``flags`` bool[T, N] at the last step of each env's first episode; False if it did not end."""
    first_end = done & (jnp.cumsum(done, axis=0) - done == 0)
    return jnp.any(first_end & flags, axis=0)


def eval_groups(task: UEDTask) -> list[tuple[object, list[str]]]:
    """The evaluation sets grouped by the env that plays them (one rollout per group), names sorted."""
    groups: list[tuple[object, list[str]]] = []
    for name in sorted(task.eval_sets):
        env = task.eval_envs.get(name, task.env)
        for genv, names in groups:
            if genv is env:
                names.append(name)
                break
        else:
            groups.append((env, [name]))
    return groups


def first_step_policy(setup: Setup, runner: Runner, env, levels, action: str = "sample") -> jax.Array:
    """f32[L, A]: the action probabilities at the first step of each level (leaves [L, ...]) of
    the policy that acts there (under ``remidi.policy=combine``, the combined policy:
    :func:`~remidi.engine.learner.combine`); with ``action="mode"`` one-hot on its most
    likely action."""
    task, net = setup.task, setup.net
    n = jax.tree.leaves(levels)[0].shape[0]
    keys = jax.random.split(jax.random.PRNGKey(0), n)
    obs, _ = jax.vmap(env.reset_to_level, in_axes=(0, 0, None))(keys, levels, task.params)
    obs_in, reset = jax.tree.map(lambda x: x[None], obs), jnp.ones((n,), bool)
    apply_fn = policy_apply(setup, runner.learner)
    carry = net.initialize_carry(n)
    _, (logits, _) = apply_fn({"params": runner.learner.train_state.params}, carry, obs_in, reset[None])
    logits = logits[0]
    if combines(setup):
        # every frozen level stepped at the first observation: the tracker's reference (the exact
        # trackers' reference tracker; a learned tracker judges the first observation itself)
        frozen = setup.tracker.frozen(setup, runner)
        frozen = frozen.replace(tracker=frozen.tracker.at_first_observation())
        tstate = frozen.tracker.start(task.env, task.params, frozen, keys, obs)
        copies = jax.tree.leaves(frozen.params)[0].shape[0]
        frozen_carry = jax.tree.map(lambda x: jnp.broadcast_to(x, (copies,) + x.shape), carry)
        _, logits = combine(frozen, tstate, apply_fn, frozen_carry, obs_in, reset, logits)
    return acting(setup.dist, action).probs(logits)


def level_returns(setup: Setup, runner: Runner, env, levels, attempts: int, rng, action: str = "sample"):
    """:func:`level_episodes`' ``(returns, discounted)``."""
    return level_episodes(setup, runner, env, levels, attempts, rng, action)[:2]


def level_episodes(setup: Setup, runner: Runner, env, levels, attempts: int, rng, action: str = "sample"):
    """``(returns, discounted, flags)`` f32/bool[L, attempts]: first-episode results of ``attempts``
    episodes on each of ``levels`` (leaves [L, ...]).

    One rollout of ``task.max_episode_steps`` on L·attempts envs; actions sampled, or the mode with
    ``action="mode"``; the combined policy under ``remidi.policy=combine``. ``discounted`` uses
    ``ppo.gamma``; ``flags``: the last-step info flag where ``solved`` names an info key, else None
    (judge with :func:`~remidi.engine.adversaries.scores.episode_solved`)."""
    task = setup.task
    frozen = setup.tracker.frozen(setup, runner) if combines(setup) else None  # act as the combined policy
    tiled = jax.tree.map(lambda x: jnp.repeat(x, attempts, axis=0), levels)  # each level's attempts side by side
    n = jax.tree.leaves(tiled)[0].shape[0]
    traj, _ = rollout(rng, Stepping(env, task.params, task.deterministic_reset, tracker_env=task.env,
                                    solved_info=sc.info_key(task.solved)),
                      Policy(policy_apply(setup, runner.learner), runner.learner.train_state.params,
                             setup.net.initialize_carry(n)),
                      tiled, task.max_episode_steps, frozen, dist=acting(setup.dist, action))
    returns = first_episode_return(traj.reward, traj.done).reshape(-1, attempts)
    discounted = first_episode_return(traj.reward, traj.done, setup.cfg.ppo.gamma).reshape(-1, attempts)
    flags = None if traj.solved is None else first_episode_flag(traj.done, traj.solved).reshape(-1, attempts)
    return returns, discounted, flags


def evaluate(setup: Setup, runner: Runner, rng, action: str = "sample") -> dict[str, jax.Array]:
    """Metrics on each evaluation set: ``solve_rate/<set>``, ``return/<set>``, ``discounted_return/<set>``.

    ``eval_attempts`` first episodes per level, acting by ``action``. With an optimal return:
    ``regret/<set>/mean`` and ``/worst`` of the expected regret ``optimal − E[return]``
    (undiscounted), exact with the task's ``expected_return`` (which adds ``entropy/<set>``), else
    estimated from the episodes. Plus :func:`buffer_solve_rates`."""
    task, cfg = setup.task, setup.cfg
    out = {}
    for i, (env, names) in enumerate(eval_groups(task)):
        levels = jax.tree.map(lambda *xs: jnp.concatenate(xs), *(task.eval_sets[name] for name in names))
        returns, discounted, flags = level_episodes(setup, runner, env, levels, cfg.eval_attempts,
                                                    jax.random.fold_in(rng, i), action)
        optimal = None
        if task.optimal_return is not None:  # once for the group's sets (for mazes, a search per level)
            optimal = jax.vmap(task.optimal_return)(levels)
        start = 0
        for name in names:
            set_levels = task.eval_sets[name]
            count = jax.tree.leaves(set_levels)[0].shape[0]
            ret, set_discounted = returns[start:start + count], discounted[start:start + count]  # [count, attempts]
            set_optimal = None if optimal is None else optimal[start:start + count]
            set_flags = None if flags is None else flags[start:start + count]
            start += count
            if task.solved is not None:  # the first episodes' returns, or their last steps' info flags
                out[f"solve_rate/{name}"] = jnp.mean(sc.episode_solved(task.solved, ret, set_flags).astype(jnp.float32))
            out[f"return/{name}"] = jnp.mean(ret)
            out[f"discounted_return/{name}"] = jnp.mean(set_discounted)
            if task.optimal_return is None:
                continue
            if task.expected_return is not None:
                probs = first_step_policy(setup, runner, env, set_levels, action)  # [L, A]
                expected = jax.vmap(task.expected_return)(set_levels, probs)
                entropy = -jnp.sum(probs * jnp.log(jnp.maximum(probs, 1e-30)), axis=-1)
                out[f"entropy/{name}"] = jnp.mean(entropy)
            else:
                expected = ret.mean(axis=1)
            regret = set_optimal - expected
            out[f"regret/{name}/mean"] = jnp.mean(regret)
            out[f"regret/{name}/worst"] = jnp.max(regret)
    # each buffer's levels (a buffer sequence): what the policy keeps of a frozen buffer
    return {**out, **buffer_solve_rates(setup, runner, jax.random.fold_in(rng, 1 << 20), level_episodes, action)}


def tracker_audit(setup: Setup, runner: Runner, rng) -> dict[str, jax.Array]:
    """The tracker's :meth:`~remidi.engine.trackers.base.Tracker.audit` (nothing for exact trackers)."""
    return setup.tracker.audit(setup, runner, rng) if setup.tracker is not None else {}
