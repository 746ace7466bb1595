"""Driving a UED run: all seeds in one compiled program, evaluation, progress and checkpoints.

:func:`train_seeds` is the entry point: it validates the config, builds the run's compiled
programs (:mod:`remidi.engine.run.programs`: init, run a block, evaluate; on one device or
sharded over several) and hands them to :func:`drive`, which returns a :class:`TrainResult`. The
run is cut into blocks of ``eval_every`` updates. After each block the driver evaluates, records
the block's metrics (reduced as :data:`~remidi.engine.train.BLOCK_REDUCTIONS` says), updates the
progress bar and, every ``checkpoint_every`` updates, writes a checkpoint
(:mod:`remidi.engine.run.checkpoint`) atomically, so a killed run never leaves a corrupt
checkpoint. A block whose rollouts met a NaN or infinite reward or observation stops the run
(:func:`nonfinite_error`) before anything of it is written. ``resume`` continues from the last
checkpoint and ends in exactly the state an uninterrupted run reaches (same blocks, same keys). Each invocation records its part of the run
(:class:`PartClock`): the updates it trained, its wall time and the time of its blocks after the
first (which compiles), from which ``remidi status`` tells the time left.

A sharded run's results match the one-device run's to floating-point rounding, not bit for bit,
and only for a while: XLA compiles the vmapped program for S/N seeds per device instead of S, and
the rounding of some reductions depends on that batch size (the same happens between CPU and GPU,
or between jaxlib versions). Seeds, keys and programs are otherwise the same, so early updates
agree to rounding (``tests/test_sharding.py``), but training turns a rounding difference into a
different sampled action or buffer decision after a few updates, and from then on a seed's run
differs as runs on different hardware do. A sharded run is itself deterministic and resumes
exactly. ``docs/devices.md`` has the multi-host set-up.
"""

from __future__ import annotations

import dataclasses
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import NamedSharding
from jax.sharding import PartitionSpec as P

from remidi import preemption
from remidi.engine import train as tr
from remidi.engine.algorithms import Algorithm
from remidi.engine.config import UEDConfig
from remidi.engine.learner import NONFINITE
from remidi.engine.run.validation import validate_ued_config
from remidi.engine.run.checkpoint import (CHECKPOINT, HISTORY, check_run, load_checkpoint, load_history,
                                      remove_stale_temporaries, save_run)
from remidi.engine.run.programs import (SEED_AXIS, Programs, _evaluate, _init, _put, _run_block,  # noqa: F401
                                        check_devices, load_run_state, over_seeds, run_steps, ued_programs)
from remidi.envs.interface import UEDTask
from remidi.errors import RemidiError
from remidi.files import code_version


def replay_fractions(step_metrics: dict[str, np.ndarray], num_envs: int) -> dict[str, np.ndarray]:
    """``replay_fraction/<tag>`` f[S]: the tag's share among the levels replayed in the given
    steps (``replay`` and ``replayed/<tag>`` are f[S, steps]); NaN where nothing was replayed."""
    replays = step_metrics["replay"].sum(axis=1)
    return {f"replay_fraction/{name.split('/', 1)[1]}":
            np.where(replays > 0, counts.sum(axis=1) / np.maximum(replays * num_envs, 1), np.nan)
            for name, counts in step_metrics.items() if name.startswith("replayed/")}


def _nanmean(values: np.ndarray) -> np.ndarray:
    """f[S]: the mean over axis 1 of the defined values, NaN where none is (no warning)."""
    defined = ~np.isnan(values)
    return np.where(defined.any(axis=1), np.where(defined, values, 0.0).sum(axis=1) / np.maximum(defined.sum(axis=1), 1),
                    np.nan)


def _block_metrics(step_metrics: dict[str, np.ndarray], num_envs: int) -> dict[str, np.ndarray]:
    """Aggregate per-step metrics f[S, B] of one block into f[S]; ``replayed/<tag>`` counts
    become :func:`replay_fractions` of the block."""
    out = replay_fractions(step_metrics, num_envs)
    reduce = {"sum": lambda v: v.sum(axis=1), "last": lambda v: v[:, -1], "mean": lambda v: v.mean(axis=1),
              "nanmean": _nanmean}
    for name, values in step_metrics.items():
        if not name.startswith("replayed/"):
            out[name] = reduce[tr.BLOCK_REDUCTIONS.get(name, "mean")](values)
    return out


def _check_finite(runner, done: int) -> None:
    """RemidiError (one line) when the agent's network parameters hold a NaN or an infinity:
    training diverged, and writing the checkpoint would overwrite the last good one with it."""
    if not all(np.isfinite(np.asarray(leaf)).all() for leaf in jax.tree.leaves(runner.learner.train_state.params)):
        raise RemidiError(f"training diverged: the agent's network parameters are not finite after update {done} "
                          f"(NaN or inf; e.g. a NaN reward, or a learning rate too high); the last checkpoint before "
                          f"it is kept")


def nonfinite_error(flags: dict[str, np.ndarray], start: int, seeds: list[int], kept: str) -> RemidiError | None:
    """The one-line error naming the first update (``start + 1`` is the block's first) and seed
    where a rollout's non-finite flag (``nonfinite/<metric>[/<rollout>]`` f[S, B],
    :func:`~remidi.engine.learner.nonfinite`) is set; None where none is. ``kept``: what the
    message ends with (the checkpoint that stays)."""
    hits = [(int(np.argmax(v.any(axis=0))), name) for name, v in flags.items() if np.any(v)]
    if not hits:
        return None
    column, name = min(hits, key=lambda hit: hit[0])  # at one update, the first flag named (reward)
    metric, *rollout = name[len(NONFINITE):].split("/", 1)
    seed = seeds[int(np.argmax(flags[name][:, column]))]
    where = f", in the {rollout[0]} rollout" if rollout else ""
    return RemidiError(f"training stopped: the environment returned a non-finite {metric} at update "
                       f"{start + column + 1} (NaN or inf; seed {seed}{where}){kept}")


def _kept(ckpt: Path | None, kept: int | None) -> str:
    """What a run stopped before its checkpoint keeps, as the end of its error message."""
    if ckpt is None:
        return ""
    return "; no checkpoint was written" if kept is None else f"; the last checkpoint before it (update {kept}) is kept"


def _in_any_process(flag: bool) -> bool:
    """Whether ``flag`` holds in any process of the run. In a multi-process run (``jax.distributed``)
    this is a collective that every process calls at the same point (after each block): a SIGTERM
    that one process has seen stops them all at the same block, so they take the checkpoint's
    gather together. Decided by each process alone, the signalled one gathered the runner while the
    others gathered the next block's metrics, and the job aborted on the mismatched collective."""
    if jax.process_count() == 1:
        return flag
    from jax.experimental import multihost_utils

    return bool(np.any(multihost_utils.process_allgather(np.asarray(flag, np.int32))))


def _to_host(tree):
    """NumPy copies of ``tree``'s arrays; arrays spread over several hosts are gathered first
    (a collective: every process must call it)."""
    if all(getattr(x, "is_fully_addressable", True) for x in jax.tree.leaves(tree)):
        return jax.tree.map(np.asarray, tree)
    from jax.experimental import multihost_utils

    return jax.tree.map(np.asarray, multihost_utils.process_allgather(tree, tiled=True))



@dataclass(frozen=True)
class TrainResult:
    """A finished run: ``steps`` i[T] (the update count at the end of each block), ``history``
    {name: f[S, T]} (each block's reduced step metrics and the evaluation at its end),
    ``per_step`` {name: f[S, num_updates]} (the raw replay counters of every update), the
    final ``runner`` (leaves ``[S, ...]``; sharded along the seed axis for a sharded run) and
    ``parts``: the invocations that trained it (:func:`drive`; empty without a run folder)."""

    steps: np.ndarray
    history: dict[str, np.ndarray]
    per_step: dict[str, np.ndarray]
    runner: object
    parts: list = ()


@dataclass(frozen=True)
class RunFolder:
    """Where a run's checkpoints go, and whether to continue from the last one there (none: from 0)."""

    path: Path
    resume: bool = False


def train_seeds(task: UEDTask, cfg: UEDConfig, algo: str | Algorithm, seeds: list[int],
                out: Path | RunFolder | None = None, progress: bool = True,
                on_block: Callable[[int, dict], None] | None = None, devices: int = 1) -> TrainResult:
    """Train ``algo`` (a name or an :class:`~remidi.engine.algorithms.Algorithm`) for every seed
    and return the :class:`TrainResult`. With ``out`` (a folder, or a :class:`RunFolder` that
    may resume), checkpoints go there every ``checkpoint_every`` updates and at the end, and a
    resume continues from the last one. ``on_block(updates done, block metrics)`` is called after
    each block, once its checkpoint is written.

    ``devices=N`` shards the seeds over the first N of ``jax.devices()`` (N must divide the
    number of seeds; :func:`check_devices`). In a multi-process run (``jax.distributed``) every
    process calls this with the same arguments, all get the full results, and only process 0
    writes checkpoints."""
    validate_ued_config(cfg, algo, task)  # the CLI's checks, for Python callers too
    check_devices(devices, len(seeds))
    setup = tr.make_setup(task, cfg, algo)
    desc = f"{setup.algo.name} × {len(seeds)} seed{'s' if len(seeds) != 1 else ''}" + \
        (f" on {devices} devices" if devices > 1 else "")
    run = {"algo": setup.algo.name, "seeds": [int(s) for s in seeds], "config": dataclasses.asdict(cfg)}
    folder = out if isinstance(out, RunFolder) or out is None else RunFolder(Path(out))
    return drive(ued_programs(setup, devices), seeds, cfg, folder, desc if progress else None, on_block, run)


def drive(programs: Programs, seeds: list[int], cfg: UEDConfig, folder: RunFolder | None = None,
          progress: str | None = "", on_block: Callable[[int, dict], None] | None = None,
          run: dict | None = None) -> TrainResult:
    """Run ``programs`` for every seed in blocks of ``cfg.eval_every`` updates (see
    :func:`train_seeds`; ``cfg.num_envs`` turns replay counts into replay fractions), with a
    progress bar described by ``progress`` (None: none). ``run``: the algorithm, seeds and config
    trained, recorded in each checkpoint and checked on resume
    (:func:`~remidi.engine.run.checkpoint.check_run`)."""
    num_updates, eval_every, checkpoint_every = cfg.num_updates, cfg.eval_every, cfg.checkpoint_every
    num_envs, out, resume = cfg.num_envs, folder.path if folder else None, bool(folder and folder.resume)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds, jnp.uint32))
    mesh = programs.mesh
    sharding = None if mesh is None else NamedSharding(mesh, P(SEED_AXIS))
    writer = mesh is None or jax.process_index() == 0
    runner = programs.init(keys if sharding is None else _put(keys, sharding))
    steps: list[int] = []
    history: list[dict[str, np.ndarray]] = []
    per_step: list[dict[str, np.ndarray]] = []
    done = 0
    ckpt = Path(out) / CHECKPOINT if out is not None else None
    if ckpt is not None:
        ckpt.parent.mkdir(parents=True, exist_ok=True)
        if writer:
            remove_stale_temporaries(ckpt)
    earlier: list[dict] = []  # the parts before this invocation's
    kept = None  # the updates of the last checkpoint (None: none written yet)
    if resume and ckpt is not None and ckpt.exists():  # no checkpoint yet: start from update 0
        runner, meta = load_checkpoint(ckpt, runner)
        check_run(ckpt, meta, run)
        if sharding is not None:
            runner = _put(runner, sharding)
        history, per_step = load_history(ckpt.with_name(HISTORY), meta)  # checks meta's keys too
        done, steps = meta["done"], meta["steps"]
        kept = done
        earlier = list(meta.get("parts") or [{"updates": [0, done], "code": None}])  # older checkpoints: unrecorded
    part, first = (PartClock(done) if ckpt is not None else None), done

    if ckpt is not None and _in_any_process(preemption.requested()):  # SIGTERM came as the previous algorithm finished
        raise preemption.Preempted(None)
    bar = _progress(num_updates, done, progress or "", progress is not None and writer)
    with ExitStack() as stack:
        armed = False  # once the first block is compiled and dispatched: a SIGTERM checkpoints, then stops
        while done < num_updates:
            length = min(eval_every, num_updates - done)
            block_started = time.perf_counter()
            runner, step_metrics = programs.run_block(runner, length)
            if ckpt is not None and not armed:
                # Python runs a signal handler only between bytecodes, so a SIGTERM that comes
                # while XLA compiles or runs a block is handled when that call returns. The call
                # above returns once the block is compiled and dispatched (asynchronously: it runs
                # while _to_host waits for it), so from here on a SIGTERM keeps the block under
                # way; before (tracing, compiling) nothing newer than the last checkpoint exists
                # and the handler exits at once.
                stack.enter_context(preemption.checkpointing())
                armed = True
            step_metrics = _to_host(step_metrics)
            flags = {name: step_metrics.pop(name) for name in list(step_metrics) if name.startswith(NONFINITE)}
            error = nonfinite_error(flags, done, seeds, _kept(ckpt, kept))
            if error is not None:  # nothing of the block is written: its training saw a NaN
                if bar is not None:
                    bar.close()
                raise error
            eval_keys = jax.vmap(jax.random.fold_in, (0, None))(keys, done + length)
            evals = _to_host(programs.evaluate(runner, eval_keys if sharding is None else _put(eval_keys, sharding)))
            done += length
            steps.append(done)
            history.append({**_block_metrics(step_metrics, num_envs), **evals})
            per_step.append({k: v for k, v in step_metrics.items() if k == "replay" or k.startswith("replayed/")})
            if bar is not None:
                bar.update(length)
            if part is not None:  # training and evaluating the block; its checkpoint is not timed
                part.block(length, time.perf_counter() - block_started)
            # SIGTERM (remidi.preemption): checkpoint this block whatever checkpoint_every says, then stop
            preempted = ckpt is not None and _in_any_process(preemption.requested())
            if ckpt is not None and (done % checkpoint_every < length or done == num_updates or preempted):
                host_runner = runner if mesh is None else _to_host(runner)  # every process gathers,
                _check_finite(host_runner, done)  # a diverged network never replaces the last good checkpoint
                if writer:  # process 0 writes
                    save_run(ckpt, host_runner, done, steps, history, per_step, earlier + [part.record(done)], run)
                kept = done
            if on_block is not None:
                on_block(done, history[-1])
            if preempted:
                if bar is not None:
                    bar.close()
                raise preemption.Preempted(done)
    if bar is not None:
        bar.close()
    names = history[0].keys()
    hist = {name: np.stack([h[name] for h in history], axis=1) for name in names}
    raw = {name: np.concatenate([p[name] for p in per_step], axis=1) for name in per_step[0]}
    trained = [part.record(done)] if part is not None and done > first else []  # a resume of a trained-out checkpoint adds no part
    return TrainResult(np.asarray(steps), hist, raw, runner, earlier + trained)


class PartClock:
    """This invocation's part of a run, from update ``start``: :meth:`record` gives ``{"updates":
    [start, done], "wall_s": seconds since it began, "train_s": the seconds of its blocks after the
    first, "train_updates": their updates, "code": remidi.files.code_version()}`` (commit, device,
    JAX). The first block of an invocation compiles the programs (minutes for a large task) and a
    block of another length compiles again, so only later blocks of the first block's length are
    timed: ``train_s / train_updates`` is the steady rate ``remidi status`` tells the time left
    at. A run resumed elsewhere (another machine, device or commit) records each part, so its
    provenance needs no hand-written note; ``code`` None: a part trained before parts were
    recorded."""

    def __init__(self, start: int):
        self.start, self.started, self.code = start, time.perf_counter(), code_version()
        self.first_length: int | None = None
        self.train_s, self.train_updates = 0.0, 0

    def block(self, length: int, seconds: float) -> None:
        """Count a block of ``length`` updates that took ``seconds`` (its evaluation included)."""
        if self.first_length is None:
            self.first_length = length
        elif length == self.first_length:
            self.train_s, self.train_updates = self.train_s + seconds, self.train_updates + length

    def record(self, done: int) -> dict:
        timed = {"train_s": round(self.train_s, 2), "train_updates": self.train_updates} if self.train_updates else {}
        return {"updates": [self.start, done], "wall_s": round(time.perf_counter() - self.started, 1), **timed,
                "code": self.code}


def _progress(total: int, initial: int, desc: str, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc=desc, unit="upd", dynamic_ncols=True)
