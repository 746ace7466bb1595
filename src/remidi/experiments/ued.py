"""Experiments on the UED engine (DR, PLR⊥, minimax return, ReMiDi), shared by every domain: a
domain's task, default config, presets and plotted metrics made into an
:class:`~remidi.experiments.base.Experiment`."""

from __future__ import annotations

import sys
from pathlib import Path
from dataclasses import dataclass
from typing import Any, Callable

import jax
import numpy as np

from remidi.engine.run.driver import RunFolder, replay_fractions, train_seeds
from remidi.engine.algorithms import PAPER_ALGORITHMS, RegisteredNames, get_algorithm
from remidi.engine.config import UEDConfig
from remidi.engine.adversaries.paired import LevelGenerator
from remidi.engine.adversaries.scores import scores_for, task_scores
from remidi.engine.run.validation import run_warnings, validate_ued_config
from remidi.engine.trackers import tracker_cost_note
from remidi.envs.interface import UEDTask
from remidi.experiments.base import Experiment, RunContext, RunResult
from remidi.experiments.plots import Panel, algorithm_curves, plot_bars, plot_panels, run_title


# measured in updates: scaled with num_updates when only num_updates is set (config.scale_dependents)
SCALED_KEYS = {"num_updates": ("eval_every", "checkpoint_every", "remidi.steps_per_buffer")}


def final_replay_fractions(raw: dict[str, np.ndarray], num_envs: int, last: float = 0.1) -> dict[str, np.ndarray]:
    """Share of each tag among the levels replayed over the last ``last`` of training, f[S]."""
    n = raw["replay"].shape[1]
    window = slice(n - max(1, int(round(n * last))), n)
    return replay_fractions({name: values[:, window] for name, values in raw.items()}, num_envs)


def stalled_seeds(metrics: dict[str, np.ndarray]) -> np.ndarray:
    """bool[S]: the seeds whose block of updates (``metrics``: block means, f[S] each) trained on
    nothing while ReMiDi rejected levels: ``rejected`` > 0 at every step, and ``ppo/policy_loss`` NaN
    (NaN on an update with no step to learn from; the block mean leaves those out). For PLR⊥'s family:
    a block without a replay; for an algorithm training on every rollout: every level explained."""
    loss = metrics.get("ppo/policy_loss")
    if loss is None:
        return np.zeros(0, bool)
    return (np.asarray(metrics["rejected"]) > 0) & np.isnan(np.asarray(loss))


def stall_warner(seeds: list[int], tracker: str, num_envs: int, block: int) -> Callable[[int, dict], list[str]]:
    """A block callback ``(done, metrics) -> warnings``: one line, with the block's counts, for
    each seed the first time (in this invocation) one of its blocks of ``block`` updates (the last
    possibly shorter) is :func:`stalled_seeds`."""
    warned: set[int] = set()
    start: list[int | None] = [None]  # where the block before ended (None: the first of this invocation)
    hint = ("" if tracker in ("prefix", "per_step") else
            "; with remidi.tracker=tolerance a remidi.tracker_tolerance wider than the differences that tell levels "
            "apart explains too much (docs/tolerance.md)" if tracker == "tolerance" else
            f"; with remidi.tracker={tracker} the frozen models may explain too much "
            f"(docs/belief.md, \"The learned belief tracker\")")

    def check(done: int, metrics: dict) -> list[str]:
        first = start[0] if start[0] is not None else (done - 1) // block * block
        start[0] = done
        lines = []
        for i in np.flatnonzero(stalled_seeds(metrics)):
            if seeds[i] not in warned:
                warned.add(seeds[i])
                lines.append(f"seed {seeds[i]}: in updates {first + 1}–{done} the agent trained on nothing: a frozen "
                             f"adversary explained {metrics['rejected'][i]:.0f} of the {num_envs * (done - first)} "
                             f"levels played{hint}")
        return lines

    return check


def stalled_updates(seeds: list[int], steps: np.ndarray, history: dict[str, np.ndarray]) -> dict[str, list]:
    """``{seed: [[first, last], ...]}``: the inclusive update ranges (adjacent blocks merged) of
    each seed's :func:`stalled_seeds` blocks, from the whole run's ``history`` ({name: f[S, T]}, blocks
    ending at ``steps`` i[T]); seeds without one left out. summary.json's ``stalled_updates``."""
    if "ppo/policy_loss" not in history:
        return {}
    out: dict[str, list] = {}
    for k, end in enumerate(np.asarray(steps).tolist()):
        begin = int(steps[k - 1]) + 1 if k else 1
        block = {name: np.asarray(history[name])[:, k] for name in ("rejected", "ppo/policy_loss")}
        for i in np.flatnonzero(stalled_seeds(block)):
            ranges = out.setdefault(str(seeds[i]), [])
            if ranges and ranges[-1][1] == begin - 1:
                ranges[-1][1] = int(end)
            else:
                ranges.append([int(begin), int(end)])
    return out


# a learned tracker's audit (engine/trackers/audit.py, audit_against_exact) that explains at least this
# share of the steps of fresh generator levels, where it and the exact tracker judge fewer than this
# share alike, says the frozen models cannot tell the later adversaries' levels from the earlier ones'
UNSEPARATED = 0.9


def separation_warning(seeds: list[int], final: dict[str, np.ndarray]) -> str | None:
    """The one-line warning for a learned tracker (``belief`` or ``simulated``) whose last audit
    (``final``: f[S]) shows frozen models that cannot separate the adversaries: they explain at least
    :data:`UNSEPARATED` of fresh steps (``belief/explained``) but agree with the exact tracker on fewer
    (``belief/agreement``), so a later adversary's levels are judged as an earlier one's (the mazes
    of docs/results.md). None where no seed shows it or there is no audit."""
    explained, agreement = final.get("belief/explained"), final.get("belief/agreement")
    if explained is None or agreement is None:
        return None
    explained, agreement = np.asarray(explained, float), np.asarray(agreement, float)
    bad = np.flatnonzero((explained >= UNSEPARATED) & (agreement < UNSEPARATED))  # NaN (no audit yet): False
    if not bad.size:
        return None
    which = ", ".join(f"{explained[i]:.2f} on seed {seeds[i]}" for i in bad)
    return (f"the learned tracker cannot separate the adversaries: at the last audit its frozen models explain {which} "
            f"of the steps of fresh generator levels (belief/explained; the exact tracker judges "
            f"{np.nanmean(agreement[bad]):.2f} of them alike), so a later adversary's levels are rejected or masked as "
            f"an earlier one's whatever they hold (docs/belief.md, \"The learned belief tracker\")")


def make_run_warnings(task_factory: Callable[[UEDConfig], UEDTask], check_step: bool = False):
    """``(spec, config) -> warnings``: :func:`~remidi.engine.run.validation.run_warnings` for all
    the run's algorithms at once, naming the preset where it, not ``--set``, chose ``num_steps``.
    ``check_step``: warn of a step that draws from its key (a user's task)."""

    def warnings(spec, cfg: UEDConfig) -> list[str]:
        chosen = "num_steps" in spec.exp.presets.get(spec.preset, {}) and "num_steps" not in spec.overrides
        return run_warnings(cfg, list(spec.algos), task_factory(cfg), check_step,
                            num_steps_from=f"the {spec.preset} preset" if chosen else None, naming=spec.naming)

    return warnings


def make_train(task_factory: Callable[[UEDConfig], UEDTask], summary_metrics: tuple[str, ...],
               derive: Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]] | None = None,
               cheap_step: bool = False):
    """``derive(history) -> more history`` adds metrics computed from the others, f[S, T] each.
    ``cheap_step``: the step costs little beside the network, so the tracker's cost
    (:func:`~remidi.engine.trackers.tracker_cost_note`) is not said."""

    def train(ctx: RunContext) -> RunResult:
        cfg: UEDConfig = ctx.config
        task = task_factory(cfg)
        # validation: train_seeds (the engine's entry point, for every caller) checks the config with
        # validate_ued_config; run_experiment calls the same function before it writes anything
        cost = None if cheap_step or ctx.resume else tracker_cost_note(task, cfg, get_algorithm(ctx.algo), ctx.naming)
        if cost is not None and jax.process_index() == 0:
            print(f"remidi: {cost}", file=sys.stderr, flush=True)
        stalls = stall_warner(ctx.seeds, cfg.remidi.tracker, cfg.num_envs, cfg.eval_every)

        def on_block(done, metrics):
            for warning in stalls(done, metrics) if jax.process_index() == 0 else ():  # one process says it
                print(f"remidi: warning: {warning}", file=sys.stderr, flush=True)
            if ctx.on_block is not None:  # stream each block's metrics, with the derived ones (e.g. solve_rate/mean)
                more = derive({k: np.asarray(v)[:, None] for k, v in metrics.items()}) if derive is not None else {}
                ctx.on_block(done, {**metrics, **{k: np.asarray(v)[:, 0] for k, v in more.items()}})

        result = train_seeds(task, cfg, ctx.algo, ctx.seeds,
                             out=None if ctx.out is None else RunFolder(ctx.out, resume=ctx.resume),
                             progress=ctx.progress, devices=ctx.devices, on_block=on_block)
        history = dict(result.history)
        if derive is not None:
            history.update(derive(history))
        final = {name: history[name][:, -1] for name in history}
        unseparated = separation_warning(ctx.seeds, final)
        if unseparated is not None and jax.process_index() == 0:  # one process says it
            print(f"remidi: warning: {unseparated}", file=sys.stderr, flush=True)
        final.update(final_replay_fractions(result.per_step, cfg.num_envs))
        ordered = {name: final[name] for name in summary_metrics if name in final}
        ordered.update({k: v for k, v in final.items() if k not in ordered})
        extra = {"parts": list(result.parts)} if result.parts else {}
        stalled = stalled_updates(ctx.seeds, result.steps, result.history)
        if stalled:  # the blocks a seed trained on nothing while a frozen adversary rejected levels
            extra["stalled_updates"] = stalled
        return RunResult(steps=result.steps, history=history, final=ordered, extra=extra)

    return train


UNIT_INTERVAL = ("solve_rate", "replay_fraction", "buffer_fraction", "generated")  # metrics in [0, 1]: fixed y-range


def make_plot(panels: tuple[tuple, ...], bars: tuple[str, tuple[str, ...]] | None = None, name: str = ""):
    """``training.png``: one panel per metric of ``panels`` ((metric, title[, options]) tuples), one
    curve per algorithm in the run's order (those without the metric left out). ``options``:
    ``references`` [(y, label)] dashed lines, ``ylim`` (the range shown at least), ``optional`` (left
    out when no algorithm has the metric); shares and rates on [0, 1]. ``bars``: (title, metrics) for
    ``final.png``, final values per algorithm (mean ± std over seeds). Titles name ``name``, the
    preset and the seeds."""

    def plot(folder: Path, results: dict[str, RunResult], cfg, preset: str | None = None,
             seeds: list[int] | None = None) -> None:
        run = run_title(name, preset, seeds)
        figure = []
        for metric, title, *more in panels:
            options = more[0] if more else {}
            kind = metric.split("/")[0]
            ylim = options.get("ylim", (0.0, 1.0) if kind in UNIT_INTERVAL else None)
            curves = algorithm_curves(results, metric)
            if not curves and options.get("optional"):  # a panel for algorithms this run does not have
                continue
            drawn = {c.label for c in curves}
            figure.append(Panel(title, curves, metric, "update", references=list(options.get("references", ())),
                                ylim=ylim, missing=[algo for algo in results if algo not in drawn]))
        plot_panels(folder / "training.png", figure, title=run)
        if bars is not None:
            title, metrics = bars
            finals = {algo: r.final_metrics() for algo, r in results.items()}
            series = {algo: np.stack([np.asarray(f[m], float) for m in metrics]) for algo, f in finals.items()
                      if all(m in f for m in metrics)}  # [M, S] per algorithm
            labels = [m.split("/", 1)[-1] for m in metrics]
            kind = metrics[0].split("/")[0]
            plot_bars(folder / "final.png", f"{run}: {title}" if run else title, labels, series, kind,
                      ylim=(0.0, 1.0) if kind in UNIT_INTERVAL else None)

    return plot


@dataclass(frozen=True)
class UEDSpec:
    """A UED experiment's definition: the task ``task_factory(cfg)`` builds, its configuration
    (``config_factory``, ``presets``, ``preset_seeds``, ``preset_reasons``), what it logs and draws
    (:func:`make_train`, :func:`make_plot`).

    ``cheap_step``: the step costs little beside the network (measured), so the exact tracker's cost is
    not said. ``builds_levels``: the task has ``UEDTask.level_builder``; without, the learned-generator
    algorithms are left out. ``refusal(algorithm) -> str | None``: why the task cannot run an
    algorithm (None: it can). ``check_step``: warn of a step that draws from its key. ``notes``: lines
    ``remidi list NAME`` prints. ``task_gives``: the score fields (``optimal_return``, ``solved``) the
    task sets, known without building it, for ``remidi list NAME``; None: build the task to see."""

    name: str
    description: str
    task_factory: Callable[[UEDConfig], UEDTask]
    config_factory: Callable[[], UEDConfig]
    presets: dict[str, dict[str, Any]]
    preset_seeds: dict[str, int]
    summary_metrics: Any
    plot_panels_spec: Any
    derive: Any = None
    bar_chart: Any = None
    preset_reasons: dict[str, dict[str, str]] | None = None
    builds_levels: bool = True
    refusal: Callable[[Any], str | None] | None = None
    check_step: bool = False
    notes: tuple[str, ...] = ()
    cheap_step: bool = False
    task_gives: tuple[str, ...] | None = None


def make_ued_experiment(spec: UEDSpec) -> Experiment:
    """The :class:`~remidi.experiments.base.Experiment` of ``spec``."""
    name, description, task_factory, config_factory = spec.name, spec.description, spec.task_factory, spec.config_factory
    presets, preset_seeds, preset_reasons = spec.presets, spec.preset_seeds, spec.preset_reasons
    summary_metrics, plot_panels_spec, derive, bar_chart = spec.summary_metrics, spec.plot_panels_spec, spec.derive, \
        spec.bar_chart
    builds_levels, refusal, check_step = spec.builds_levels, spec.refusal, spec.check_step
    if refusal is None and not builds_levels:
        def refusal(algo):
            return (f"{name}'s task has no level-building MDP (UEDTask.level_builder), which a learned level "
                    f"generator needs" if isinstance(algo.adversary, LevelGenerator) else None)
    tasks: dict[UEDConfig, UEDTask] = {}

    def task_for(cfg: UEDConfig) -> UEDTask:
        # one task per configuration in a process: building one costs seconds for Brax (a physics
        # model), and the engine reuses compiled programs per task object (UEDTask compares by
        # identity), so validating, training and training again with one configuration share them
        if cfg not in tasks:
            tasks[cfg] = task_factory(cfg)
        return tasks[cfg]

    def validate(cfg: UEDConfig, algo: str) -> None:
        validate_ued_config(cfg, algo, task_for(cfg))

    def scores(cfg: UEDConfig) -> list[str]:
        if spec.task_gives is not None:
            return scores_for("optimal_return" in spec.task_gives, "solved" in spec.task_gives)
        return task_scores(task_for(cfg))

    return Experiment(
        name=name, description=description, default_algorithms=PAPER_ALGORITHMS,
        algorithms=RegisteredNames(None if refusal is None else lambda algo: refusal(algo) is None, why=refusal),
        config_factory=config_factory,
        presets=presets, preset_seeds=preset_seeds, validate=validate,
        train=make_train(task_for, summary_metrics, derive, spec.cheap_step),
        run_warnings=make_run_warnings(task_for, check_step),
        plot=make_plot(plot_panels_spec, bar_chart, name),
        scaled_keys=SCALED_KEYS,
        divisor_keys=("eval_every",),  # the length of a compiled block of updates
        shards_seeds=True,  # train_seeds(devices=N): remidi run --devices N
        preset_reasons=preset_reasons or {},
        notes=tuple(spec.notes),
        make_task=task_for,
        scores=scores,
        derive=derive,
    )
