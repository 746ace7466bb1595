"""Bring your own environment: a tiny custom UED environment trained with PLR⊥ and ReMiDi.

    python examples/bring_your_own_env.py OUT_DIR [--updates 200] [--seeds 2] [--resume]

Runs in well under a minute on a laptop CPU (most of it XLA compiling) and writes to OUT_DIR:

    OUT_DIR/training.png                 evaluation curves, one per algorithm
    OUT_DIR/<algo>/config.json           everything needed to rerun or resume it
    OUT_DIR/<algo>/metrics.csv           every metric at every evaluation (seed, step, metric, value)
    OUT_DIR/<algo>/summary.json          final value of every metric: mean, std, per seed
    OUT_DIR/<algo>/checkpoint.npz        the final training state (and checkpoint.history.npz)

The environment, a *signpost corridor*, is a tiny level space with irreducible regret. A level
is (goal end, signpost visible?, decoration). The agent starts in the middle of a corridor of
``LENGTH`` cells and walks left or right; the first end it reaches ends the episode, paying
``1 − 0.05·steps`` at the goal end and 0 at the other. When the signpost is visible the agent sees
which end holds the goal (and the decoration, which changes nothing); when it is hidden it sees
neither, so no policy can do better than guess: those levels keep their regret however long one
trains, and levels that differ only in the unseen goal side and decoration look the same (like
the paper's T-mazes with their unseen walls). PLR⊥'s buffer fills up with them;
ReMiDi's second buffer rejects them (their rollouts are indistinguishable from the first
buffer's) and trains on the visible ones. A few dozen updates only show the machinery: raise
``--updates`` (and run on a GPU) for results.

Everything an environment needs is here: an ``UnderspecifiedEnv`` (levels are pytrees,
``reset_env_to_level`` and ``step_env``; the engine wraps it to replay the same level when an
episode ends) and a ``UEDTask`` (level generator, number of actions, episode bound, optimal return
for the perfect-regret score, evaluation sets, level tags to report).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
from flax import struct

from remidi import run_ued
from remidi.engine.config import BufferConfig
from remidi.engine.core.ppo import PPOConfig
from remidi.engine.config import ReMiDiConfig, UEDConfig
from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.errors import RemidiError

LENGTH = 7  # corridor cells; the ends are 0 and LENGTH − 1
START = LENGTH // 2
DECORATIONS = 16  # cosmetic variants of a level, seen only with the signpost
MAX_STEPS = 2 * LENGTH  # episode limit
STEP_COST = 0.05


# ------------------------------------------------------------------------------ the environment
@struct.dataclass
class Level:
    goal_right: jax.Array  # bool[], the goal is at the right end
    visible: jax.Array  # bool[], the signpost shows the goal's side
    decor: jax.Array  # i32[] in [0, DECORATIONS), seen only when the signpost is visible


@struct.dataclass
class State:
    level: Level
    pos: jax.Array  # i32[]
    t: jax.Array  # i32[], steps taken


class SignpostCorridor(UnderspecifiedEnv):
    """Actions 0 (left) and 1 (right). Observation f32[LENGTH + 3 + DECORATIONS]: the agent's
    cell (one-hot), the signpost (goal left, goal right, blank), the decoration (zeros when the
    signpost is hidden)."""

    @property
    def default_params(self):
        return None  # nothing to configure

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(2)

    def observation(self, state: State) -> jax.Array:
        sign = jnp.where(state.level.visible, state.level.goal_right.astype(jnp.int32), 2)
        decor = jax.nn.one_hot(state.level.decor, DECORATIONS) * state.level.visible
        return jnp.concatenate([jax.nn.one_hot(state.pos, LENGTH), jax.nn.one_hot(sign, 3), decor])

    def reset_env_to_level(self, rng, level: Level, params):
        state = State(level=level, pos=jnp.asarray(START, jnp.int32), t=jnp.asarray(0, jnp.int32))
        return self.observation(state), state

    def step_env(self, rng, state: State, action, params):
        pos = jnp.clip(state.pos + jnp.where(action == 1, 1, -1), 0, LENGTH - 1)
        t = state.t + 1
        at_end = (pos == 0) | (pos == LENGTH - 1)
        at_goal = jnp.where(state.level.goal_right, pos == LENGTH - 1, pos == 0)
        reward = jnp.where(at_goal, 1.0 - STEP_COST * t, 0.0)
        done = at_end | (t >= MAX_STEPS)
        state = state.replace(pos=pos, t=t)
        return self.observation(state), state, reward, done, {}


def sample_level(rng) -> Level:
    k1, k2, k3 = jax.random.split(rng, 3)
    return Level(goal_right=jax.random.bernoulli(k1), visible=jax.random.bernoulli(k2),
                 decor=jax.random.randint(k3, (), 0, DECORATIONS))


def optimal_return(level: Level) -> jax.Array:
    """Walk straight to the goal end."""
    steps = jnp.where(level.goal_right, LENGTH - 1 - START, START)
    return 1.0 - STEP_COST * steps


def optimal_discounted_return(level: Level, gamma: float) -> jax.Array:
    """The same walk under the paper's discounted utility Σ_t γ^t r_t: the goal's reward comes
    with the ``steps``-th action, at t = steps − 1."""
    steps = jnp.where(level.goal_right, LENGTH - 1 - START, START)
    return gamma ** (steps - 1.0) * (1.0 - STEP_COST * steps)


def all_levels(visible: bool) -> Level:
    """Every level with the given signpost, batched: leading dim 2 · DECORATIONS (goal left,
    then right; hidden levels differ only in what the agent cannot see)."""
    decor = jnp.tile(jnp.arange(DECORATIONS, dtype=jnp.int32), 2)
    goal_right = jnp.repeat(jnp.asarray([False, True]), DECORATIONS)
    return Level(goal_right=goal_right, visible=jnp.full((2 * DECORATIONS,), visible), decor=decor)


def make_task() -> UEDTask:
    env = SignpostCorridor()
    return UEDTask(
        env=env, params=env.default_params, sample_level=sample_level, num_actions=2,
        max_episode_steps=MAX_STEPS,
        optimal_return=optimal_return,  # enables the perfect-regret score and regret metrics
        optimal_discounted_return=optimal_discounted_return,  # the default (discounted) perfect regret
        eval_sets={"visible": all_levels(True), "hidden": all_levels(False)},  # solve_rate/<name>, ...
        level_tags=lambda level: {"hidden": ~level.visible},  # replay_fraction/hidden, buffer_fraction/hidden
        solved=lambda ret: ret > 0,  # reached the goal end
        deterministic_reset=True,  # reset_env_to_level ignores its key: ReMiDi's cheaper candidate tracker applies
    )


# --------------------------------------------------------------------------------- the run
def make_config(updates: int) -> UEDConfig:
    """Small everything: 16 envs × 16 steps per update; ReMiDi switches buffers after 40% of the run."""
    return UEDConfig(
        num_updates=updates, num_envs=16, num_steps=16, score="perfect_regret", network="mlp",
        eval_every=max(1, updates // 5), eval_attempts=4, checkpoint_every=updates,
        ppo=PPOConfig(epochs=2, minibatches=1, lr=3e-3, ent_coef=0.01),
        buffer=BufferConfig(capacity=32, prioritization="rank", temperature=0.3, staleness_coef=0.3,
                            replay_prob=0.8, min_fill=0.25, duplicate_check=True),
        remidi=ReMiDiConfig(num_buffers=2, buffer_capacity=16, steps_per_buffer=max(1, (updates * 2) // 5)),
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("out", type=Path, help="output folder (must not hold a run; with --resume: the run)")
    parser.add_argument("--updates", type=int, default=200, help="train steps per algorithm (default 200)")
    parser.add_argument("--seeds", type=int, default=2, help="number of seeds (default 2)")
    parser.add_argument("--resume", action="store_true", help="continue the interrupted run in OUT")
    args = parser.parse_args(argv)

    task, cfg = make_task(), make_config(args.updates)
    try:
        if args.seeds < 1:
            raise RemidiError(f"--seeds: must be an integer ≥ 1, got {args.seeds}")
        # validates everything first (one-line errors, nothing written), then trains each algorithm
        # and writes config.json, metrics.csv, summary.json, checkpoints and training.png
        # task_ref: config.json records where the task comes from, so that `remidi evaluate OUT` and
        # `remidi run --resume OUT` rebuild it, from any folder
        summaries = run_ued(task, cfg, ["plr", "remidi"], seeds=list(range(args.seeds)), out=args.out,
                            progress=False, resume=args.resume, name="bring_your_own_env",
                            task_ref="bring_your_own_env:make_task")
    except RemidiError as err:  # one line, nothing written
        print(f"bring_your_own_env: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"bring_your_own_env: interrupted; continue with: python {sys.argv[0]} {args.out} --resume",
              file=sys.stderr)
        return 130

    for algo, summary in summaries.items():
        m = {name: entry["mean"] for name, entry in summary["metrics"].items()}
        replayed = m.get("replay_fraction/hidden")
        replayed = "n/a" if replayed is None or replayed != replayed else f"{replayed:.2f}"  # None/NaN: never replayed
        print(f"{algo}: solve rate visible {m['solve_rate/visible']:.2f}, hidden {m['solve_rate/hidden']:.2f}; "
              f"mean regret visible {m['regret/visible/mean']:.3f}; hidden share of replayed levels (last 10%) "
              f"{replayed}")
    print(f"\nwrote {args.out}: training.png, and per algorithm config.json, metrics.csv, summary.json, "
          f"checkpoint.npz")
    print("next:")
    print(f"  * look at {args.out / 'training.png'} and {args.out / 'remidi' / 'summary.json'}")
    print(f"  * evaluate the trained agents on more levels (CVaR over the generator): remidi evaluate {args.out}")
    print("  * train longer: python examples/bring_your_own_env.py OTHER_DIR --updates 2000 --seeds 5 "
          "(a GPU helps: see docs/devices.md)")
    print("  * make it yours: replace SignpostCorridor, sample_level, optimal_return and the eval_sets / "
          "level_tags in make_task(), then tune make_config() (keys as in `remidi list lever`); or run "
          "your task from the command line, in the folder holding yourmodule.py: "
          "remidi run yourmodule:make_task --algo plr,remidi --set ...")
    return 0


if __name__ == "__main__":
    sys.exit(main())
