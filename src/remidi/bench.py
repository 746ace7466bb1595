"""``remidi bench``: named, rerunnable throughput benchmarks.

Each benchmark builds one compiled program, times its compilation (``compile_s``), warms it up,
then times ``repeats`` calls (``block_until_ready``) and reports the median
(``env_steps_per_s``, ``seconds_per_call``) and the process's peak resident memory
(``peak_rss_mb``). Every benchmark runs in a fresh Python process, so its memory and compile
time are its own; ratios are taken between benchmarks of one ``remidi bench`` invocation (same
machine, same moment).

Workloads (one seed, or ``--seeds N`` trained together as a run of N seeds does; the shapes of the
paper's maze preset; the train steps are the engine's own ``train_step`` inside the driver's
compiled block, ``driver.run_steps``):

* ``maze-plr``: PLR⊥ on the T-maze task, 32 envs × 256 steps, the paper's maze agent (conv +
  LSTM), PPO 5 epochs × 1 minibatch; the buffer (4000) is full and every update replays, so
  every update is one rollout plus a gradient update (as in jaxued's maze PLR example).
* ``maze-remidi``: the same for ReMiDi in its last buffer, three full frozen buffers of 256
  task levels (half of them T-mazes) tracked by the candidate tracker; reports the tracker's
  overflow.
* ``maze-remidi-reference``: ``maze-remidi`` with the reference tracker (every frozen level
  stepped beside every env), for the ratio of the two trackers (not run by default: slow).
* ``maze-remidi-combine``: ``maze-remidi`` with ``remidi.policy=combine`` (Algorithm 1's
  multi-policy form: the three frozen buffers' policies each read every step's observation and
  the earliest buffer whose levels explain the prefix acts); ``remidi_combine_step_over_remidi_step``
  (not run by default).
* ``maze-remidi-rehearsal``: ``maze-remidi`` with ``remidi.rehearsal=1``: every update trains on
  a batch of a frozen buffer's levels instead of a replay of the active one (one rollout and one
  PPO update either way); ``remidi_rehearsal_step_over_remidi_step`` (not run by default).
* ``maze-remidi-belief``: ``maze-remidi`` with the learned belief tracker
  (``remidi.tracker=belief``, engine/trackers/belief.py): each step every env's prefix is scored by the
  three frozen buffers' GRU models instead of stepping frozen levels, and the active buffer's
  model fits on every replay (``remidi.belief_epochs`` updates);
  ``remidi_belief_step_over_remidi_step`` is its cost per environment step against the exact
  candidate tracker's (not run by default).
* ``maze-remidi-simulated``: ``maze-remidi`` with the simulated belief model
  (``remidi.tracker=simulated`` judged by the ratio, engine/trackers/simulated.py): each step every env's
  ``tracker_budget`` candidates are stepped in two copies, and every update replays its levels
  twice for the noise table (and a fresh update fits the GRU reference);
  ``remidi_simulated_step_over_remidi_step`` (not run by default).
* ``maze-accel``: ACCEL (``accel``) on the same set-up as ``maze-plr``: with every update
  replaying, the updates alternate between a replay (rollout + PPO) and an edit of that replay's
  levels (rollout + scoring + insertion, no PPO); reports the share of edit updates (``edit``)
  and no GFLOP/s (the network's count assumes every update trains).
* ``maze-paired``: PAIRED (``paired``) on the same set-up as ``maze-plr``: every update the
  generator builds 32 levels (29 design steps each, its 64-unit MLP), the protagonist rolls out
  and learns as PLR⊥'s replay update does, the antagonist rolls out and learns, and the
  generator learns; ``paired_step_over_plr_step`` is its cost per environment step against
  ``maze-plr``'s (no GFLOP/s: the count covers one network).
* ``maze-paired-reference``: ``maze-paired`` with the reference libraries' generator
  (``paired.generator_network=reference``: a 128-channel conv, a 256-unit LSTM);
  ``paired_reference_step_over_plr_step`` (not run by default).
* ``maze-env``: the maze environment alone (random actions, 32 envs × 256 steps, automatic
  restarts): the ceiling training cannot beat.
* ``lever-plr``: PLR⊥ on the lever game's paper preset, every update replaying.
* ``lstm-matmul``: the maze LSTM's gate product alone, chained: the rate (``gflops_per_s``)
  this machine reaches on the shape that dominates maze training. Training workloads report
  their network's ``gflops_per_s`` too (XLA's operation count), so ``maze_plr_flops_over_matmul``
  says how far ``maze-plr`` is from it.
* ``solve-onestep``: ``remidi solve``'s exact BLP of a random one-step game of 10,000 levels,
  100 observations and 3 actions (rewards uniform in [0, 1], seed 0); plain Python and HiGHS, no
  compilation (not run by default).
* ``brax-plr``: PLR⊥ on ``brax-hopper``'s paper preset (256 envs × 100 steps, PPO 4 epochs × 32
  minibatches, the 256-unit LSTM agent), every update replaying (not run by default: about 4 s
  per update on a 2-core CPU, docs/performance.md).
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from typing import Callable

BENCHMARKS: dict[str, "Benchmark"] = {}
DEFAULT = ("maze-plr", "maze-remidi", "maze-env", "lever-plr", "lstm-matmul")
TINY_ENV = "REMIDI_BENCH_TINY"  # set (by --tiny): every workload at toy sizes, to check the tool in seconds
SET_ENV = "REMIDI_BENCH_SET"  # JSON {key: value} (by --set): overrides of the train workloads' UED config
SEEDS_ENV = "REMIDI_BENCH_SEEDS"  # seeds trained together by the train workloads (by --seeds; default 1)
BARRIER_ENV = "REMIDI_BENCH_BARRIER"  # a folder (by --lanes): warmed-up lanes wait there to be timed together
CORE_ENV = "REMIDI_BENCH_CORE"  # the core a lane pins itself to (before JAX starts its threads)
# one lane of --lanes: XLA's CPU runtime on one thread (its process is pinned to one core)
SINGLE_THREAD_XLA = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def _overrides() -> dict:
    return json.loads(os.environ.get(SET_ENV) or "{}")


def check_overrides(overrides: dict) -> None:
    """Raise ConfigError for a ``--set`` key that is no UED config key, a value of the wrong type,
    or a value no workload can run with (sizes below 1, PPO and buffer settings out of range), before
    any benchmark starts."""
    from remidi.engine.config import validate_buffer_config
    from remidi.engine.core.ppo import validate_ppo_config
    from remidi.engine.config import UEDConfig
    from remidi.engine.run.validation import validate_section
    from remidi.errors import positive_int
    from remidi.experiments.config import apply_overrides

    cfg = apply_overrides(UEDConfig(), overrides)
    for key in ("num_updates", "num_envs", "num_steps"):
        if key in overrides:
            positive_int(key, getattr(cfg, key))
    if any(key.startswith("ppo.") or key == "num_envs" for key in overrides):
        validate_section("ppo.", lambda: validate_ppo_config(cfg.ppo, cfg.num_envs))
    if any(key.startswith("buffer.") for key in overrides):
        validate_section("buffer.", lambda: validate_buffer_config(cfg.buffer))


def _seeds() -> int:
    return int(os.environ.get(SEEDS_ENV) or 1)


def _tiny() -> bool:
    return os.environ.get(TINY_ENV, "") not in ("", "0")


def _shrink(cfg):
    """``--tiny``: 4 envs × 16 steps, one epoch, small buffers (same code paths)."""
    if not _tiny():
        return cfg
    return dataclasses.replace(cfg, num_envs=4, num_steps=16, ppo=dataclasses.replace(cfg.ppo, epochs=1, minibatches=1),
                               buffer=dataclasses.replace(cfg.buffer, capacity=32, topk_k=8),
                               remidi=dataclasses.replace(cfg.remidi, buffer_capacity=16))


@dataclass(frozen=True)
class Benchmark:
    name: str
    description: str
    build: Callable[[], "Workload"]


@dataclass
class Workload:
    fn: Callable  # jitted (unless ``jit`` is false)
    args: tuple
    env_steps_per_call: int | None
    extras: Callable[[object], dict] = lambda out: {}  # reported values read off a call's output
    chain: bool = False  # fn returns (new first argument, ...): feed it to the next call
    flops_per_call: float | None = None  # floating-point operations of the agent's network per call (XLA's count)
    jit: bool = True  # false: ``fn`` is plain Python (nothing to compile, compile_s is 0)


def register(name: str, description: str):
    def wrap(build):
        BENCHMARKS[name] = Benchmark(name, description, build)
        return build

    return wrap


# ----------------------------------------------------------------------------- workloads
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
    from remidi.experiments.config import apply_overrides

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

    flops = None if setup.algo.edits or isinstance(setup.algo.adversary, LevelGenerator) or \
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


# ----------------------------------------------------------------------------- timing
def run_one(name: str, repeats: int) -> dict:
    """Compile, warm up and time benchmark ``name`` in this process."""
    import jax

    work = BENCHMARKS[name].build()
    args = work.args
    start = time.perf_counter()
    compiled = work.fn.lower(*args).compile() if work.jit else work.fn
    compile_s = time.perf_counter() - start

    def call(args):
        out = compiled(*args)
        if work.jit:
            jax.block_until_ready(out)
        return out

    out = call(args)  # warm-up
    _wait_for_the_other_lanes()
    times = []
    for _ in range(repeats):
        if work.chain:
            args = (out[0],) + args[1:]
        start = time.perf_counter()
        out = call(args)
        times.append(time.perf_counter() - start)
    seconds = statistics.median(times)
    steps = work.env_steps_per_call
    flops = work.flops_per_call
    return {"env_steps_per_s": steps / seconds if steps else None, "seconds_per_call": seconds,
            "env_steps_per_call": steps, "gflops_per_s": flops / seconds / 1e9 if flops else None,
            "compile_s": compile_s, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "repeats": repeats, "times_s": times, "cores": sorted(os.sched_getaffinity(0)), **work.extras(out)}


def _wait_for_the_other_lanes() -> None:
    """In a lane of ``--lanes``: say this process is warmed up, then wait until every lane is, so
    that the lanes' timed calls overlap."""
    folder = os.environ.get(BARRIER_ENV)
    if not folder:
        return
    open(os.path.join(folder, f"ready-{os.getpid()}"), "w").close()
    while not os.path.exists(os.path.join(folder, "go")):
        time.sleep(0.01)


def run_lanes(name: str, repeats: int, lanes: int, env: dict) -> dict:
    """Benchmark ``name`` in ``lanes`` processes at once, each pinned to a core of its own with
    XLA's CPU runtime on one thread, all timed together: how a CPU runs independent jobs (seeds,
    algorithms) side by side. ``env_steps_per_s`` is the lanes' total."""
    import glob
    import tempfile

    cores = sorted(os.sched_getaffinity(0))
    with tempfile.TemporaryDirectory() as folder:
        lane_env = {**env, BARRIER_ENV: folder,
                    "XLA_FLAGS": f"{env.get('XLA_FLAGS', '')} {SINGLE_THREAD_XLA}".strip()}
        procs = [subprocess.Popen([sys.executable, "-m", "remidi.bench", name, str(repeats)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True, env={**lane_env, CORE_ENV: str(core)})
                 for core in cores[:lanes]]
        while len(glob.glob(os.path.join(folder, "ready-*"))) < lanes and all(p.poll() is None for p in procs):
            time.sleep(0.05)
        open(os.path.join(folder, "go"), "w").close()  # also when a lane died: the others must not wait forever
        outs = [p.communicate() for p in procs]
    for p, (_, err) in zip(procs, outs):
        if p.returncode != 0:
            raise RuntimeError(f"benchmark {name} (a lane of {lanes}) failed:\n{err[-3000:]}")
    each = [json.loads(out.strip().splitlines()[-1]) for out, _ in outs]
    rates = [r["env_steps_per_s"] for r in each]
    return {"lanes": lanes, "env_steps_per_s": sum(rates) if None not in rates else None,
            "lane_env_steps_per_s": rates, "lane_seconds_per_call": [r["seconds_per_call"] for r in each],
            "lane_cores": [r["cores"] for r in each],
            "xla_flags": SINGLE_THREAD_XLA}


def device_description() -> str:
    import jax

    d = jax.devices()[0]
    kind = getattr(d, "device_kind", d.platform)
    cores = len(os.sched_getaffinity(0))
    return f"{d.platform}: {kind} ({jax.device_count()} device{'s' if jax.device_count() != 1 else ''}), " \
           f"{cores} CPU cores, {platform.machine()}, jax {jax.__version__}"


# (workload, baseline, key): the workload's time per env step over the baseline's, in one invocation
STEP_RATIOS = (
    ("maze-remidi", "maze-plr", "remidi_step_over_plr_step"),
    ("maze-remidi-combine", "maze-remidi", "remidi_combine_step_over_remidi_step"),
    ("maze-remidi-rehearsal", "maze-remidi", "remidi_rehearsal_step_over_remidi_step"),
    ("maze-remidi-belief", "maze-remidi", "remidi_belief_step_over_remidi_step"),
    ("maze-remidi-simulated", "maze-remidi", "remidi_simulated_step_over_remidi_step"),
    ("maze-paired", "maze-plr", "paired_step_over_plr_step"),
    ("maze-paired-reference", "maze-plr", "paired_reference_step_over_plr_step"),
    ("maze-accel", "maze-plr", "accel_step_over_plr_step"),
    ("maze-remidi-reference", "maze-plr", "remidi_reference_step_over_plr_step"),
)


def ratios(results: dict[str, dict]) -> dict[str, float]:
    out = {}

    def per_call(name):
        return results[name]["seconds_per_call"] / results[name]["env_steps_per_call"]

    for numerator, denominator, key in STEP_RATIOS:
        if numerator in results and denominator in results:
            out[key] = per_call(numerator) / per_call(denominator)
    if "maze-plr" in results and "maze-env" in results:
        out["maze_plr_over_env"] = results["maze-plr"]["env_steps_per_s"] / results["maze-env"]["env_steps_per_s"]
    if results.get("maze-plr", {}).get("gflops_per_s") and "lstm-matmul" in results:
        out["maze_plr_flops_over_matmul"] = results["maze-plr"]["gflops_per_s"] / results["lstm-matmul"]["gflops_per_s"]
    return out


def run_benchmarks(names: list[str], repeats: int, log=sys.stderr, tiny: bool = False,
                   overrides: dict | None = None, lanes: int = 1, seeds: int = 1) -> dict:
    """Run each benchmark in its own process; return the JSON document ``remidi bench --json``
    prints. ``tiny``: toy sizes (checks the tool; the figures mean nothing). ``overrides``: UED
    config keys set in every train workload (``num_envs`` and ``num_steps`` also in ``maze-env``).
    ``lanes`` > 1: each benchmark also runs in that many pinned single-threaded processes at once
    (:func:`run_lanes`), reported under ``"lanes"`` with their total against the one process on
    every core (``over_one_process``). ``seeds``: the train workloads train that many seeds
    together (vmapped, as a run of that many seeds does; their env-steps count every seed's)."""
    overrides = overrides or {}
    env = {**os.environ, TINY_ENV: "1" if tiny else "", SET_ENV: json.dumps(overrides), SEEDS_ENV: str(seeds)}
    results = {}
    for name in names:
        print(f"bench {name}: {BENCHMARKS[name].description} ...", file=log, flush=True)
        proc = subprocess.run([sys.executable, "-m", "remidi.bench", name, str(repeats)],
                              capture_output=True, text=True, env=env)
        if proc.returncode != 0:
            raise RuntimeError(f"benchmark {name} failed:\n{proc.stderr[-3000:]}")
        results[name] = json.loads(proc.stdout.strip().splitlines()[-1])
        r = results[name]
        print(f"  {_num(r['env_steps_per_s'])} env-steps/s, {_num(r['gflops_per_s'], 1)} GFLOP/s, "
              f"{r['seconds_per_call']:.3f} s per call, compile {r['compile_s']:.1f} s, peak RSS {r['peak_rss_mb']:.0f} MB", file=log, flush=True)
    doc = {"benchmarks": results, "ratios": ratios(results), "device": device_description(), "tiny": tiny,
           "set": overrides, "seeds": seeds}
    if lanes > 1:
        doc["lanes"] = {}
        for name in names:
            print(f"bench {name} in {lanes} lanes (one process per core, XLA on one thread) ...", file=log, flush=True)
            lane = run_lanes(name, repeats, lanes, env)
            total, one = lane["env_steps_per_s"], results[name]["env_steps_per_s"]
            lane["over_one_process"] = total / one if total and one else None
            doc["lanes"][name] = lane
            print(f"  {_num(total)} env-steps/s in total ({_num(lane['over_one_process'] or None, 2)}× one process)",
                  file=log, flush=True)
    return doc


def _num(value, digits: int = 0) -> str:
    """``1,234`` (or ``12.3`` with ``digits``), ``-`` where a benchmark has no such figure."""
    return "-" if value is None else f"{value:,.{digits}f}"


def format_table(doc: dict) -> str:
    lines = [f"device: {doc['device']}", "",
             f"{'benchmark':24s} {'env-steps/s':>12s} {'GFLOP/s':>8s} {'s/call':>8s} {'compile s':>9s} {'peak MB':>8s}"]
    for name, r in doc["benchmarks"].items():
        lines.append(f"{name:24s} {_num(r['env_steps_per_s']):>12s} {_num(r.get('gflops_per_s'), 1):>8s} "
                     f"{r['seconds_per_call']:8.3f} "
                     f"{r['compile_s']:9.1f} {r['peak_rss_mb']:8.0f}")
    if doc["ratios"]:
        lines.append("")
        lines += [f"{k}: {v:.3f}" for k, v in doc["ratios"].items()]
    if doc.get("lanes"):
        lines += ["", "one process per core (pinned, XLA on one thread), timed together:",
                  f"{'benchmark':24s} {'lanes':>5s} {'env-steps/s':>12s} {'× one process':>14s}"]
        for name, lane in doc["lanes"].items():
            lines.append(f"{name:24s} {lane['lanes']:5d} {_num(lane['env_steps_per_s']):>12s} "
                         f"{_num(lane['over_one_process'], 2):>14s}")
    return "\n".join(lines)


if __name__ == "__main__":  # one benchmark in this process: python -m remidi.bench NAME REPEATS
    if os.environ.get(CORE_ENV):
        os.sched_setaffinity(0, {int(os.environ[CORE_ENV])})
    print(json.dumps(run_one(sys.argv[1], int(sys.argv[2]))))
