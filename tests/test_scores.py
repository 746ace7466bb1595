"""Level scores on hand-computed rollouts."""

import jax.numpy as jnp
import numpy as np

from remidi.engine import scores as sc
from remidi.engine.train import first_episode_return

REWARD = jnp.array([[0.0, 1.0], [2.0, 0.0], [0.0, 3.0], [5.0, 0.0]])  # [T=4, N=2]
DONE = jnp.array([[False, True], [True, False], [False, False], [False, True]])


def test_episode_returns():
    mean, best, count = sc.episode_returns(REWARD, DONE)
    # env 0: one episode ended (0+2=2), then 0+5 unfinished; env 1: episodes 1 and 0+3+0=3
    np.testing.assert_allclose(mean, [2.0, 2.0])
    np.testing.assert_allclose(best, [2.0, 3.0])
    np.testing.assert_array_equal(count, [1, 2])
    # no finished episode: the partial return
    mean, best, count = sc.episode_returns(jnp.array([[1.0], [2.0]]), jnp.array([[False], [False]]))
    assert float(mean[0]) == 3.0 and float(best[0]) == 3.0 and int(count[0]) == 0


def test_first_episode_return():
    np.testing.assert_allclose(first_episode_return(REWARD, DONE), [2.0, 1.0])


def test_score_formulas():
    mean = jnp.array([0.5, -1.0])
    np.testing.assert_allclose(sc.perfect_regret(mean, jnp.array([1.0, 10.0])), [0.5, 11.0])
    np.testing.assert_allclose(sc.negative_return(mean), [-0.5, 1.0])
    adv = jnp.array([[1.0, -2.0], [-1.0, 4.0]])
    np.testing.assert_allclose(sc.positive_value_loss(adv), [0.5, 2.0])
    values = jnp.array([[0.0, 1.0], [1.0, 1.0]])
    np.testing.assert_allclose(sc.max_mc(values, jnp.array([2.0, 1.0])), [1.5, 0.0])
    for name in sc.SCORES:
        out = sc.score_levels(name, mean_return=mean, values=values, advantages=adv,
                              max_return=jnp.array([2.0, 1.0]), optimal_return=jnp.array([1.0, 10.0]))
        assert out.shape == (2,)
