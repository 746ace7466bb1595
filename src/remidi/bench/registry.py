"""The benchmarks' registry (:data:`BENCHMARKS`, :func:`register`), what a workload is, and the
settings a benchmark's own process reads from its environment (``--tiny``, ``--set``,
``--seeds``, ``--lanes``)."""

from __future__ import annotations

import dataclasses
import json
import os
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
    from remidi.engine.adversaries.level_buffer import validate_buffer_config
    from remidi.engine.core.ppo import validate_ppo_config
    from remidi.engine.config import UEDConfig
    from remidi.engine.run.validation import validate_section
    from remidi.errors import positive_int
    from remidi.experiments.overrides import apply_overrides

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
    """``--tiny``: 4 envs × 16 steps, one epoch, small buffers and SFL refreshes (same code paths)."""
    if not _tiny():
        return cfg
    return dataclasses.replace(cfg, num_envs=4, num_steps=16, ppo=dataclasses.replace(cfg.ppo, epochs=1, minibatches=1),
                               buffer=dataclasses.replace(cfg.buffer, capacity=32, topk_k=8),
                               remidi=dataclasses.replace(cfg.remidi, buffer_capacity=16),
                               sfl=dataclasses.replace(cfg.sfl, batch_size=16, num_batches=2, rollout_steps=4,
                                                       buffer_size=8))


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
