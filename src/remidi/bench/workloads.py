"""What each benchmark compiles and calls (the package's docstring describes every one).
Registered by name with :func:`~remidi.bench.registry.register`."""

from __future__ import annotations

import dataclasses

from remidi.bench.registry import Workload, _overrides, _seeds, _shrink, _tiny, register


def _filled_runner(setup, active: int, seeds: int = 1):
    """A runner of ``seeds`` seeds (leaves [S, ...], as ``driver.run_steps`` takes them) whose
    every buffer is full of the task's random levels (random scores; the same for every seed),
    on buffer ``active``."""
    import jax
    import jax.numpy as jnp

    from remidi.engine.run import driver

    runner = driver._init(setup, jax.vmap(jax.random.PRNGKey)(jnp.arange(seeds, dtype=jnp.uint32)))
    bufs = runner.adversary.buffers  # leaves [S, K, C, ...]
    k, c = bufs.valid.shape[1:]
    keys = jax.random.split(jax.random.PRNGKey(1), k * c)
    levels = jax.jit(jax.vmap(setup.task.sample_level))(keys)
    levels = jax.tree.map(lambda x: jnp.broadcast_to(x.reshape((1, k, c) + x.shape[1:]), (seeds, k, c) + x.shape[1:]),
                          levels)
    scores = jnp.broadcast_to(jax.random.uniform(jax.random.PRNGKey(2), (1, k, c)), (seeds, k, c))
    bufs = bufs.replace(levels=levels, valid=jnp.ones_like(bufs.valid), scores=scores)
    return runner.replace(adversary=runner.adversary.replace(buffers=bufs,
                                                            active=jnp.full_like(runner.adversary.active, active)))


def _train_workload(task, cfg, algo: str, active: int, updates_per_call: int = 2):
    from functools import partial

    import jax

    from remidi.engine.run import driver
    from remidi.engine import train as tr
    from remidi.experiments.overrides import apply_overrides

    cfg = apply_overrides(_shrink(cfg), _overrides())
    setup = tr.make_setup(task, cfg, algo)
    seeds = _seeds()
    runner = _filled_runner(setup, active, seeds)

    @partial(jax.jit, donate_argnums=0)
    def block(runner):
        return driver.run_steps(setup, runner, updates_per_call)

    def extras(out):
        _, metrics = out
        return {name: float(metrics[name].mean()) for name in ("replay", "edit", "rehearsal", "tracker_overflow", "rejected")
                if name in metrics}

    steps = updates_per_call * cfg.num_envs * cfg.num_steps * seeds
    # the network's operation count assumes every update trains one network; an editing algorithm's
    # edit updates do not, a learned generator's updates train three, a belief tracker adds its models'
    # work and Combine the frozen policies' (no figure rather than a wrong one)
    from remidi.engine.adversaries.paired import LevelGenerator

    from remidi.engine.adversaries.sfl import LearnabilityBuffers

    # SFL's refreshes add forward passes the count leaves out
    flops = None if setup.algo.edits or isinstance(setup.algo.adversary, (LevelGenerator, LearnabilityBuffers)) or \
        setup.algo.buffer_sequence and (setup.tracker.learns or cfg.remidi.policy == "combine") else \
        steps * network_flops_per_step(setup, jax.tree.map(lambda x: x[0], runner.learner.train_state.params))
    return Workload(block, (runner,), steps, extras, chain=True, flops_per_call=flops)


def network_flops_per_step(setup, params) -> float:
    """Floating-point operations the agent's network costs per environment step of a replay
    update: a forward pass in the rollout, plus a forward and a backward pass (counted as two
    forwards: the products with the inputs' and with the weights' gradients) per PPO epoch.
    The forward pass is counted by XLA (``cost_analysis``) on the network applied to one time
    step of ``num_envs`` envs; one step, because XLA counts a loop's body once whatever its
    trip count. ``params``: one seed's."""
    import jax
    import jax.numpy as jnp

    from remidi.engine.setup import example_observation

    cfg, net = setup.cfg, setup.net
    n = cfg.num_envs
    obs = jax.tree.map(lambda x: jnp.broadcast_to(x, (1, n) + jnp.shape(x)), example_observation(setup.task)[0])
    reset = jnp.zeros((1, n), bool)
    carry = net.initialize_carry(n)

    def forward(params):
        return net.apply({"params": params}, carry, obs, reset)

    cost = jax.jit(forward).lower(params).compile().cost_analysis()
    cost = cost[0] if isinstance(cost, list) else cost
    return (1 + 3 * cfg.ppo.epochs) * float(cost["flops"]) / n


def _maze_config(algo: str, budget: int | None = None):
    from remidi.engine.algorithms import get_algorithm
    from remidi.experiments.maze import paper_config

    cfg = paper_config()
    cfg = dataclasses.replace(cfg, buffer=dataclasses.replace(cfg.buffer, replay_prob=1.0))
    if get_algorithm(algo).buffer_sequence:  # stay on the last buffer: no switch during the benchmark
        remidi = dataclasses.replace(cfg.remidi, steps_per_buffer=10**9, count="updates")
        if budget is not None:
            remidi = dataclasses.replace(remidi, tracker_budget=budget)
        cfg = dataclasses.replace(cfg, remidi=remidi)
    return cfg


@register("maze-plr", "PLR⊥ update on the T-maze task: 32 envs × 256 steps, maze agent, PPO 5×1")
def _maze_plr():
    from remidi.envs.maze import maze_task

    return _train_workload(maze_task("tmaze"), _maze_config("plr"), "plr", active=0)


@register("maze-remidi", "ReMiDi update in its last buffer, three full frozen buffers of 256 levels")
def _maze_remidi():
    return _maze_remidi_last_buffer()


def _maze_remidi_last_buffer(**remidi):
    """ReMiDi's update on the T-maze in its last buffer (``remidi``: ReMiDiConfig fields to change)."""
    from remidi.envs.maze import maze_task

    cfg = _maze_config("remidi")
    cfg = dataclasses.replace(cfg, remidi=dataclasses.replace(cfg.remidi, **remidi))
    return _train_workload(maze_task("tmaze"), cfg, "remidi", active=cfg.remidi.num_buffers - 1)


@register("nomatch-plr", "maze-plr on the fogged maze (bench/nomatch.py): every level's first observation its own, "
                        "a step costlier than the maze's")
def _nomatch_plr():
    from remidi.bench.nomatch import fog_maze_task

    return _train_workload(fog_maze_task(), _maze_config("plr"), "plr", active=0)


@register("nomatch-remidi", "maze-remidi on the fogged maze: three full frozen buffers of 256 levels, none of "
                           "which shares an env's first observation")
def _nomatch_remidi():
    from remidi.bench.nomatch import fog_maze_task

    cfg = _maze_config("remidi")
    return _train_workload(fog_maze_task(), cfg, "remidi", active=cfg.remidi.num_buffers - 1)


@register("maze-accel", "ACCEL on the T-maze task: PLR⊥'s update, every other one editing the last replay's levels")
def _maze_accel():
    from remidi.envs.maze import maze_task

    return _train_workload(maze_task("tmaze"), _maze_config("accel"), "accel", active=0)


@register("maze-paired", "PAIRED on the T-maze task: generator, protagonist and antagonist each update")
def _maze_paired():
    from remidi.envs.maze import maze_task

    return _train_workload(maze_task("tmaze"), _maze_config("paired"), "paired", active=0)


@register("maze-paired-reference", "maze-paired with the reference libraries' generator (conv 128, LSTM 256)")
def _maze_paired_reference():
    from remidi.envs.maze import maze_task

    cfg = _maze_config("paired")
    cfg = dataclasses.replace(cfg, paired=dataclasses.replace(cfg.paired, generator_network="reference"))
    return _train_workload(maze_task("tmaze"), cfg, "paired", active=0)


@register("maze-remidi-reference", "maze-remidi with the reference tracker (every frozen level stepped)")
def _maze_remidi_reference():
    from remidi.envs.maze import maze_task

    cfg = _maze_config("remidi", budget=0)
    return _train_workload(maze_task("tmaze"), cfg, "remidi", active=cfg.remidi.num_buffers - 1, updates_per_call=1)


@register("maze-remidi-combine", "maze-remidi with remidi.policy=combine: each frozen buffer's policy reads every "
                                "step, the earliest whose levels explain the prefix acts")
def _maze_remidi_combine():
    return _maze_remidi_last_buffer(policy="combine")


@register("maze-remidi-rehearsal", "maze-remidi with remidi.rehearsal=1: every update trains on a frozen buffer's "
                                  "levels instead of replaying the active one")
def _maze_remidi_rehearsal():
    return _maze_remidi_last_buffer(rehearsal=1.0)


@register("maze-remidi-belief", "maze-remidi with the learned belief tracker (remidi.tracker=belief): three frozen "
                               "models judge, the active one learns from each replay")
def _maze_remidi_belief():
    return _maze_remidi_last_buffer(tracker="belief")


@register("maze-remidi-simulated", "maze-remidi with the simulated belief model (remidi.tracker=simulated, the ratio): "
                                  "two copies of each candidate, the noise table counted on every update")
def _maze_remidi_simulated():
    return _maze_remidi_last_buffer(tracker="simulated", belief_reference=True)


@register("brax-plr", "PLR⊥ update on brax-hopper's paper preset: 256 envs × 100 steps, PPO 4 × 32")
def _brax_plr():
    from remidi.experiments.brax import paper_config, task_factory

    cfg = paper_config()
    cfg = dataclasses.replace(cfg, buffer=dataclasses.replace(cfg.buffer, replay_prob=1.0),
                              brax=dataclasses.replace(cfg.brax, reference_return=250.0))  # any value: timing only
    return _train_workload(task_factory("hopper")(cfg), cfg, "plr", active=0, updates_per_call=1)


@register("maze-env", "the maze environment alone: random actions, 32 envs × 256 steps")
def _maze_env():
    import jax

    from remidi.envs.interface import AutoReplay
    from remidi.envs.maze import maze_task

    task = maze_task("tmaze")
    env, params = AutoReplay(task.env), task.params
    num_envs, num_steps = (4, 16) if _tiny() else (32, 256)
    num_envs = int(_overrides().get("num_envs", num_envs))
    num_steps = int(_overrides().get("num_steps", num_steps))
    levels = jax.jit(jax.vmap(task.sample_level))(jax.random.split(jax.random.PRNGKey(0), num_envs))

    @jax.jit
    def block(rng):
        obs, state = jax.vmap(env.reset_to_level, in_axes=(0, 0, None))(
            jax.random.split(rng, num_envs), levels, params)

        def step(state, key):
            k_act, k_env = jax.random.split(key)
            action = jax.random.randint(k_act, (num_envs,), 0, task.num_actions)
            obs, state, reward, done, _ = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_env, num_envs), state, action, params)
            # the observations are an output, or XLA would drop their computation
            return state, (jax.tree.map(lambda x: x.reshape(num_envs, -1).sum(axis=1), obs), reward, done)

        _, out = jax.lax.scan(step, state, jax.random.split(rng, num_steps))
        return out

    return Workload(block, (jax.random.PRNGKey(1),), num_envs * num_steps)


@register("lever-plr", "PLR⊥ update on the lever game's paper preset")
def _lever_plr():
    from remidi.envs.lever import lever_task
    from remidi.experiments.lever import paper_config

    cfg = paper_config()
    cfg = dataclasses.replace(cfg, buffer=dataclasses.replace(cfg.buffer, replay_prob=1.0))
    return _train_workload(lever_task(), cfg, "plr", active=0, updates_per_call=20)


@register("lever-sfl", "SFL on the lever game's paper preset: sfl.refresh_every (25) updates per call, the "
                       "first refreshing the buffer (1024 candidates × 32 steps)")
def _lever_sfl():
    from remidi.envs.lever import lever_task
    from remidi.experiments.lever import paper_config

    cfg = paper_config()
    return _train_workload(lever_task(), cfg, "sfl", active=0, updates_per_call=cfg.sfl.refresh_every)


@register("lstm-matmul", "the maze LSTM's matrix product alone: [32, 406] × [406, 1024], 1280 in a loop")
def _lstm_matmul():
    """The rate this machine multiplies matrices of the shape that dominates maze training: the
    LSTM's gate product for 32 envs (input 144 conv features + 5 direction + 1 for the bias +
    256 hidden = 406, 4 × 256 gates), chained so that each product depends on the one before (as in the LSTM's
    loop over time). 1280 products: the forward passes of one rollout and five epochs."""
    import jax
    import jax.numpy as jnp

    n, d, g = (4, 406, 1024) if _tiny() else (32, 406, 1024)
    length = 64 if _tiny() else 1280
    w = jax.random.normal(jax.random.PRNGKey(0), (d, g)) / jnp.sqrt(d)

    @jax.jit
    def block(x, w):
        def step(x, _):
            gates = x @ w
            return jnp.tanh(gates[:, :d]), None  # the next step's input, as the LSTM's h feeds back

        return jax.lax.scan(step, x, None, length=length)[0]

    x = jax.random.normal(jax.random.PRNGKey(1), (n, d))
    return Workload(block, (x, w), None, flops_per_call=2.0 * n * d * g * length)


def random_onestep_game(n_levels: int, n_obs: int, n_actions: int, seed: int = 0):
    """A one-step game [L levels, O observations, A actions] with rewards uniform in [0, 1]."""
    import numpy as np

    from remidi.solvers.onestep import OneStepGame

    rng = np.random.default_rng(seed)
    return OneStepGame(tuple(f"a{i}" for i in range(n_actions)), tuple(f"l{i}" for i in range(n_levels)),
                       tuple(f"o{o}" for o in rng.integers(n_obs, size=n_levels)),
                       rng.random((n_levels, n_actions)))


@register("solve-onestep", "exact BLP of a one-step game: 10,000 levels, 100 observations, 3 actions")
def _solve_onestep():
    from remidi.solvers.onestep import solve_blp

    game = random_onestep_game(*((100, 20) if _tiny() else (10_000, 100)), 3)
    return Workload(solve_blp, (game,), None, extras=lambda out: {"rounds": len(out.rounds)}, jit=False)
