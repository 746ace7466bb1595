"""Policies that learn nothing, scored as ``remidi evaluate`` scores the trained agents: the floor
that the results page's primary metrics are read against (a metric must tell a good agent from
a bad one).

    python -m tools.results.floors [OUT]    # default docs/results/references/floors.json

* Brax (Table 1's ``return/undisturbed``):
  - **zero action**: a policy that does nothing (every action 0). Brax's hopper, walker2d and ant
    pay a healthy reward for every step the body stays up, so standing still earns about one per
    step; halfcheetah pays none.
  - **N(0, 1) actions**: independent standard normal actions at every step, the noise a Gaussian
    policy with log-std 0 (an untrained agent's) adds around its mean; its control cost is what a
    policy pays that has not narrowed its action distribution.
* Mazes (Fig. 6's ``solve_rate/mean`` over the ten held-out mazes): **uniform random actions**,
  what a categorical policy with equal logits (an untrained agent's, nearly) does.

Each plays the levels ``remidi evaluate`` scores (``task.eval_sets``, in the environment of each
set, ``task.eval_envs``), scored by the same first-episode return over the task's episode limit
(:func:`remidi.engine.run.evaluation.first_episode_return`) and, for the mazes, the task's solve
criterion; independent attempts per level (zero action one: its episode is determined by the
level). Brax's physics is the experiments' default back end.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[2] / "docs" / "results" / "references" / "floors.json"


def floor_returns(task, name: str, policy: str, attempts: int, seed: int = 0):
    """f32[L, attempts]: the first-episode return on each of the L levels of ``task.eval_sets[name]``
    of ``policy``: ``"zero"`` (every continuous action 0), ``"normal"`` (each continuous action
    N(0, 1)) or ``"uniform"`` (each discrete choice uniform: over ``n`` for ``Discrete(n)``, per component for
    ``MultiDiscrete``)."""
    import jax
    import jax.numpy as jnp

    from remidi.engine.run.evaluation import first_episode_return

    from remidi.envs.actions import Box

    continuous = isinstance(task.actions, Box)
    fits = ("zero", "normal") if continuous else ("uniform",)
    if policy not in fits:
        raise ValueError(f"policy: {policy!r} for a task with {'continuous' if continuous else 'discrete'} "
                         f"actions; allowed: {', '.join(fits)}")
    env, params, levels = task.eval_envs.get(name, task.env), task.params, task.eval_sets[name]
    num_levels = jax.tree.leaves(levels)[0].shape[0]

    def act(key):
        if policy == "uniform":  # each component's choice uniform (Discrete: the one choice)
            counts = getattr(task.actions, "nvec", getattr(task.actions, "n", None))
            return jax.random.randint(key, task.actions.shape, 0, jnp.asarray(counts, jnp.int32))
        return (policy == "normal") * jax.random.normal(key, task.actions.shape)

    def play(key, level):
        _, state = env.reset_to_level(key, level, params)

        def step(state, k):
            k_action, k_step = jax.random.split(k)
            _, state, reward, done, _ = env.step(k_step, state, act(k_action), params)
            return state, (reward, done)

        _, (reward, done) = jax.lax.scan(step, state, jax.random.split(key, task.max_episode_steps))
        return first_episode_return(reward[:, None], done[:, None])[0]

    keys = jax.random.split(jax.random.PRNGKey(seed), num_levels * attempts).reshape(num_levels, attempts, -1)
    per_level = jax.vmap(lambda k, lv: jax.vmap(play, in_axes=(0, None))(k, lv))
    return jnp.asarray(jax.jit(per_level)(keys, levels))


def measure(attempts: int = 30, maze_attempts: int = 1000, seed: int = 0) -> dict:
    """``{"config": ..., "brax-<m>": {"zero_action", "normal_actions", per level},
    "mazes": {"uniform_actions": {"solve_rate/<maze>": ..., "solve_rate/mean": ...}}}``: the Brax
    floors over ``attempts`` per level (as the agents' evaluation), the mazes' over
    ``maze_attempts`` (a random policy's solve rate is a few in a thousand at most: 30 attempts
    would see a handful of successes in all)."""
    import numpy as np

    from remidi.envs.brax import DEFAULT_BACKEND, MORPHOLOGIES, brax_task
    from remidi.envs.maze import maze_task
    from remidi.envs.maze_names import HELD_OUT_NAMES
    from remidi.files import code_version

    out = {"config": {"backend": DEFAULT_BACKEND, "attempts": attempts, "maze_attempts": maze_attempts, "seed": seed,
                      "code": code_version(),
                      "command": "python -m tools.results.floors"}}
    for m in MORPHOLOGIES:
        task = brax_task(m)
        zero = np.asarray(floor_returns(task, "undisturbed", "zero", 1, seed))[:, 0]
        noisy = np.asarray(floor_returns(task, "undisturbed", "normal", attempts, seed)).mean(axis=1)
        out[f"brax-{m}"] = {"zero_action": float(zero.mean()), "normal_actions": float(noisy.mean()),
                            "zero_action_per_level": [round(float(v), 3) for v in zero],
                            "normal_actions_per_level": [round(float(v), 3) for v in noisy]}
        print(f"brax-{m}: zero action {zero.mean():.1f}, N(0, 1) actions {noisy.mean():.1f}", file=sys.stderr, flush=True)
    task = maze_task("tmaze")  # its held-out sets are the blindfold's too
    rates = {f"solve_rate/{name}": float(np.mean(task.solved(np.asarray(floor_returns(task, name, "uniform",
                                                                                       maze_attempts, seed)))))
             for name in HELD_OUT_NAMES}
    rates["solve_rate/mean"] = float(np.mean(list(rates.values())))  # as experiments/maze.py derives it
    out["mazes"] = {"uniform_actions": rates}
    print(f"mazes: uniform actions solve_rate/mean {rates['solve_rate/mean']:.4f}", file=sys.stderr, flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else OUT
    from remidi.files import atomic_write

    doc = measure()
    atomic_write(path, lambda f: f.write(json.dumps(doc, indent=1) + "\n"))
    print(f"wrote {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
