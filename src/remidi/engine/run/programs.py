"""The compiled programs of a UED run for every seed at once (:class:`Programs`, :func:`ued_programs`).

A block is one jit-compiled ``lax.scan`` of :func:`~remidi.engine.train.train_step` over seeds
(:func:`over_seeds`). ``devices=N`` shards the seed axis over a 1-D mesh ``"seed"`` under
:func:`jax.shard_map`: each device runs the unchanged per-seed program on S/N seeds, no
communication. The set-up is a static argument, so every run of one set-up in a process reuses
the programs."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import PartitionSpec as P

from remidi.engine import train as tr
from remidi.engine.core.seeds import SEED_BATCH
from remidi.engine.run import evaluation
from remidi.engine.run.checkpoint import load_checkpoint
from remidi.engine.setup import Setup
from remidi.errors import ConfigError

SEED_AXIS = "seed"

def load_run_state(setup: Setup, seeds: list[int], path: Path, flag: str = "--resume"):
    """``(runner, meta)``: every seed's state from checkpoint ``path``, checked against :func:`_init`'s
    structure (traced, not compiled)."""
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds, jnp.uint32))
    return load_checkpoint(path, jax.eval_shape(lambda k: _init(setup, k), keys), flag)


@partial(jax.jit, static_argnums=0)
def _init(setup: Setup, keys):
    # lax.map, not vmap: batched QR decompositions (orthogonal initialisers) hang jaxlib 0.10.2's CPU runtime.
    # Every leaf strongly typed, as a checkpoint restores it: else a resumed run would compile again.
    runner = jax.lax.map(lambda k: tr.init_runner(setup, k), keys)
    return jax.tree.map(lambda x: jax.lax.convert_element_type(x, x.dtype), runner)


def over_seeds(fn):
    """``fn`` over the arguments' leading seed axis S: vmapped, or for S = 1 called without the axis.

    Why: a vmapped axis of size 1 is not free (XLA keeps it in matmuls and turns ``lax.cond`` into
    selects; ``docs/performance.md``). Under ``shard_map`` S is a device's share."""

    def mapped(*args):
        if jax.tree.leaves(args)[0].shape[0] != 1:
            return jax.vmap(fn, axis_name=SEED_BATCH)(*args)  # seeds.cond_per_seed reads the axis
        out = fn(*jax.tree.map(lambda x: x[0], args))
        return jax.tree.map(lambda x: x[None], out)

    return mapped


def run_steps(setup: Setup, runner, length: int):
    """``(runner, per-step metrics f[S, length])``: ``length`` train steps for every seed."""
    return over_seeds(lambda r: jax.lax.scan(lambda c, _: tr.train_step(setup, c), r, None, length=length))(runner)


@partial(jax.jit, static_argnums=(0, 2))
def _run_block(setup: Setup, runner, length: int):
    return run_steps(setup, runner, length)


@partial(jax.jit, static_argnums=0)
def _evaluate(setup: Setup, runner, keys):
    return over_seeds(lambda r, k: {**evaluation.evaluate(setup, r, k), **tr.buffer_tag_fractions(setup, r),
                                    **evaluation.tracker_audit(setup, r, jax.random.fold_in(k, 7))})(runner, keys)


def check_devices(devices: int, num_seeds: int) -> None:
    """ConfigError unless ``devices`` ≥ 1, at most ``jax.device_count()``, and divides ``num_seeds``."""
    if devices == 1 and not isinstance(devices, bool):
        return  # today's path: every machine has one device
    available = jax.device_count()
    allowed = ", ".join(str(d) for d in range(1, min(available, num_seeds) + 1) if num_seeds % d == 0)
    if isinstance(devices, bool) or not isinstance(devices, (int, np.integer)) or devices < 1:
        problem = f"must be an integer ≥ 1, got {devices!r}"
    elif devices > available:
        problem = f"{devices} is more than the {available} device{'s' if available != 1 else ''} JAX sees"
    elif num_seeds % devices:
        problem = f"{devices} does not divide the {num_seeds} seed{'s' if num_seeds != 1 else ''}"
    else:
        return
    raise ConfigError(f"--devices: {problem}; allowed: {allowed}")


def seed_mesh(devices: int) -> jax.sharding.Mesh:
    """A 1-D mesh ``"seed"`` of the first ``devices`` of ``jax.devices()`` (all hosts')."""
    return jax.make_mesh((devices,), (SEED_AXIS,), axis_types=(jax.sharding.AxisType.Auto,),
                         devices=jax.devices()[:devices])


def _per_shard(mesh, fn):
    # every input and output is split along its leading (seed) axis; the per-shard program is the
    # unsharded one on S/N seeds and has no collectives, so replication checking is not needed
    return jax.shard_map(fn, mesh=mesh, in_specs=P(SEED_AXIS), out_specs=P(SEED_AXIS), check_vma=False)


@partial(jax.jit, static_argnums=(0, 1))
def _init_sharded(mesh, setup: Setup, keys):
    return _per_shard(mesh, lambda k: _init(setup, k))(keys)


@partial(jax.jit, static_argnums=(0, 1, 3))
def _run_block_sharded(mesh, setup: Setup, runner, length: int):
    return _per_shard(mesh, lambda r: _run_block(setup, r, length))(runner)


@partial(jax.jit, static_argnums=(0, 1))
def _evaluate_sharded(mesh, setup: Setup, runner, keys):
    return _per_shard(mesh, lambda r, k: _evaluate(setup, r, k))(runner, keys)


def _put(tree, sharding):
    """Place host arrays on ``sharding`` (multi-host: each process supplies its devices' shards)."""
    def one(x):
        host = np.asarray(x)
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])
    return jax.tree.map(one, tree)


@dataclass(frozen=True)
class Programs:
    """What the driver runs for every seed (runner leaves ``[S, ...]``, keys ``[S, 2]``).

    init(keys) -> runner; run_block(runner, length) -> (runner, {name: f[S, length]});
    evaluate(runner, keys) -> {name: f[S]}."""

    init: Callable
    run_block: Callable
    evaluate: Callable
    mesh: jax.sharding.Mesh | None = None  # set when the seeds are sharded over devices


def ued_programs(setup: Setup, devices: int = 1) -> Programs:
    """The compiled programs of a UED run of ``setup``, on ``devices`` devices."""
    if devices == 1:
        return Programs(init=partial(_init, setup), run_block=partial(_run_block, setup),
                        evaluate=partial(_evaluate, setup))
    mesh = seed_mesh(devices)
    return Programs(init=partial(_init_sharded, mesh, setup), run_block=partial(_run_block_sharded, mesh, setup),
                    evaluate=partial(_evaluate_sharded, mesh, setup), mesh=mesh)
