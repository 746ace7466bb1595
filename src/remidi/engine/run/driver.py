"""Driving a UED run: all seeds in one compiled program, evaluation, progress and checkpoints.

:func:`train_seeds` validates the config, builds the compiled programs
(:mod:`remidi.engine.run.programs`) and hands them to :func:`drive`. The run is cut into blocks
of ``eval_every`` updates; after each the driver evaluates, records the block's metrics (reduced
per :data:`~remidi.engine.train.BLOCK_REDUCTIONS`) and, every ``checkpoint_every`` updates,
writes a checkpoint atomically. A block that met a non-finite reward or observation stops the
run before anything of it is written. ``resume`` ends in exactly the state an uninterrupted run
reaches. Each invocation records its part (:class:`PartClock`) for ``remidi status``.

A sharded run matches the one-device run only to rounding, and only early on: XLA compiles the
vmapped program for S/N seeds per device, some reductions round differently at that batch size,
and training soon turns a rounding difference into a different action. A sharded run is itself
deterministic and resumes exactly (``docs/devices.md``)."""

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
    """``replay_fraction/<tag>`` f[S]: the tag's share among replayed levels (``replay`` and
    ``replayed/<tag>`` are f[S, steps]); NaN where nothing was replayed."""
    replays = step_metrics["replay"].sum(axis=1)
    return {f"replay_fraction/{name.split('/', 1)[1]}":
            np.where(replays > 0, counts.sum(axis=1) / np.maximum(replays * num_envs, 1), np.nan)
            for name, counts in step_metrics.items() if name.startswith("replayed/")}


def _nanmean(values: np.ndarray) -> np.ndarray:
    """f[S]: mean over axis 1 of the non-NaN values; NaN where none (no warning)."""
    defined = ~np.isnan(values)
    return np.where(defined.any(axis=1), np.where(defined, values, 0.0).sum(axis=1) / np.maximum(defined.sum(axis=1), 1),
                    np.nan)


def _block_metrics(step_metrics: dict[str, np.ndarray], num_envs: int) -> dict[str, np.ndarray]:
    """One block's step metrics f[S, B] reduced to f[S]; ``replayed/<tag>`` become :func:`replay_fractions`."""
    out = replay_fractions(step_metrics, num_envs)
    reduce = {"sum": lambda v: v.sum(axis=1), "last": lambda v: v[:, -1], "mean": lambda v: v.mean(axis=1),
              "nanmean": _nanmean}
    for name, values in step_metrics.items():
        if not name.startswith("replayed/"):
            out[name] = reduce[tr.BLOCK_REDUCTIONS.get(name, "mean")](values)
    return out


def _check_finite(runner, done: int) -> None:
    """RemidiError when the agent's parameters are not finite, so a diverged network never
    overwrites the last good checkpoint."""
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
    """The end of a stopped run's error message: which checkpoint is kept."""
    if ckpt is None:
        return ""
    return "; no checkpoint was written" if kept is None else f"; the last checkpoint before it (update {kept}) is kept"


def _in_any_process(flag: bool) -> bool:
    """Whether ``flag`` holds in any process (a collective every process calls after each block).

    Why: a SIGTERM one process saw must stop all at the same block, or they run mismatched
    collectives (checkpoint gather against next block's metrics) and the job aborts."""
    if jax.process_count() == 1:
        return flag
    from jax.experimental import multihost_utils

    return bool(np.any(multihost_utils.process_allgather(np.asarray(flag, np.int32))))


def _to_host(tree):
    """NumPy copies of ``tree``'s arrays, gathered first if spread over hosts (a collective)."""
    if all(getattr(x, "is_fully_addressable", True) for x in jax.tree.leaves(tree)):
        return jax.tree.map(np.asarray, tree)
    from jax.experimental import multihost_utils

    return jax.tree.map(np.asarray, multihost_utils.process_allgather(tree, tiled=True))



@dataclass(frozen=True)
class TrainResult:
    """A finished run.

    ``steps`` i[T]: updates at each block's end; ``history`` {name: f[S, T]}: block metrics and
    evaluations; ``per_step`` {name: f[S, num_updates]}: raw replay counters; ``runner``: leaves
    ``[S, ...]`` (sharded for a sharded run); ``parts``: the invocations that trained it (empty
    without a run folder)."""

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
    """Train ``algo`` (name or :class:`~remidi.engine.algorithms.Algorithm`) for every seed.

    ``out`` (a folder, or a :class:`RunFolder` that may resume): checkpoints every
    ``checkpoint_every`` updates and at the end. ``on_block(updates done, block metrics)`` runs after
    each block's checkpoint. ``devices=N`` shards the seeds over N devices (N divides the seed
    count). Multi-process: every process calls it alike, all get the results, process 0 writes."""
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
    """Run ``programs`` for every seed in blocks of ``cfg.eval_every`` (see :func:`train_seeds`).

    ``progress``: the bar's description (None: no bar). ``run``: algorithm, seeds and config, stored
    in each checkpoint and checked on resume."""
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
                # a signal is handled only when XLA's call returns: once the first block is dispatched
                # a SIGTERM keeps it; before, nothing is newer than the last checkpoint: exit at once
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
    """This invocation's part of a run, from update ``start``.

    :meth:`record`: ``{"updates": [start, done], "wall_s", "train_s", "train_updates", "code"}``.
    Only blocks after the first and of its length are timed (the first compiles, another length
    compiles again), so ``train_s / train_updates`` is the steady rate. ``code`` None: a part from
    before parts were recorded."""

    def __init__(self, start: int):
        self.start, self.started, self.code = start, time.perf_counter(), code_version()
        self.first_length: int | None = None
        self.train_s, self.train_updates = 0.0, 0

    def block(self, length: int, seconds: float) -> None:
        """Count a block of ``length`` updates that took ``seconds`` (evaluation included)."""
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
