"""remidi: ReMiDi and Bayesian level-perfect minimax regret (BLP) for unsupervised environment design."""

__version__ = "0.1.0"
