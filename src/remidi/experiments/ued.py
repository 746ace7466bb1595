"""Experiments on the UED engine (DR, PLR⊥, minimax return, ReMiDi), shared by every domain.

A domain supplies its :class:`~remidi.envs.interface.UEDTask`, its default
:class:`~remidi.engine.train.UEDConfig`, presets and which metrics to plot; this module turns
that into an :class:`~remidi.experiments.base.Experiment`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from remidi.engine.driver import replay_fractions, train_seeds
from remidi.engine.train import ALGORITHMS, UEDConfig, validate_ued_config
from remidi.envs.interface import UEDTask
from remidi.experiments.base import Experiment, RunContext, RunResult
from remidi.experiments.plots import Curve, Panel, plot_panels


def final_replay_fractions(raw: dict[str, np.ndarray], num_envs: int, last: float = 0.1) -> dict[str, np.ndarray]:
    """Share of each tag among the levels replayed over the last ``last`` of training, f[S]."""
    n = raw["replay"].shape[1]
    window = slice(n - max(1, int(round(n * last))), n)
    return replay_fractions({name: values[:, window] for name, values in raw.items()}, num_envs)


def make_train(task_factory: Callable[[UEDConfig], UEDTask], summary_metrics: tuple[str, ...]):
    def train(ctx: RunContext) -> RunResult:
        cfg: UEDConfig = ctx.config
        task = task_factory(cfg)
        steps, history, raw, _ = train_seeds(task, cfg, ctx.algo, ctx.seeds, out=ctx.out, resume=ctx.resume,
                                             progress=ctx.progress)
        final = {name: history[name][:, -1] for name in history}
        final.update(final_replay_fractions(raw, cfg.num_envs))
        ordered = {name: final[name] for name in summary_metrics if name in final}
        ordered.update({k: v for k, v in final.items() if k not in ordered})
        return RunResult(steps=steps, history=history, final=ordered)

    return train


def make_plot(panels: tuple[tuple[str, str], ...]):
    """``panels``: (metric, title) pairs; one panel per metric, one curve per algorithm."""

    def plot(folder: Path, results: dict[str, RunResult], cfg) -> None:
        figure = []
        for metric, title in panels:
            curves = [Curve(algo, r.steps, r.history[metric]) for algo, r in results.items() if metric in r.history]
            figure.append(Panel(title, curves, metric.split("/")[0].replace("_", " "), "update"))
        plot_panels(folder / "training.png", figure)

    return plot


def make_ued_experiment(*, name: str, description: str, task_factory, config_factory, presets, preset_seeds,
                        summary_metrics, plot_panels_spec) -> Experiment:
    def validate(cfg: UEDConfig, algo: str) -> None:
        validate_ued_config(cfg, algo, task_factory(cfg))

    return Experiment(
        name=name, description=description, algorithms=ALGORITHMS, config_factory=config_factory,
        presets=presets, preset_seeds=preset_seeds, validate=validate,
        train=make_train(task_factory, summary_metrics), plot=make_plot(plot_panels_spec),
    )
