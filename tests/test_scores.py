"""Level scores on hand-computed rollouts."""

import jax
import jax.numpy as jnp
import numpy as np

from remidi.engine.adversaries import scores as sc
from remidi.engine.run.evaluation import first_episode_return

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
    # discounted from the rollout's first step: env 0 γ·2, env 1 1 (its first episode is one step)
    np.testing.assert_allclose(first_episode_return(REWARD, DONE, 0.5), [1.0, 1.0])


def test_discounted_episode_returns_count_t_from_each_episode_start():
    """Σ_k γ^k r_k with k restarting at 0 after every done (the paper's U_θ per episode)."""
    g = 0.5
    mean, best, count = sc.episode_returns(REWARD, DONE, g)
    # env 0: episode (0, 2) → 0 + g·2 = 1; env 1: episodes (1) → 1 and (0, 3, 0) → g·3 = 1.5
    np.testing.assert_allclose(mean, [1.0, 1.25])
    np.testing.assert_allclose(best, [1.0, 1.5])
    np.testing.assert_array_equal(count, [1, 2])
    # the unfinished tail is discounted from its own start: (1, 2) → 1 + g·2
    mean, _, _ = sc.episode_returns(jnp.array([[1.0], [2.0]]), jnp.array([[False], [False]]), g)
    assert float(mean[0]) == 2.0


def test_score_formulas():
    mean = jnp.array([0.5, -1.0])
    np.testing.assert_allclose(sc.perfect_regret(mean, jnp.array([1.0, 10.0])), [0.5, 11.0])
    np.testing.assert_allclose(sc.negative_return(mean), [-0.5, 1.0])


# [T=4, N=3]. env 0: episodes [t0] and [t1..t3]; env 1: episode [t0], then an unfinished tail;
# env 2: no finished episode (scored from its truncated rollout: tests/test_long_episode_scores.py).
X = jnp.array([[1.0, 2.0, 5.0], [3.0, -1.0, 5.0], [-2.0, 4.0, 5.0], [6.0, 8.0, 5.0]])
EPISODE_DONE = jnp.array([[True, True, False], [False, False, False], [False, False, False], [True, False, False]])
MAX_RETURN = jnp.array([4.0, 3.0, 1.0])
# PVL: max(X, 0) per episode: env 0 -> mean(1, mean(3, 0, 6) = 3) = 2; env 1 -> 2 (tail left out)
PVL = [2.0, 2.0, 5.0]  # env 2: the mean of max(X, 0) over all its steps
# MaxMC with values X: max_return - X is env 0 [3, 1, 6, -2] -> mean(3, 5/3) = 7/3; env 1 [1, ...] -> 1
# env 2 (advantages X too): max(1, V_0 + A_0 = 10) − 5 at every step -> 5
MAXMC = [7 / 3, 1.0, 5.0]


def test_pvl_and_maxmc_average_per_finished_episode():
    np.testing.assert_allclose(sc.positive_value_loss(X, EPISODE_DONE), PVL, rtol=1e-6)
    np.testing.assert_allclose(sc.max_mc(X, MAX_RETURN, EPISODE_DONE, X), MAXMC, rtol=1e-6)


def test_one_step_episodes_reduce_to_the_mean_over_steps():
    done = jnp.ones_like(EPISODE_DONE)
    np.testing.assert_allclose(sc.positive_value_loss(X, done), [2.5, 3.5, 5.0], rtol=1e-6)
    np.testing.assert_allclose(sc.max_mc(X, MAX_RETURN, done, X), [2.0, -0.25, -4.0], rtol=1e-6)


def test_score_levels_dispatches_by_name():
    mean = jnp.array([0.5, -1.0, 2.0])
    optimal = jnp.array([1.0, 10.0, 2.0])
    expected = {"perfect_regret": [0.5, 11.0, 0.0], "pvl": PVL, "maxmc": MAXMC, "neg_return": [-0.5, 1.0, -2.0],
                "learnability": [0.0, 0.0, -np.inf]}  # X's returns are all positive: p = 1 where an episode ended
    assert set(expected) == set(sc.SCORES)
    for name, want in expected.items():
        got = sc.score_levels(name, sc.ScoreInputs(mean_return=mean, values=X, advantages=X, max_return=MAX_RETURN,
                                                   done=EPISODE_DONE, optimal_return=optimal, reward=X,
                                                   solved=lambda ret: ret > 0))
        np.testing.assert_allclose(got, want, rtol=1e-6, err_msg=name)


def test_pvl_and_maxmc_agree_with_jaxued(monkeypatch):
    """jaxued's scores (from minimax's ued_scores.py) are the reference; jaxued still calls the
    removed ``jax.tree_map``."""
    import jax

    monkeypatch.setattr(jax, "tree_map", jax.tree.map, raising=False)
    from jaxued import utils as ref

    k_x, k_done, k_max = jax.random.split(jax.random.PRNGKey(0), 3)
    x = jax.random.normal(k_x, (40, 6))
    done = (jax.random.uniform(k_done, (40, 6)) < 0.15).at[:, 0].set(False)  # env 0: no finished episode
    max_return = jax.random.normal(k_max, (6,))
    # where an episode ended; env 0 (none: the references' -inf) is scored from its truncated rollout
    np.testing.assert_allclose(sc.positive_value_loss(x, done)[1:], ref.positive_value_loss(done, x)[1:], rtol=1e-5)
    np.testing.assert_allclose(sc.max_mc(x, max_return, done, x)[1:], ref.max_mc(done, x, max_return)[1:], rtol=1e-5)
    assert np.isfinite(sc.positive_value_loss(x, done)[0]) and np.isfinite(sc.max_mc(x, max_return, done, x)[0])


def test_perfect_regret_of_a_maze_level_is_discounted_by_default():
    """The paper's utility is discounted: a level solved in 2n actions whose shortest path is n
    scores γ^(n−1)·R(n) − γ^(2n−1)·R(2n) by default, R(n) − R(2n) with discounted_regret off."""
    import dataclasses
    from types import SimpleNamespace

    from remidi.engine.learner import Collection, score_rollout
    from remidi.engine.train import make_setup
    from remidi.envs import maze as M
    from remidi.experiments.maze import paper_config

    cfg = paper_config()
    task = M.maze_task("tmaze")
    level = jax.tree.map(lambda x: x[None], M.prefab_level("StandardMaze"))
    n = int(M.shortest_path_steps(jax.tree.map(lambda x: x[0], level)))
    g, steps = cfg.ppo.gamma, 2 * n
    reward = np.zeros((steps, 1), np.float32)
    reward[-1] = 1 - 0.9 * steps / M.MAX_STEPS
    done = np.zeros((steps, 1), bool)
    done[-1] = True
    traj = SimpleNamespace(reward=jnp.asarray(reward), done=jnp.asarray(done), value=jnp.zeros((steps, 1)), solved=None)
    mean_return = jnp.asarray(reward.sum(0))

    def level_score(c):
        collection = Collection(traj=traj, advantages=jnp.zeros((steps, 1)), targets=jnp.zeros((steps, 1)),
                                mean_return=mean_return, best_return=mean_return)
        return float(score_rollout(make_setup(task, c, "plr"), level, collection)[0])

    discounted = g ** (n - 1) * (1 - 0.9 * n / 250) - g ** (steps - 1) * (1 - 0.9 * steps / 250)
    np.testing.assert_allclose(level_score(cfg), discounted, rtol=1e-4)
    np.testing.assert_allclose(level_score(dataclasses.replace(cfg, discounted_regret=False)), 0.9 * n / 250,
                               rtol=1e-4)
    assert abs(discounted - 0.9 * n / 250) > 0.05  # the two forms really differ on this level


def test_learnability_is_p_times_one_minus_p_over_finished_episodes():
    """SFL's score on a hand-built rollout: env 0 solves 1 of 2 finished episodes (p = 1/2: 0.25),
    env 1 solves 3 of 3 (0), env 2 1 of 4 (3/16), env 3 finishes none (-inf, like PVL/MaxMC); an
    unfinished trailing episode never counts, solved or not."""
    solved = lambda ret: ret > 0  # noqa: E731  the maze's criterion
    r = np.zeros((8, 4), np.float32)
    d = np.zeros((8, 4), bool)
    r[1, 0], d[1, 0], d[3, 0], r[5, 0] = 1.0, True, True, 1.0  # solved, failed, then an unfinished solve
    r[[0, 2, 4], 1], d[[0, 2, 4], 1] = 0.5, True
    r[0, 2], d[[0, 1, 2, 3], 2] = 0.8, True
    r[:, 3] = 1.0
    got = np.asarray(sc.learnability(jnp.asarray(r), jnp.asarray(d), solved))
    np.testing.assert_allclose(got, [0.25, 0.0, 3 / 16, -np.inf])
    p, count = sc.solve_rate(jnp.asarray(r), jnp.asarray(d), solved)
    np.testing.assert_allclose(p, [0.5, 1.0, 0.25, 0.0])
    np.testing.assert_array_equal(count, [2, 3, 4, 0])
    # a policy that never solves and one that always solves both score 0: nothing left to learn
    assert float(sc.learnability(jnp.zeros((4, 1)), jnp.ones((4, 1), bool), solved)[0]) == 0.0


def test_the_engine_scores_levels_by_learnability_with_the_tasks_solve_criterion():
    import dataclasses
    from types import SimpleNamespace

    from remidi.engine.learner import Collection, score_rollout
    from remidi.engine.train import make_setup
    from remidi.envs.lever import lever_task
    from remidi.experiments.lever import paper_config

    task = lever_task(64)
    cfg = dataclasses.replace(paper_config(), score="learnability")
    reward = jnp.asarray([[1.0, -10.0], [-1.0, -10.0], [1.0, 10.0], [1.0, -10.0]])  # one-step episodes
    traj = SimpleNamespace(reward=reward, done=jnp.ones((4, 2), bool), value=jnp.zeros((4, 2)), solved=None)
    levels = jax.tree.map(lambda x: x[:2], task.eval_sets["visible"])
    collection = Collection(traj=traj, advantages=jnp.zeros((4, 2)), targets=jnp.zeros((4, 2)),
                            mean_return=jnp.zeros(2), best_return=jnp.zeros(2))
    got = score_rollout(make_setup(task, cfg, "plr"), levels, collection)
    np.testing.assert_allclose(got, [0.75 * 0.25, 0.25 * 0.75])


def test_a_replay_that_ends_no_episode_leaves_the_maxmc_record_as_it_was():
    """MaxMC's record is the best return of an episode that ended. A replay whose rollout is
    shorter than the episode (−0.5 per step, 3-step episodes, 1-step rollouts) ends none: its
    partial return −0.5 would beat the record −5 of the level's whole episodes and stay in it."""
    import dataclasses

    from flax import struct

    from remidi.engine import train as tr
    from remidi.engine.config import UEDConfig
    from remidi.envs.interface import UEDTask, UnderspecifiedEnv

    @struct.dataclass
    class Level:
        x: jax.Array  # f32[]: nothing the game reads

    class Cost(UnderspecifiedEnv):
        @property
        def default_params(self):
            return None

        def action_space(self, params):
            from gymnax.environments import spaces

            return spaces.Discrete(2)

        def reset_env_to_level(self, rng, level, params):
            return jnp.zeros(2), jnp.zeros((), jnp.int32)

        def step_env(self, rng, t, action, params):
            return jnp.zeros(2), t + 1, jnp.asarray(-0.5), t + 1 >= 3, {}

    task = UEDTask(env=Cost(), params=None, sample_level=lambda rng: Level(x=jax.random.uniform(rng)), num_actions=2,
                   max_episode_steps=3, optimal_return=lambda level: jnp.asarray(-1.5),
                   eval_sets={"one": Level(x=jnp.zeros(1))}, deterministic_reset=True)
    base = UEDConfig()
    cfg = UEDConfig(num_updates=1, num_envs=4, num_steps=1, network="mlp", hidden_size=8, score="maxmc",
                    buffer=dataclasses.replace(base.buffer, capacity=4, min_fill=0.25, replay_prob=1.0))
    setup = tr.make_setup(task, cfg, "plr")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    bufs = runner.adversary.buffers  # [K=1, C=4]: four levels whose record is a whole episode's −5
    runner = runner.replace(adversary=runner.adversary.replace(buffers=bufs.replace(
        valid=jnp.ones_like(bufs.valid), scores=jnp.ones_like(bufs.scores),
        extras={"max_return": jnp.full_like(bufs.extras["max_return"], -5.0)})))
    after, metrics = jax.jit(lambda r: tr.train_step(setup, r))(runner)
    assert float(metrics["replay"]) == 1.0  # a replay of the four levels
    np.testing.assert_array_equal(np.asarray(after.adversary.buffers.extras["max_return"]), -5.0)
