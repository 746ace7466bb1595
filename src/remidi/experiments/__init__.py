"""Registry of the reproducible experiments: ``remidi run NAME``.

``catalog.json`` describes the built-in ones (module, description, presets, algorithms), generated
by ``python -m remidi.experiments`` and checked by ``tests/test_catalog.py``, so ``remidi list``,
``--help`` and a mistyped name are answered without importing JAX (seconds), and
:func:`get_experiment` imports only the module asked for."""

from __future__ import annotations

import importlib
import json
from functools import cache
from pathlib import Path

from remidi.errors import ConfigError, one_of

CATALOG = Path(__file__).with_name("catalog.json")
MODULES = ("tabular", "lever", "darkroom", "darkreach", "maze", "brax", "gymnax",  # remidi.experiments.<module>
           "kinetix")


@cache
def catalog() -> dict[str, dict]:
    """{name: {"module", "description", "presets", "preset_seeds", "algorithms",
    "default_algorithms"}} of the built-in experiments in ``remidi list``'s order (the library's own
    algorithms only)."""
    return json.loads(CATALOG.read_text())


def catalog_entries() -> dict[str, dict]:
    """What :func:`catalog` holds, computed from the experiment modules (imports them all)."""
    entries = {}
    for module in MODULES:
        for exp in importlib.import_module(f"remidi.experiments.{module}").EXPERIMENTS:
            entries[exp.name] = {"module": module, "description": exp.description, "presets": list(exp.presets),
                                 "preset_seeds": dict(exp.preset_seeds), "algorithms": list(exp.algorithms),
                                 "default_algorithms": list(exp.default_algorithms or exp.algorithms)}
    return entries


def all_experiments() -> dict:
    """{name: Experiment} of every built-in experiment (imports every module: seconds)."""
    return {name: get_experiment(name) for name in catalog()}


def entry(name: str) -> dict:
    """The catalog entry of the built-in experiment ``name``; ConfigError (one line naming the
    experiments) for any other name."""
    if name not in catalog():
        raise one_of("experiment", name, catalog())
    return catalog()[name]


def get_experiment(name: str):
    """A registered experiment, or for ``module:function`` the user's task it names
    (:func:`remidi.experiments.custom.import_experiment`)."""
    if ":" in name:
        from remidi.experiments.custom import import_experiment

        return import_experiment(name)
    module = importlib.import_module(f"remidi.experiments.{entry(name)['module']}")
    return next(exp for exp in module.EXPERIMENTS if exp.name == name)


def saved_experiment(name: str, task: dict | None = None):
    """The experiment of a run's ``config.json`` (``name``, ``task``): a user's task rebuilt from its
    import path, looked up in the recorded folder first; else the registered experiment (or
    ``module:function`` from the current folder where no folder is recorded). ConfigError (one line)
    for a user's task recorded without an import path."""
    if task is not None:
        from remidi.experiments.custom import import_experiment

        if not (isinstance(task, dict) and isinstance(task.get("import"), str)
                and isinstance(task.get("folder"), (str, type(None)))):
            raise ConfigError(f"task: must be a record {{\"import\": \"module:function\", \"folder\": ...}}, "
                              f"got {task!r:.120}")
        return import_experiment(task["import"], folder=task.get("folder"), name=name, args=task.get("args"),
                                 key="task.args")
    if ":" in name or name in catalog():
        return get_experiment(name)
    raise ConfigError(f"experiment: {name!r} is a task given to run_ued without task_ref, so this run records no import "
                      f"path to rebuild it from; in Python pass the task: evaluate_run(RUN_DIR, task=...) or "
                      f"run_ued(task, ..., resume=True); for the command line train with "
                      f"run_ued(..., task_ref='module:function')")
