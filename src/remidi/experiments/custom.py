"""A user's own :class:`~remidi.envs.interface.UEDTask` as an experiment, with the built-in
outputs (``config.json``, ``metrics.csv``, ``summary.json``, ``training.png``), resumable.

* Python: :func:`run_ued` (``remidi.run_ued``)::

      from remidi import run_ued
      summaries = run_ued(make_task(), {"num_updates": 200}, ["plr", "remidi"], seeds=[0, 1], out="runs/mine")

* Command line: ``remidi run mypkg.tasks:make_task [--task-arg NAME=VALUE ...] [--algo ...] [--set
  key=value ...]`` imports ``make_task`` (a ``UEDTask`` or a function returning one, called with the
  ``--task-arg`` values, each a JSON scalar or else a string) from the current folder first, and runs
  it on defaults from what the task provides (:func:`task_defaults`) and budgets from the run's size
  (:func:`~remidi.experiments.budgets.budget_defaults`), each said in one line at the start.

``config.json`` records the task's source (``"task": {"import": ..., "folder": ..., "args": ...}``),
so ``remidi run --resume DIR``, ``remidi evaluate DIR`` and ``remidi render DIR`` rebuild it from any
folder. :func:`run_ued` records it when given ``task_ref`` (and ``task_args``); without, resume with
``run_ued(..., resume=True)`` and evaluate with ``evaluate_run(DIR, task=...)``.

Metrics: ``solve_rate/<set>`` (and ``regret/<set>/mean`` given an optimal return) per evaluation
set, ``replay_fraction/<tag>`` and ``buffer_fraction/<tag>`` per level tag."""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import os
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

import jax
import numpy as np

from remidi.engine.config import UEDConfig
from remidi.engine.run.validation import task_refusal, validate_task
from remidi.envs.interface import UEDTask
from remidi.errors import PYTHON, ConfigError, Naming, a_type, debugging, user_code_error
from remidi.experiments.overrides import apply_overrides, flat_keys
from remidi.experiments.budgets import BUDGET_KEYS, MAX_ROLLOUT, budget_defaults, budget_line
from remidi.experiments.task_args import described, parameter_names, shown_args, check_task_args, parse_task_args, task_args_argument
from remidi.experiments.base import MAX_SEED, Experiment, RunSpec, parse_algos
from remidi.experiments.resuming import resume_experiment
from remidi.experiments.running import run_experiment
from remidi.experiments.ued import UEDSpec, make_ued_experiment

PRESET = "default"
EVALUATIONS = 20  # an import-path task's run evaluates this many times (eval_every = num_updates / 20) ...
EVAL_FLOOR = 10  # ... but at most every 10 updates: --set num_updates=30 evaluates 3 times, not 30
_IMPORTED: dict[tuple[str, str, str], Experiment] = {}  # (import path, folder, name) → its experiment


def task_experiment(name: str, make_task: Callable[[], UEDTask], config: UEDConfig | None = None,
                    description: str = "a user's UEDTask", task_ref: dict | None = None) -> Experiment:
    """An :class:`Experiment` named ``name`` training ``make_task()``, with ``config`` (default:
    :func:`task_defaults`, said in one line at the start) as its only preset, ``default``. The task is
    validated first; ``task_ref`` (:func:`task_source`) is recorded in ``config.json``."""
    task = make_task()
    if not isinstance(task, UEDTask):
        raise ConfigError(f"experiment: {name} gives {a_type(task)}, not a remidi UEDTask")
    validate_task(task)  # one line naming the field, before anything reads the task
    base, why = (config, {}) if config is not None else task_defaults(task)
    tags = sorted(jax.eval_shape(lambda k: task.level_tags(task.sample_level(k)), jax.random.PRNGKey(0)))  # names only
    sets = sorted(task.eval_sets)
    rates = tuple(f"solve_rate/{s}" for s in sets) if task.solved is not None else ()
    regrets = tuple(f"regret/{s}/mean" for s in sets) if task.optimal_return is not None else ()
    shares = tuple(f"{kind}/{tag}" for tag in tags for kind in ("replay_fraction", "buffer_fraction"))
    titles = {"solve_rate": "solve rate", "regret": "mean regret", "replay_fraction": "share among replayed levels",
              "buffer_fraction": "share in the active buffer"}
    panels = tuple((m, f"{titles[m.split('/')[0]]}: {m.split('/')[1]}") for m in rates + regrets + shares)
    exp = make_ued_experiment(UEDSpec(
        name=name, description=description, task_factory=lambda cfg: task, config_factory=lambda: base,
        presets={PRESET: {}}, preset_seeds={PRESET: 2}, summary_metrics=rates + regrets + shares,
        plot_panels_spec=panels or (("mean_return", "mean training return"),),
        refusal=lambda algo: task_refusal(algo, task),  # --algo all: the algorithms this task can run
        check_step=True,  # warn of a step with randomness of its own under ReMiDi's exact tracker
    ))
    derived = {} if config is not None else {  # derived from the run's size: recomputed, not scaled
        "scaled_keys": {length: tuple(k for k in keys if k not in BUDGET_KEYS) for length, keys in exp.scaled_keys.items()},
        "derive_config": lambda cfg, overrides: budget_defaults(task, cfg, overrides)}
    return dataclasses.replace(exp, task_ref=task_ref, scale_floors={"eval_every": EVAL_FLOOR} if why else {},
                               config_note=defaults_note(why) if why else None, budget_line=budget_line, **derived)


def task_defaults(task: UEDTask) -> tuple[UEDConfig, dict[str, str]]:
    """The configuration a run of an import-path task starts from, and why each key differs from
    ``UEDConfig()`` (key → reason):

    * ``score``: perfect regret given the optimal return (discounted given the discounted optimum,
      else ``discounted_regret=false``), else positive value loss where episodes outlast the rollout
      (``max_episode_steps`` > :data:`MAX_ROLLOUT`: it reads the bootstrapped value), else
      learnability (SFL's p(1 − p)) given ``solved``, else positive value loss;
    * ``num_steps``: the episode bound, at most :data:`MAX_ROLLOUT`, so episodes end inside a rollout
      (every score reads finished episodes);
    * ``eval_every``: ``num_updates`` / :data:`EVALUATIONS`, never below :data:`EVAL_FLOOR`.

    The algorithms' budgets follow the run's size instead: :func:`budget_defaults`."""
    base = UEDConfig()
    why: dict[str, str] = {}
    changes: dict[str, Any] = {}
    if task.optimal_return is not None:
        changes["score"], why["score"] = "perfect_regret", "the task gives its optimal return"
        if task.optimal_discounted_return is None:
            changes["discounted_regret"] = False
            why["discounted_regret"] = "it gives no discounted optimum: undiscounted regret"
    elif task.max_episode_steps > MAX_ROLLOUT:
        changes["score"] = "pvl"
        why["score"] = (f"the task gives no optimal return and its episodes (up to {task.max_episode_steps} steps) "
                        f"outlast a rollout (at most {MAX_ROLLOUT}): pvl scores a truncated rollout by its "
                        f"bootstrapped value")
    elif task.solved is not None:
        changes["score"], why["score"] = "learnability", "the task defines solved but gives no optimal return"
    else:
        changes["score"], why["score"] = "pvl", "the task gives no optimal return and does not define solved"
    steps = min(task.max_episode_steps, MAX_ROLLOUT)
    changes["num_steps"] = steps
    why["num_steps"] = ("the task's episode bound" if steps == task.max_episode_steps else
                        f"the task's episodes last up to {task.max_episode_steps} steps; at most {MAX_ROLLOUT}")
    changes["eval_every"] = max(base.num_updates // EVALUATIONS, 1)
    why["eval_every"] = f"{EVALUATIONS} evaluations per run, at least {EVAL_FLOOR} updates apart"
    return dataclasses.replace(base, **changes), why


def defaults_note(why: dict[str, str]):
    """``(config, overrides, naming) -> line``: the first line of a fresh run of an import-path
    task, naming the derived defaults the overrides left alone (None where they set them all)."""
    def note(config, overrides, naming: Naming) -> str | None:
        kept = [f"{key} {getattr(config, key)} ({reason})" for key, reason in why.items() if key not in overrides]
        if not kept:
            return None
        return f"defaults for this task: {'; '.join(kept)}; {naming.setting('KEY', 'VALUE')} chooses another"
    return note


def run_ued(task: UEDTask, config: dict[str, Any] | UEDConfig | None, algos: str | Sequence[str],
            seeds: int | Sequence[int], out: str | Path, *, progress: bool = True, resume: bool = False,
            name: str = "custom", task_ref: str | None = None,
            task_args: dict[str, Any] | None = None) -> dict[str, dict]:
    """Train ``task`` with each of ``algos`` (a list, a comma-separated string, or ``"all"``) over
    ``seeds`` (a list, or how many: ``2`` is ``[0, 1]``) into ``out`` (one sub-folder per algorithm when
    several); ``resume=True`` continues the run in ``out``. Returns ``{algo: summary}``.

    ``config``: a dict of :class:`~remidi.engine.config.UEDConfig` keys (dotted or nested) set on the
    task's defaults (:func:`task_defaults`) as ``--set`` does, a whole ``UEDConfig`` used as it is, or
    None. All arguments and the task are validated before anything is written (one-line
    :class:`~remidi.errors.ConfigError`).

    ``task_ref``: ``"module:function"`` giving this task again, and ``task_args`` (JSON scalars) its
    keyword arguments: recorded in ``config.json`` (checked, not called) so that ``remidi run
    --resume OUT`` and ``remidi evaluate OUT`` rebuild the task. Without it, resume here and evaluate
    with ``remidi.runs.evaluate.evaluate_run(OUT, task=task)``."""
    naming = python_naming(config)
    if not isinstance(out, (str, os.PathLike)) or not str(out).strip():
        raise ConfigError(f"out: must be a folder path (a str or a Path), got {out!r}")
    whole, overrides = config_argument(config)
    if task_args is not None and task_ref is None:
        raise ConfigError("task_args: records how task_ref's function built the task, so it needs task_ref "
                          "(e.g. task_ref='mypkg.tasks:make_task', task_args={'size': 9})")
    args = task_args_argument(task_args, "task_args")
    record = task_source(task_ref, args=args, key="task_args") if task_ref is not None else None
    exp = task_experiment(name, lambda: task, whole, task_ref=record)
    if resume:
        return resume_experiment(lambda *_: exp, Path(out), progress=progress, naming=naming)
    spec = RunSpec(exp, parse_algos(exp, algos_argument(algos), key=naming.algos), PRESET, seeds_argument(seeds),
                   overrides=overrides, naming=naming)
    return run_experiment(spec, Path(out), progress=progress)


def python_naming(config) -> Naming:
    """How :func:`run_ued`'s errors and notes spell a key: ``config["ppo.lr"]`` for a dict,
    ``config.ppo.lr`` for a ``UEDConfig``."""
    if isinstance(config, UEDConfig):
        return dataclasses.replace(PYTHON, setting_form="config.{key}={value}")
    return PYTHON


def config_argument(config) -> tuple[UEDConfig | None, dict[str, Any]]:
    """``(whole config or None, overrides)`` of :func:`run_ued`'s ``config``: a ``UEDConfig`` is
    whole; a dict (flattened to dotted keys) or None gives overrides, checked by the run. ConfigError
    for anything else."""
    if isinstance(config, UEDConfig):
        return config, {}
    if config is None:
        return None, {}
    if not isinstance(config, dict) or not all(isinstance(key, str) for key in config):
        raise ConfigError(f"config: must be a dict of UEDConfig keys (e.g. {{'num_updates': 200, 'ppo.lr': 3e-4}}) "
                          f"or a UEDConfig, got {described(config)}")
    return None, flat_keys(config)


def algos_argument(algos) -> str:
    """:func:`run_ued`'s ``algos`` as ``--algo``'s comma-separated text. ConfigError otherwise."""
    if isinstance(algos, str):
        return algos
    if not isinstance(algos, (list, tuple)) or not all(isinstance(a, str) for a in algos):
        raise ConfigError(f"algos: must be a list of algorithm names or a comma-separated string "
                          f"(e.g. ['plr', 'remidi'] or 'plr,remidi'), got {described(algos)}")
    return ",".join(algos)


def seeds_argument(seeds) -> list[int]:
    """:func:`run_ued`'s ``seeds`` as a list (an integer ``n``: ``0 .. n-1``). ConfigError for
    anything else; the run checks the range."""
    if _is_int(seeds):
        if seeds < 1:
            raise ConfigError(f"seeds: must be a number of seeds ≥ 1 or a list of seeds, got {seeds!r}")
        return list(range(int(seeds)))
    if not isinstance(seeds, (list, tuple, range)) or not seeds or not all(_is_int(s) for s in seeds):
        raise ConfigError(f"seeds: must be a non-empty list of integers in [0, {MAX_SEED}] or a number of seeds "
                          f"≥ 1, got {described(seeds)}")
    return [int(s) for s in seeds]


def _is_int(value) -> bool:
    """An integer (Python's or NumPy's), not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _split(path: str) -> tuple[str, str]:
    module_name, _, attribute = path.partition(":")
    if not module_name or not attribute:
        raise ConfigError(f"experiment: {path!r} is no import path; give module:function (e.g. mypkg.tasks:make_task)")
    return module_name, attribute


@contextlib.contextmanager
def _folder_on_path(folder: str | None):
    """``folder`` (default: the current one) first on ``sys.path`` while the block runs, as Python
    does for a script, so the user's module and its imports are found."""
    where = str(Path(folder if folder is not None else os.getcwd()).resolve())
    added = where not in sys.path
    if added:
        sys.path.insert(0, where)
    try:
        yield where
    finally:
        if added and where in sys.path:
            sys.path.remove(where)


def _import(module_name: str, folder: str | None):
    """Import ``module_name`` from ``folder`` (default: the current one), then from the installed
    packages; ConfigError (one line) with the module's own error."""
    with _folder_on_path(folder) as where:
        try:
            importlib.invalidate_caches()  # a module written since the last import (a test, a notebook)
            return importlib.import_module(module_name)
        except Exception as err:  # the user's module: report its own error in one line
            detail = (str(err).strip().splitlines() or [""])[0]
            raise ConfigError(f"experiment: cannot import {module_name} ({type(err).__name__}: {detail}); looked in "
                              f"{where} and the installed packages") from None


def _module_folder(module, module_name: str) -> str:
    """The folder holding ``module``'s top-level package (``F`` for ``F/pkg/mod.py`` as ``pkg.mod``);
    the current folder for a module without a file."""
    file = getattr(module, "__file__", None)
    if not file:
        return str(Path.cwd().resolve())
    path = Path(file).resolve()
    depth = module_name.count(".") + (1 if path.name == "__init__.py" else 0)
    return str(path.parents[depth])


def task_source(path: str, folder: str | None = None, args: dict[str, Any] | None = None,
                key: str = "--task-arg") -> dict[str, Any]:
    """``{"import": path, "folder": F}`` for ``module:attribute``, ``F`` the folder the module
    imports from (``folder`` first, default the current one), with ``"args": args`` where given (checked
    against its parameters, ``key`` naming them). ConfigError (one line) when it cannot be imported,
    lacks the attribute or does not take ``args``."""
    module_name, attribute = _split(path)
    module = _import(module_name, folder)
    target = getattr(module, attribute, None)
    if target is None:
        raise ConfigError(f"experiment: {module_name} has no {attribute}")
    check_task_args(target, path, args or {}, key)
    return {"import": path, "folder": _module_folder(module, module_name), **({"args": dict(args)} if args else {})}


def import_experiment(path: str, folder: str | None = None, name: str | None = None,
                      args: dict[str, Any] | None = None, key: str = "--task-arg") -> Experiment:
    """The experiment of ``module:attribute`` (a ``UEDTask`` or a function returning one, called
    with ``args``), the module imported from ``folder`` (default: the current one) first. Named ``name``
    (default: ``path``). ConfigError (one line) when it cannot be imported, is neither, or refuses
    ``args`` (``key`` names them)."""
    import json

    module_name, attribute = _split(path)
    args = task_args_argument(args, key)
    record = task_source(path, folder, args, key)
    known = (path, record["folder"], name or path, json.dumps(args, sort_keys=True))
    if known in _IMPORTED:  # one task object per process: its compiled programs are reused (UEDTask
        return _IMPORTED[known]  # compares by identity), e.g. by every algorithm of an evaluated run
    target: Any = getattr(importlib.import_module(module_name), attribute)
    make = (lambda: target(**args)) if callable(target) and not isinstance(target, UEDTask) else (lambda: target)
    try:
        with _folder_on_path(record["folder"]):  # what the task builder imports is found beside it
            exp = task_experiment(name or path, make, description=f"the UEDTask of {path}", task_ref=record)
    except ConfigError:
        raise
    except TypeError as err:  # the function refused its arguments (or has a TypeError of its own: said)
        if debugging():
            raise
        if not args:
            raise user_code_error(f"experiment: building the task of {path}", err) from None
        detail = (str(err).strip().splitlines() or [""])[0]
        raise ConfigError(f"{key}: {path} refused {shown_args(args)} (TypeError: {detail}); it accepts: "
                          f"{parameter_names(target)}") from None
    except (Exception, SystemExit) as err:  # the user's task builder (a SystemExit too: no silent exit 0)
        if debugging():
            raise
        raise user_code_error(f"experiment: building the task of {path}", err) from None
    _IMPORTED[known] = exp
    return exp
