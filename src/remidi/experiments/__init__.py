"""Registry of the reproducible experiments: ``remidi run NAME``."""

from __future__ import annotations

from remidi.errors import ConfigError, one_of
from remidi.experiments.base import Experiment


def all_experiments() -> dict[str, Experiment]:
    from remidi.experiments import brax, gymnax, kinetix, lever, maze, tabular

    found: dict[str, Experiment] = {}
    for module in (tabular, lever, maze, brax, gymnax, kinetix):
        for exp in module.EXPERIMENTS:
            found[exp.name] = exp
    return found


def get_experiment(name: str) -> Experiment:
    """A registered experiment, or for ``module:function`` the user's task it names
    (:func:`remidi.experiments.custom.import_experiment`)."""
    if ":" in name:
        from remidi.experiments.custom import import_experiment

        return import_experiment(name)
    experiments = all_experiments()
    if name not in experiments:
        raise one_of("experiment", name, experiments)
    return experiments[name]


def saved_experiment(name: str, task: dict | None = None) -> Experiment:
    """The experiment of a run's ``config.json``: ``name`` (its ``experiment``) and ``task`` (its
    ``task`` record, ``{"import": "module:function", "folder": ...}``, written for a user's task
    given by import path): the task rebuilt from its import path, looked up in the recorded folder
    first, whatever the current folder; else the registered experiment (or ``module:function`` from
    the current folder, for runs recorded before the folder was). ConfigError (one line, saying what
    to pass) for a user's task recorded without an import path."""
    if task is not None:
        from remidi.experiments.custom import import_experiment

        if not (isinstance(task, dict) and isinstance(task.get("import"), str)
                and isinstance(task.get("folder"), (str, type(None)))):
            raise ConfigError(f"task: must be a record {{\"import\": \"module:function\", \"folder\": ...}}, "
                              f"got {task!r:.120}")
        return import_experiment(task["import"], folder=task.get("folder"), name=name)
    if ":" in name or name in all_experiments():
        return get_experiment(name)
    raise ConfigError(f"experiment: {name!r} is a task given to run_ued without task_ref, so this run records no import "
                      f"path to rebuild it from; in Python pass the task: evaluate_run(RUN_DIR, task=...) or "
                      f"run_ued(task, ..., resume=True); for the command line train with "
                      f"run_ued(..., task_ref='module:function')")
