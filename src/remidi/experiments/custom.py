"""A user's own :class:`~remidi.envs.interface.UEDTask` as an experiment: the same outputs as the
built-in ones (``config.json``, ``metrics.csv``, ``summary.json``, ``training.png``), resumable.

Two entry points:

* Python: :func:`run_ued` (``remidi.run_ued``) trains a task you built with the algorithms and
  seeds you name and writes the standard outputs::

      from remidi import run_ued
      summaries = run_ued(make_task(), cfg, ["plr", "remidi"], seeds=[0, 1], out="runs/mine")

* Command line: ``remidi run mypkg.tasks:make_task [--algo ...] [--set key=value ...]`` imports
  ``make_task`` (a function of no arguments returning a ``UEDTask``, or a ``UEDTask``) and runs it
  on the engine's default :class:`~remidi.engine.config.UEDConfig` with your ``--set`` keys;
  ``remidi run --resume DIR`` finds it again by that import path.

Metrics reported and plotted: ``solve_rate/<set>`` (and ``regret/<set>/mean`` when the task gives
an optimal return) for each evaluation set, ``replay_fraction/<tag>`` and ``buffer_fraction/<tag>``
for each level tag.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any, Callable

import jax

from remidi.engine.config import UEDConfig
from remidi.engine.validation import validate_task
from remidi.envs.interface import UEDTask
from remidi.errors import ConfigError
from remidi.experiments.base import Experiment, resume_experiment, run_experiment
from remidi.experiments.ued import make_ued_experiment

PRESET = "default"


def task_experiment(name: str, make_task: Callable[[], UEDTask], config: UEDConfig | None = None,
                    description: str = "a user's UEDTask") -> Experiment:
    """An :class:`Experiment` named ``name`` that trains the task ``make_task()`` returns, with
    ``config`` (default: ``UEDConfig()``) as its only preset, ``default``."""
    task = make_task()
    if not isinstance(task, UEDTask):
        raise ConfigError(f"experiment: {name} gives a {type(task).__name__}, not a remidi UEDTask")
    validate_task(task)  # one line naming the field, before anything reads the task
    base = config if config is not None else UEDConfig()
    tags = sorted(task.level_tags(task.sample_level(jax.random.PRNGKey(0))))
    sets = sorted(task.eval_sets)
    rates = tuple(f"solve_rate/{s}" for s in sets) if task.solved is not None else ()
    regrets = tuple(f"regret/{s}/mean" for s in sets) if task.optimal_return is not None else ()
    shares = tuple(f"{kind}/{tag}" for tag in tags for kind in ("replay_fraction", "buffer_fraction"))
    titles = {"solve_rate": "solve rate", "regret": "mean regret", "replay_fraction": "share among replayed levels",
              "buffer_fraction": "share in the active buffer"}
    panels = tuple((m, f"{titles[m.split('/')[0]]}: {m.split('/')[1]}") for m in rates + regrets + shares)
    return make_ued_experiment(
        name=name, description=description, task_factory=lambda cfg: task, config_factory=lambda: base,
        presets={PRESET: {}}, preset_seeds={PRESET: 2}, summary_metrics=rates + regrets + shares,
        plot_panels_spec=panels or (("mean_return", "mean training return"),),
    )


def run_ued(task: UEDTask, config: UEDConfig, algos: list[str], seeds: list[int], out: str | Path, *,
            progress: bool = True, resume: bool = False, name: str = "custom") -> dict[str, dict]:
    """Train ``task`` with each of ``algos`` (``dr``, ``plr``, ``minimax-return``, ``remidi``) over
    ``seeds`` and write the standard outputs into ``out`` (one sub-folder per algorithm when there
    are several); ``resume=True`` continues the run in ``out`` from its checkpoints. Validates
    everything first (one-line :class:`~remidi.errors.ConfigError`, nothing written). Returns
    ``{algo: summary}`` (the ``summary.json`` documents)."""
    exp = task_experiment(name, lambda: task, config)
    if resume:
        return resume_experiment(lambda _: exp, Path(out), progress=progress)
    return run_experiment(exp, algos=list(algos), preset=PRESET, seeds=list(seeds), overrides={}, out=Path(out),
                          progress=progress)


def import_experiment(path: str) -> Experiment:
    """The experiment of ``module:attribute``: the attribute a ``UEDTask`` or a function of no
    arguments returning one. ConfigError (one line) when it cannot be imported or is neither."""
    module_name, _, attribute = path.partition(":")
    if not module_name or not attribute:
        raise ConfigError(f"experiment: {path!r} is no import path; give module:function (e.g. mypkg.tasks:make_task)")
    try:
        module = importlib.import_module(module_name)
    except Exception as err:  # the user's module: report its own error in one line
        raise ConfigError(f"experiment: cannot import {module_name} ({type(err).__name__}: {err})") from None
    target: Any = getattr(module, attribute, None)
    if target is None:
        raise ConfigError(f"experiment: {module_name} has no {attribute}")
    make = target if callable(target) and not isinstance(target, UEDTask) else (lambda: target)
    try:
        return task_experiment(path, make, description=f"the UEDTask of {path}")
    except ConfigError:
        raise
    except Exception as err:  # the user's task builder
        detail = (str(err).strip().splitlines() or [""])[0]
        raise ConfigError(f"experiment: building the task of {path} failed ({type(err).__name__}: {detail})") from None
