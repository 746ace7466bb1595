"""Exact optimal returns of maze levels: a shortest path over (position, direction) states
(:func:`cost_to_go`); an n-action path's reward arrives at step index n−1."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from remidi.envs.maze_levels import MazeLevel
from remidi.envs.maze_names import MAX_STEPS


# ----------------------------------------------------------------------------- optimal return
def cost_to_go(level: MazeLevel) -> jax.Array:
    """f32[4, H, W]: from each state (index ``[d, y, x]``) the fewest actions until the goal reward
    (the last the forward move into the goal); ``inf`` where unreachable and on walls.

    Exact: the Bellman fixed point over turn left/right and forward, iterated until nothing changes."""
    h, w = level.wall_map.shape
    is_goal = (jnp.arange(h)[:, None] == level.goal_pos[1]) & (jnp.arange(w)[None, :] == level.goal_pos[0])
    # the goal cell counts as reached (0); walls can never be stood on (inf)
    fixed = jnp.broadcast_to(jnp.where(is_goal, 0.0, jnp.inf), (4, h, w))
    pinned = jnp.broadcast_to(level.wall_map | is_goal, (4, h, w))

    def ahead(cost_d, d):
        """cost_d f32[H, W] of the cell in front of each cell when facing d (inf past the edge)."""
        padded = jnp.pad(cost_d, 1, constant_values=jnp.inf)
        dx, dy = [(1, 0), (0, 1), (-1, 0), (0, -1)][d]
        return padded[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]

    def relax(cost):
        forward = jnp.stack([ahead(cost[d], d) for d in range(4)])
        turn = jnp.minimum(jnp.roll(cost, 1, axis=0), jnp.roll(cost, -1, axis=0))  # now facing d∓1
        return jnp.where(pinned, fixed, jnp.minimum(cost, 1.0 + jnp.minimum(turn, forward)))

    _, cost = jax.lax.while_loop(lambda c: jnp.any(c[0] != c[1]), lambda c: (c[1], relax(c[1])),
                                 (fixed, relax(fixed)))
    return cost


def shortest_path_steps(level: MazeLevel) -> jax.Array:
    """f32[]: the fewest actions from the level's start to the goal reward (:func:`cost_to_go`)."""
    cost = cost_to_go(level)
    return cost[level.agent_dir.astype(jnp.int32), level.agent_pos[1], level.agent_pos[0]]


def optimal_return(level: MazeLevel, max_steps: int = MAX_STEPS) -> jax.Array:
    """f32[]: the best return on ``level``: ``1 − 0.9·n/T`` for ``n`` = :func:`shortest_path_steps`
    (0 if unreachable or ``n > T``); a T-maze's is ``1``; blindness does not change it.

    (``jaxued``'s ``MazeSolved.optimal_value`` uses ``n + 1``, one step too many.)"""
    return optimal_discounted_return(level, 1.0, max_steps)


def optimal_discounted_return(level: MazeLevel, gamma: float, max_steps: int = MAX_STEPS) -> jax.Array:
    """f32[]: the best E[Σ_t γ^t r_t] on ``level`` (t = 0 at the first action).

    ``γ^(n−1)·(1 − 0.9·n/T)`` for the shortest path's ``n`` (optimal for every γ: a shorter path is
    discounted less and paid more); 0 if unreachable or ``n > T``. A T-maze's agent faces the wall,
    so a turn then the move pays 1 at t = 1: ``γ``."""
    n = shortest_path_steps(level)
    reachable = n <= max_steps
    steps = jnp.where(reachable, n, 1.0)
    maze = jnp.where(reachable, jnp.power(jnp.float32(gamma), steps - 1.0) * (1.0 - 0.9 * steps / max_steps), 0.0)
    return jnp.where(level.tmaze, jnp.float32(gamma), maze).astype(jnp.float32)
