"""remidi: ReMiDi and Bayesian level-perfect minimax regret (BLP) for unsupervised environment design."""

__version__ = "0.1.0"


def __getattr__(name):  # ``remidi.run_ued`` without importing JAX for ``import remidi``
    if name == "run_ued":
        from remidi.experiments.custom import run_ued

        return run_ued
    raise AttributeError(f"module 'remidi' has no attribute {name!r}")
