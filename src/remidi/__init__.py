"""remidi: ReMiDi and Bayesian level-perfect minimax regret (BLP) for unsupervised environment design.

``remidi.run_ued`` trains a task of your own (docs/extending.md); ``remidi.register_algorithm``,
``remidi.register_score``, ``remidi.register_network`` and ``remidi.register_replay_rule`` add an
algorithm made of existing components, a level score, an agent network and a buffer's replay rule
without editing the library (docs/extending.md, examples/my_algorithm.py, examples/my_score.py,
examples/my_network.py, examples/my_replay_rule.py).
"""

__version__ = "0.1.0"

# name → (module, attribute): imported on first use, so ``import remidi`` does not import JAX
_LAZY = {
    "run_ued": ("remidi.experiments.custom", "run_ued"),
    "register_algorithm": ("remidi.engine.algorithms", "register_algorithm"),
    "register_score": ("remidi.engine.adversaries.scores", "register_score"),
    "register_network": ("remidi.engine.core.networks.registry", "register_network"),
    "register_replay_rule": ("remidi.engine.adversaries.level_buffer", "register_replay_rule"),
}

__all__ = ["__version__", "register_algorithm", "register_network", "register_replay_rule", "register_score",
           "run_ued"]


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attribute = _LAZY[name]
        return getattr(importlib.import_module(module), attribute)
    raise AttributeError(f"module 'remidi' has no attribute {name!r}")


def __dir__():
    """The public names, the lazy ones included: ``dir(remidi)`` and tab completion list them
    without importing JAX."""
    return sorted(set(globals()) | set(__all__))
