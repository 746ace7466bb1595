"""Continuous actions through the one engine path: the Gaussian policy's log-probability and
entropy against closed forms, the running observation statistics against NumPy, continuous PPO
learning a target, and a UED run of every algorithm on a continuous toy task."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct
from scipy import stats

from remidi.engine.core import normalize as nrm
from remidi.engine import learner as lrn
from remidi.engine import train as tr
from remidi.engine.config import ReMiDiConfig, UEDConfig
from remidi.engine.run.validation import validate_ued_config
from remidi.engine.core.distributions import ACTIONS, CATEGORICAL, GAUSSIAN, Greedy, acting, for_task
from remidi.engine.core.networks import make_network
from remidi.engine.learner import Batch, ppo_update
from remidi.engine.core.ppo import PPOConfig, create_train_state
from remidi.envs.interface import UEDTask, UnderspecifiedEnv, one_step_discounted


def test_gaussian_log_prob_and_entropy_match_closed_forms():
    rng = np.random.default_rng(0)
    mean, log_std = rng.normal(size=(5, 3)), rng.normal(size=(5, 3)) * 0.5
    action = rng.normal(size=(5, 3)) * 2
    out = jnp.asarray(np.concatenate([mean, log_std], axis=-1), jnp.float32)
    expected = stats.norm.logpdf(action, mean, np.exp(log_std)).sum(-1)
    np.testing.assert_allclose(GAUSSIAN.log_prob(out, jnp.asarray(action, jnp.float32)), expected, rtol=1e-5)
    np.testing.assert_allclose(GAUSSIAN.entropy(out), stats.norm.entropy(mean, np.exp(log_std)).sum(-1), rtol=1e-5)
    # samples follow the distribution: mean and std over many draws
    draws = GAUSSIAN.sample(jax.random.PRNGKey(0), jnp.broadcast_to(out[0], (20000, 6)))
    np.testing.assert_allclose(draws.mean(0), mean[0], atol=0.05 * np.exp(log_std[0]).max() + 0.02)
    np.testing.assert_allclose(draws.std(0), np.exp(log_std[0]), rtol=0.05)
    assert for_task(True) is GAUSSIAN and for_task(False) is CATEGORICAL


def test_categorical_log_prob_and_entropy_match_closed_forms():
    logits = jnp.asarray([[0.0, 1.0, -2.0], [3.0, 3.0, 3.0]])
    p = np.exp(logits) / np.exp(logits).sum(-1, keepdims=True)
    np.testing.assert_allclose(CATEGORICAL.log_prob(logits, jnp.asarray([2, 0])), np.log([p[0, 2], p[1, 0]]), rtol=1e-6)
    np.testing.assert_allclose(CATEGORICAL.entropy(logits), -(p * np.log(p)).sum(-1), rtol=1e-6)


def test_greedy_acts_with_the_mean_or_the_arg_max_and_scores_as_its_base():
    key = jax.random.PRNGKey(0)
    out = jnp.array([[0.3, -1.0, 2.0, 0.5], [1.5, 0.0, -0.2, -3.0]])  # Gaussian: means [.3, -1], log-stds [2, .5]
    mode = acting(GAUSSIAN, "mode")
    assert isinstance(mode, Greedy) and mode.continuous and acting(GAUSSIAN, "sample") is GAUSSIAN
    for k in jax.random.split(key, 3):  # the same action whatever the key: the mean
        np.testing.assert_array_equal(mode.sample(k, out), out[:, :2])
    action = jnp.array([[0.0, 0.0], [1.0, 1.0]])
    np.testing.assert_array_equal(mode.log_prob(out, action), GAUSSIAN.log_prob(out, action))
    logits = jnp.array([[0.1, 2.0, -1.0], [3.0, 0.0, 2.9]])
    greedy = acting(CATEGORICAL, "mode")
    np.testing.assert_array_equal(greedy.sample(key, logits), [1, 0])
    np.testing.assert_array_equal(greedy.probs(logits), [[0, 1, 0], [1, 0, 0]])
    np.testing.assert_allclose(CATEGORICAL.probs(logits), jax.nn.softmax(logits))
    with pytest.raises(Exception, match=f"--action: unknown value 'mean'; allowed: {', '.join(ACTIONS)}$"):
        acting(CATEGORICAL, "mean")


def test_running_statistics_equal_numpy_over_all_batches():
    rng = np.random.default_rng(1)
    batches = [rng.normal(3.0, 2.0, size=(n, 4)) * [1, 10, 0.1, 1] for n in (7, 1, 30)]
    s = nrm.init_stats(4)
    for b in batches:
        s = nrm.update_stats(s, jnp.asarray(b, jnp.float32))
    allx = np.concatenate(batches)
    np.testing.assert_allclose(s.mean, allx.mean(0), rtol=1e-5)
    np.testing.assert_allclose(s.var, allx.var(0), rtol=1e-4)
    assert float(s.count) == len(allx)
    z = nrm.normalize(s, jnp.asarray(allx, jnp.float32))
    np.testing.assert_allclose(z.mean(0), 0, atol=1e-4)
    np.testing.assert_allclose(z.std(0), 1, rtol=1e-3)
    # an all-constant entry normalises to 0, never to inf or nan
    s = nrm.update_stats(nrm.init_stats(1), jnp.ones((5, 1)))
    assert np.all(np.isfinite(nrm.normalize(s, jnp.ones((2, 1)))))


@pytest.mark.parametrize("kind", ["mlp", "mlp_lstm"])
def test_continuous_networks_output_a_mean_and_a_state_independent_log_std(kind):
    net = make_network(kind, 3, continuous=True, **({"lstm_size": 8} if kind == "mlp_lstm" else {}))
    obs = jnp.ones((2, 4, 5))
    params = net.init(jax.random.PRNGKey(0), net.initialize_carry(4), obs, jnp.ones((2, 4), bool))["params"]
    _, (out, value) = net.apply({"params": params}, net.initialize_carry(4), obs * jnp.arange(4.0)[:, None],
                                jnp.ones((2, 4), bool))
    assert out.shape == (2, 4, 6) and value.shape == (2, 4)
    np.testing.assert_array_equal(out[..., 3:], 0.0)  # log-std starts at 0 (std 1), whatever the observation
    assert params["heads"]["log_std"].shape == (3,)


def test_continuous_ppo_learns_to_hit_a_target():
    """One-step episodes: observation x ∈ {−1, 1}, reward −(a − x)²; the mean must follow x."""
    net = make_network("mlp", 1, continuous=True, hidden=(32,))
    cfg = PPOConfig(epochs=4, minibatches=2, lr=3e-3, anneal_lr=False, gamma=0.0, gae_lambda=0.0, ent_coef=0.0,
                    total_updates=200)
    n = 64
    state = create_train_state(jax.random.PRNGKey(0), net, jnp.zeros((1, n, 1)), n, cfg)

    @jax.jit
    def update(state, key):
        k_obs, k_act, k_ppo = jax.random.split(key, 3)
        x = jnp.where(jax.random.bernoulli(k_obs, 0.5, (1, n, 1)), 1.0, -1.0)
        reset = jnp.ones((1, n), bool)
        _, (out, value) = net.apply({"params": state.params}, net.initialize_carry(n), x, reset)
        action = GAUSSIAN.sample(k_act, out)
        reward = -jnp.square(action - x)[..., 0]
        batch = Batch(obs=x, reset=reset, actions=action, log_probs=GAUSSIAN.log_prob(out, action), values=value,
                      advantages=reward - value, targets=reward, mask=jnp.ones((1, n), bool))
        state, metrics = ppo_update(state, net.initialize_carry(n), batch, k_ppo, cfg, net.apply, GAUSSIAN)
        return state, jnp.mean(reward)

    keys = jax.random.split(jax.random.PRNGKey(1), 200)
    first = None
    for key in keys:
        state, r = update(state, key)
        first = r if first is None else first
    x = jnp.asarray([[[1.0], [-1.0]]])
    _, (out, _) = net.apply({"params": state.params}, net.initialize_carry(2), x, jnp.ones((1, 2), bool))
    mean = GAUSSIAN.split(out)[0][0, :, 0]
    assert float(mean[0]) > 0.7 and float(mean[1]) < -0.7, mean  # the mean follows the target
    assert float(r) > 0.5 * float(first)  # less negative: the squared error shrank


# ------------------------------------------------------------------ a continuous UED toy task
@struct.dataclass
class TargetLevel:
    target: jax.Array  # f32[2]
    hidden: jax.Array  # bool[]: the target is not shown (irreducible regret)


class TargetEnv(UnderspecifiedEnv):
    """One step: observation = (target, 0) or (0, 0, 1) when hidden; reward 1 − |a − target|²."""

    @property
    def default_params(self):
        return None

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Box(-1.0, 1.0, (2,))

    def _obs(self, level):
        shown = jnp.where(level.hidden, 0.0, level.target)
        return jnp.concatenate([shown, level.hidden[None].astype(jnp.float32)])

    def reset_env_to_level(self, rng, level, params):
        return self._obs(level), level

    def step_env(self, rng, state, action, params):
        reward = 1.0 - jnp.sum(jnp.square(action - state.target))
        return self._obs(state), state, reward, jnp.asarray(True), {}


def target_task():
    env = TargetEnv()

    def sample(rng):
        k1, k2 = jax.random.split(rng)
        return TargetLevel(target=jax.random.uniform(k1, (2,), minval=-1, maxval=1), hidden=jax.random.bernoulli(k2))

    grid = jnp.stack(jnp.meshgrid(jnp.linspace(-0.8, 0.8, 3), jnp.linspace(-0.8, 0.8, 3)), -1).reshape(-1, 2)
    return UEDTask(env=env, params=None, sample_level=sample, num_actions=2, max_episode_steps=1,
                   optimal_return=lambda level: jnp.asarray(1.0),
                   optimal_discounted_return=one_step_discounted(lambda level: jnp.asarray(1.0)),
                   eval_sets={"shown": TargetLevel(target=grid, hidden=jnp.zeros(9, bool))},
                   level_tags=lambda level: {"hidden": level.hidden}, deterministic_reset=True, continuous=True)


TASK = target_task()
TINY = UEDConfig(num_updates=6, num_envs=8, num_steps=4, network="mlp", hidden_size=16, eval_every=3,
                    eval_attempts=2, checkpoint_every=3, reward_scale=0.1, normalize_obs=True,
                    ppo=PPOConfig(epochs=1, minibatches=2),
                    buffer=dataclasses.replace(UEDConfig().buffer, capacity=8, min_fill=0.25),
                    remidi=ReMiDiConfig(num_buffers=2, buffer_capacity=8, steps_per_buffer=3, tracker_budget=2))


# DR trains on fresh levels; ReMiDi's first buffer is PLR⊥ (minimax return differs only in its score).
# Through the driver, as a run trains: ReMiDi's programs are then the resume test's (one compile).
@pytest.mark.parametrize("algo", ["dr", "remidi"])
def test_algorithms_train_on_continuous_actions(algo):
    from remidi.engine.run import driver

    assert TASK.sample_level(jax.random.PRNGKey(0)).target.shape == (2,)
    result = driver.train_seeds(TASK, TINY, algo, [0], progress=False)
    hist, runner = result.history, result.runner
    runner = jax.tree.map(lambda x: x[0], runner)  # the one seed
    assert runner.learner.obs_stats.mean.shape == (3,)
    # NaN by definition: a replay share of an update without replays, a buffer not yet reached
    assert all(np.all(np.isfinite(v)) for name, v in hist.items()
               if not name.startswith(("replay_fraction", "buffer_solve_rate")))
    assert float(runner.learner.obs_stats.count) == TINY.num_updates * TINY.num_envs * TINY.num_steps
    assert -10 < float(hist["return/shown"][0, -1]) <= 1.0 and np.isfinite(hist["regret/shown/worst"][0, -1])
    rejected = float(hist["rejected"].sum())
    if algo == "remidi":  # the second buffer rejects hidden levels: one frozen hidden level plays them all
        assert int(runner.adversary.active) == 1 and rejected > 0
        hidden = runner.adversary.buffers.valid & runner.adversary.buffers.levels.hidden  # [K, C]
        assert bool(jnp.any(hidden[0])) and not bool(jnp.any(hidden[1])) and bool(jnp.any(runner.adversary.buffers.valid[1]))
    else:
        assert rejected == 0


def test_normalize_obs_rules_are_one_line_errors():
    from remidi.errors import ConfigError

    with pytest.raises(ConfigError, match="^remidi.policy: must be masked with normalize_obs"):
        validate_ued_config(dataclasses.replace(TINY, remidi=dataclasses.replace(TINY.remidi, policy="combine")),
                               "remidi", TASK)
    with pytest.raises(ConfigError, match="^reward_scale: must be > 0"):
        validate_ued_config(dataclasses.replace(TINY, reward_scale=0.0), "plr", TASK)
    with pytest.raises(ConfigError, match="^lstm_size: the network mlp has no such layer"):
        validate_ued_config(dataclasses.replace(TINY, lstm_size=8), "plr", TASK)


@pytest.mark.parametrize("score", ["pvl", "maxmc"])
def test_scores_are_in_the_environments_units_whatever_the_reward_scale(score):
    """The critic learns reward × reward_scale; a level's score must not depend on that scale."""
    plain = dataclasses.replace(TINY, score=score, reward_scale=1.0, normalize_obs=False)
    setup = tr.make_setup(TASK, plain, "plr")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    levels = jax.vmap(TASK.sample_level)(jax.random.split(jax.random.PRNGKey(1), TINY.num_envs))
    collection = lrn.collect(setup, runner.learner, jax.random.PRNGKey(2), levels, None)
    scaled = tr.make_setup(TASK, dataclasses.replace(plain, reward_scale=0.1), "plr")
    expected = lrn.score_rollout(setup, levels, collection)
    traj = collection.traj
    got = lrn.score_rollout(scaled, levels, collection.replace(traj=traj.replace(value=traj.value * 0.1),
                                                               advantages=collection.advantages * 0.1))
    np.testing.assert_allclose(got, expected, rtol=1e-5)
    assert np.all(np.isfinite(np.asarray(expected)))


def test_observation_statistics_survive_a_resume(tmp_path):
    from remidi.engine.run import driver

    class Crash(Exception):
        pass

    def crash(done, metrics):
        if done == 3:
            raise Crash

    result = driver.train_seeds(TASK, TINY, "remidi", [0], progress=False)
    full, runner = result.history, result.runner
    with pytest.raises(Crash):
        driver.train_seeds(TASK, TINY, "remidi", [0], out=tmp_path, progress=False, on_block=crash)
    second = driver.train_seeds(TASK, TINY, "remidi", [0], out=driver.RunFolder(tmp_path, resume=True),
                                progress=False)
    resumed, runner_b = second.history, second.runner
    assert float(runner.learner.obs_stats.count[0]) == TINY.num_updates * TINY.num_envs * TINY.num_steps
    for a, b in zip(jax.tree.leaves(runner), jax.tree.leaves(runner_b)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    for name in full:
        np.testing.assert_array_equal(full[name], resumed[name], err_msg=name)


def test_floors_play_the_evaluated_levels_with_zero_and_with_normal_actions():
    """The floors of docs/results.md's Brax section (tools.results.floors), on the toy
    task: zero action earns 1 − |target|² on each level; N(0, 1) actions lose their variance,
    2 more in expectation; the episodes after the first, inside the scan, do not count."""
    from tools.results.floors import floor_returns

    levels = TASK.eval_sets["shown"]  # one-step episodes in a 3-step scan: the first episode's return only
    task = dataclasses.replace(TASK, eval_sets={"undisturbed": levels}, max_episode_steps=3)
    expected = 1.0 - np.sum(np.square(np.asarray(levels.target)), axis=1)
    np.testing.assert_allclose(np.asarray(floor_returns(task, "undisturbed", "zero", 1))[:, 0], expected, rtol=1e-5)
    noisy = np.asarray(floor_returns(task, "undisturbed", "normal", 4000)).mean(axis=1)
    np.testing.assert_allclose(noisy, expected - 2.0, atol=0.25)
