"""remidi: ReMiDi and Bayesian level-perfect minimax regret (BLP) for unsupervised environment design.

``remidi.run_ued`` trains a task of your own (docs/extending.md); ``remidi.register_algorithm``
and ``remidi.register_score`` add an algorithm made of existing components and a level score
without editing the library (docs/extending.md, examples/my_algorithm.py, examples/my_score.py).
"""

__version__ = "0.1.0"

# name → (module, attribute): imported on first use, so ``import remidi`` does not import JAX
_LAZY = {
    "run_ued": ("remidi.experiments.custom", "run_ued"),
    "register_algorithm": ("remidi.engine.algorithms", "register_algorithm"),
    "register_score": ("remidi.engine.adversaries.scores", "register_score"),
}

__all__ = ["__version__", "register_algorithm", "register_score", "run_ued"]


def __getattr__(name):
    if name in _LAZY:
        import importlib

        module, attribute = _LAZY[name]
        return getattr(importlib.import_module(module), attribute)
    raise AttributeError(f"module 'remidi' has no attribute {name!r}")
