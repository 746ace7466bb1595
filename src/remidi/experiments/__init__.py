"""Registry of the reproducible experiments: ``remidi run NAME``."""

from __future__ import annotations

from remidi.errors import one_of
from remidi.experiments.base import Experiment


def all_experiments() -> dict[str, Experiment]:
    from remidi.experiments import brax, gymnax, lever, maze, tabular

    found: dict[str, Experiment] = {}
    for module in (tabular, lever, maze, brax, gymnax):
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
