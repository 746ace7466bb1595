"""PVL and MaxMC on rollouts shorter than an episode (scores.py's module docstring): checked
against GAE and the scores computed by hand in numpy, with and without finished episodes; the
short-rollout warning; and PLR⊥'s buffer on a task whose episodes outlast the rollout."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from remidi.engine.adversaries import scores as sc
from remidi.engine.config import UEDConfig
from remidi.engine.learner import compute_gae
from remidi.engine.run.validation import run_warnings
from remidi.envs.interface import UEDTask, UnderspecifiedEnv

GAMMA, LAM = 0.9, 0.8
# [T=5, N=3]. env 0: episodes [t0..t1] and [t2..t3], then an unfinished t4; env 1 and env 2: no
# episode ends (env 2 with a record of 4.0 from an earlier replay, above its bootstrapped return)
REWARD = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.5], [0.0, 2.0, 0.0], [2.0, 0.0, 0.0], [0.5, 1.0, 0.0]], np.float32)
VALUE = np.array([[0.5, 1.0, 0.2], [0.8, 1.5, 0.4], [0.3, 0.5, 0.1], [1.2, 2.0, 0.3], [0.1, 0.7, 0.6]], np.float32)
DONE = np.zeros((5, 3), bool)
DONE[[1, 3], 0] = True
LAST_VALUE = np.array([0.4, 1.2, 0.5], np.float32)
RECORD = np.array([2.5, -np.inf, 4.0], np.float32)  # MaxMC's max_return: −inf where no episode ever ended


def hand_gae(reward, value, done, last_value):
    """GAE by its definition: δ_t = r_t + γ(1 − d_t)V_{t+1} − V_t, A_t = δ_t + γλ(1 − d_t)A_{t+1}."""
    t_len, n = reward.shape
    adv = np.zeros((t_len, n))
    for e in range(n):
        nxt = 0.0
        for t in reversed(range(t_len)):
            v_next = last_value[e] if t == t_len - 1 else value[t + 1, e]
            delta = reward[t, e] + GAMMA * (1 - done[t, e]) * v_next - value[t, e]
            nxt = delta + GAMMA * LAM * (1 - done[t, e]) * nxt
            adv[t, e] = nxt
    return adv


def hand_scores(adv, value, done, record):
    """Per env: PVL and MaxMC as the module docstring defines them, loop by loop."""
    pvl, maxmc = [], []
    for e in range(adv.shape[1]):
        ends = [t for t in range(adv.shape[0]) if done[t, e]]
        if ends:  # today's scores: per finished episode its per-step mean, then the mean; the tail left out
            starts = [0] + [t + 1 for t in ends[:-1]]
            pvl.append(np.mean([np.mean(np.maximum(adv[s:t + 1, e], 0)) for s, t in zip(starts, ends)]))
            maxmc.append(np.mean([np.mean(record[e] - value[s:t + 1, e]) for s, t in zip(starts, ends)]))
        else:  # the truncated episode, bootstrapped: the GAE over all steps, best = max(record, V_0 + A_0)
            pvl.append(np.mean(np.maximum(adv[:, e], 0)))
            best = max(record[e], value[0, e] + adv[0, e])
            maxmc.append(np.mean(best - value[:, e]))
    return np.array(pvl), np.array(maxmc)


@pytest.fixture(scope="module")
def advantages():
    adv, _ = compute_gae(jnp.asarray(REWARD), jnp.asarray(VALUE), jnp.asarray(DONE), jnp.asarray(LAST_VALUE),
                         GAMMA, LAM)
    return np.asarray(adv)


def test_gae_bootstraps_from_the_last_value(advantages):
    np.testing.assert_allclose(advantages, hand_gae(REWARD, VALUE, DONE, LAST_VALUE), rtol=1e-5, atol=1e-6)
    # env 1's last step: r + γ·V(s_T) − V, V(s_T) the value after the rollout
    assert advantages[4, 1] == pytest.approx(1.0 + GAMMA * 1.2 - 0.7, rel=1e-5)


def test_pvl_and_maxmc_match_the_hand_computation(advantages):
    want_pvl, want_maxmc = hand_scores(advantages, VALUE, DONE, RECORD)
    inputs = sc.ScoreInputs(mean_return=jnp.zeros(3), values=jnp.asarray(VALUE), advantages=jnp.asarray(advantages),
                            max_return=jnp.asarray(RECORD), done=jnp.asarray(DONE), reward=jnp.asarray(REWARD))
    np.testing.assert_allclose(sc.score_levels("pvl", inputs), want_pvl, rtol=1e-5)
    np.testing.assert_allclose(sc.score_levels("maxmc", inputs), want_maxmc, rtol=1e-5)
    assert np.all(np.isfinite(want_pvl)) and np.all(np.isfinite(want_maxmc))
    # env 2's record (4.0) beats its bootstrapped return; env 1 has only the bootstrapped one
    assert VALUE[0, 2] + advantages[0, 2] < RECORD[2]
    np.testing.assert_allclose(want_maxmc[1], VALUE[0, 1] + advantages[0, 1] - VALUE[:, 1].mean(), rtol=1e-6)


def test_where_episodes_finish_the_score_is_unchanged(advantages):
    """Env 0's episodes end inside the rollout: the references' (jaxued's) formula, the trailing
    unfinished step left out, whatever its advantage."""
    pvl = np.asarray(sc.positive_value_loss(jnp.asarray(advantages), jnp.asarray(DONE)))
    tail_changed = advantages.copy()
    tail_changed[4, 0] = 100.0
    again = np.asarray(sc.positive_value_loss(jnp.asarray(tail_changed), jnp.asarray(DONE)))
    assert again[0] == pvl[0]
    np.testing.assert_allclose(pvl[0], sc.episode_mean(jnp.maximum(jnp.asarray(advantages), 0), jnp.asarray(DONE))[0])


def test_pvl_and_maxmc_no_longer_warn_of_short_rollouts_but_learnability_does():
    assert not sc.SCORES["pvl"].needs_finished_episodes and not sc.SCORES["maxmc"].needs_finished_episodes
    assert sc.SCORES["learnability"].needs_finished_episodes
    task = long_task()
    cfg = dataclasses.replace(UEDConfig(), num_steps=8)
    for score in ("pvl", "maxmc"):
        assert not any("num_steps" in w for w in run_warnings(dataclasses.replace(cfg, score=score), "plr", task))
    (line,) = [w for w in run_warnings(dataclasses.replace(cfg, score="learnability"), "plr", task)
               if "num_steps" in w]
    assert "learnability" in line and f"num_steps={LONG}" in line and "-inf" in line and "\n" not in line


# ---------------------------------------------------------------- a task whose episodes outlast the rollout

K, LONG = 8, 1000


@struct.dataclass
class BeaconState:
    target: jax.Array  # i32[]
    t: jax.Array  # i32[]


class Beacon(UnderspecifiedEnv):
    """A level is a target in [0, K), shown one-hot; every step pays (1 + target)/K for the
    target's action, 0 otherwise; an episode lasts LONG steps."""

    @property
    def default_params(self):
        return None

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(K)

    def reset_env_to_level(self, rng, level, params):
        return jax.nn.one_hot(level, K), BeaconState(target=level, t=jnp.zeros((), jnp.int32))

    def step_env(self, rng, state, action, params):
        reward = jnp.where(action == state.target, (1.0 + state.target) / K, 0.0)
        state = state.replace(t=state.t + 1)
        return jax.nn.one_hot(state.target, K), state, reward, state.t >= LONG, {}


def long_task() -> UEDTask:
    return UEDTask(env=Beacon(), params=None, sample_level=lambda k: jax.random.randint(k, (), 0, K),
                   num_actions=K, max_episode_steps=LONG, solved=None, deterministic_reset=True,
                   eval_sets={"all": jnp.arange(K)})


@pytest.mark.parametrize("score", ["pvl", pytest.param("maxmc", marks=pytest.mark.slow)])  # one compile each
def test_plr_fills_its_buffer_on_episodes_longer_than_the_rollout(score):
    """PLR⊥ with 8-step rollouts of 1000-step episodes: every fresh level is scored (finite), so
    the buffer holds more than one level (before, each scored −inf and none was inserted)."""
    from remidi.engine.run import driver

    base = UEDConfig()
    cfg = dataclasses.replace(base, score=score, num_updates=8, num_envs=4, num_steps=8, eval_every=8,
                              eval_attempts=1, checkpoint_every=8, hidden_size=16,
                              ppo=dataclasses.replace(base.ppo, epochs=1, minibatches=1),
                              buffer=dataclasses.replace(base.buffer, capacity=16, min_fill=0.5))
    runner = driver.train_seeds(long_task(), cfg, "plr", [0], progress=False).runner
    buffers = runner.adversary.buffers
    valid = np.asarray(buffers.valid)[0]
    assert valid.sum() > 1
    assert np.all(np.isfinite(np.asarray(buffers.scores)[0][valid]))
