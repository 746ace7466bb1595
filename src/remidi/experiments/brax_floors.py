"""Two trivial policies' return on Brax's undisturbed levels: the floor that a trained walker's
``return/undisturbed`` (Table 1's metric) is read against.

    python -m remidi.experiments.brax_floors [OUT]    # default docs/results/references/brax-floors.json

* **zero action**: a policy that does nothing (every action 0). Brax's hopper, walker2d and ant
  pay a healthy reward for every step the body stays up, so standing still earns about one per
  step; halfcheetah pays none.
* **N(0, 1) actions**: independent standard normal actions at every step, the noise a Gaussian
  policy with log-std 0 (an untrained agent's) adds around its mean; its control cost is what a
  policy pays that has not narrowed its action distribution.

Both play the levels ``remidi evaluate`` scores (``task.eval_sets["undisturbed"]``: θ = 1, the
reset noise of seeds 0…15), and their return is the same first-episode return over the
100-step episode (:func:`remidi.engine.evaluation.first_episode_return`); the noisy policy takes
``attempts`` independent attempts per level, zero action one (its episode is determined by the
level). Brax's physics is the experiments' default back end.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

OUT = Path(__file__).resolve().parents[3] / "docs" / "results" / "references" / "brax-floors.json"


def floor_returns(task, noise_std: float, attempts: int, seed: int = 0):
    """f32[L, attempts]: the first-episode return on each of ``task``'s L undisturbed levels of the
    policy whose every action is ``noise_std`` times a standard normal draw (0: zero action)."""
    import jax
    import jax.numpy as jnp

    from remidi.engine.evaluation import first_episode_return

    env, params, levels = task.env, task.params, task.eval_sets["undisturbed"]
    num_levels = jax.tree.leaves(levels)[0].shape[0]

    def play(key, level):
        _, state = env.reset_to_level(key, level, params)

        def step(state, k):
            k_action, k_step = jax.random.split(k)
            action = noise_std * jax.random.normal(k_action, (task.num_actions,))
            _, state, reward, done, _ = env.step(k_step, state, action, params)
            return state, (reward, done)

        _, (reward, done) = jax.lax.scan(step, state, jax.random.split(key, task.max_episode_steps))
        return first_episode_return(reward[:, None], done[:, None])[0]

    keys = jax.random.split(jax.random.PRNGKey(seed), num_levels * attempts).reshape(num_levels, attempts, -1)
    per_level = jax.vmap(lambda k, lv: jax.vmap(play, in_axes=(0, None))(k, lv))
    return jnp.asarray(jax.jit(per_level)(keys, levels))


def measure(morphologies=None, attempts: int = 30, seed: int = 0) -> dict:
    """``{"config": ..., "<morphology>": {"zero_action": mean, "normal_actions": mean, per level}}``
    for ``morphologies`` (default: every one of :mod:`remidi.envs.brax`)."""
    import numpy as np

    from remidi.envs.brax import DEFAULT_BACKEND, MORPHOLOGIES, brax_task
    from remidi.files import code_version

    out = {"config": {"backend": DEFAULT_BACKEND, "attempts": attempts, "seed": seed, "code": code_version(),
                      "command": "python -m remidi.experiments.brax_floors"}}
    for m in morphologies or MORPHOLOGIES:
        task = brax_task(m)
        zero = np.asarray(floor_returns(task, 0.0, 1, seed))[:, 0]
        noisy = np.asarray(floor_returns(task, 1.0, attempts, seed)).mean(axis=1)
        out[m] = {"zero_action": float(zero.mean()), "normal_actions": float(noisy.mean()),
                  "zero_action_per_level": [round(float(v), 3) for v in zero],
                  "normal_actions_per_level": [round(float(v), 3) for v in noisy]}
        print(f"{m}: zero action {zero.mean():.1f}, N(0, 1) actions {noisy.mean():.1f}", file=sys.stderr, flush=True)
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
