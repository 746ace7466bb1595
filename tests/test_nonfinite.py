"""A NaN or infinite reward or observation stops every algorithm's run with one line naming the
metric and the first update it came in, and nothing of that block is written (the last good
checkpoint stays). Before, PLR⊥ and ReMiDi finished "successfully" on a NaN reward: the NaN scores
never entered the buffer, nothing replayed, nothing trained, every metric n/a."""

import dataclasses
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_ued_engine import TINY  # noqa: E402

from remidi.cli import main  # noqa: E402
from remidi.engine import train as tr  # noqa: E402
from remidi.engine.algorithms import BUILTIN_ALGORITHMS  # noqa: E402
from remidi.engine.learner import Trajectory, nonfinite  # noqa: E402
from remidi.engine.run import driver  # noqa: E402
from remidi.engine.run.checkpoint import CHECKPOINT, load_checkpoint  # noqa: E402
from remidi.envs.lever import LeverBuilder, LeverGame, lever_task  # noqa: E402
from remidi.errors import RemidiError  # noqa: E402

R = dataclasses.replace
#: one seed, 4 envs, blocks of one update, a checkpoint after each: every test shares its programs
CFG = R(TINY, num_updates=2, num_envs=4, num_steps=2, eval_every=1, checkpoint_every=1, hidden_size=16,
        buffer=R(TINY.buffer, capacity=4, topk_k=2),
        remidi=R(TINY.remidi, num_buffers=2, buffer_capacity=4, steps_per_buffer=1),
        sfl=R(TINY.sfl, batch_size=4, num_batches=1, rollout_steps=2, buffer_size=2, refresh_every=2))
QUICK = ("dr", "plr", "remidi")  # the rest in the slow tier


class NaNReward(LeverGame):
    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = super().step_env(rng, state, action, params)
        return obs, state, reward * jnp.nan, done, info


class NaNObservation(LeverGame):
    def observation(self, level):
        return super().observation(level).at[0].set(jnp.inf)


class NaNBuilder(LeverBuilder):  # PAIRED's generator sees a NaN
    def show(self, design):
        return jnp.full((1,), jnp.nan)


NAN_REWARD = R(lever_task(8), env=NaNReward(8))
NAN_OBSERVATION = R(lever_task(8), env=NaNObservation(8))


def test_the_flags_read_rewards_and_the_floating_observation_leaves():
    t, n = 3, 2
    obs = {"image": jnp.zeros((t, n, 4)), "count": jnp.full((t, n), 7, jnp.int32)}
    clean = Trajectory(obs=obs, reset=jnp.zeros((t, n), bool), action=jnp.zeros((t, n), jnp.int32),
                       log_prob=jnp.zeros((t, n)), value=jnp.zeros((t, n)), reward=jnp.zeros((t, n)),
                       done=jnp.zeros((t, n), bool), indist=jnp.zeros((t, n), bool), overflow=jnp.zeros((t, n), jnp.int32))
    assert nonfinite(clean) == {"nonfinite/reward": 0.0, "nonfinite/observation": 0.0}
    bad_reward = clean.replace(reward=clean.reward.at[2, 1].set(-jnp.inf))
    assert nonfinite(bad_reward, "antagonist") == {"nonfinite/reward/antagonist": 1.0,
                                                   "nonfinite/observation/antagonist": 0.0}
    bad_obs = clean.replace(obs={**obs, "image": obs["image"].at[1, 0, 3].set(jnp.nan)})
    assert nonfinite(bad_obs) == {"nonfinite/reward": 0.0, "nonfinite/observation": 1.0}
    assert nonfinite(clean.replace(obs=obs["count"]))["nonfinite/observation"] == 0.0  # integers only


def test_the_error_names_the_first_update_its_seed_and_rollout():
    flags = {"nonfinite/reward": np.zeros((2, 4)), "nonfinite/observation": np.zeros((2, 4)),
             "nonfinite/reward/antagonist": np.zeros((2, 4))}
    assert driver.nonfinite_error(flags, 4, [10, 11], "") is None
    flags["nonfinite/observation"][0, 3] = 1.0
    flags["nonfinite/reward/antagonist"][1, 2] = 1.0  # updates 5..8: the 7th, seed 11
    assert str(driver.nonfinite_error(flags, 4, [10, 11], "; kept")) == (
        "training stopped: the environment returned a non-finite reward at update 7 (NaN or inf; seed 11, in the "
        "antagonist rollout); kept")


@pytest.mark.parametrize("algo", [a if a in QUICK else pytest.param(a, marks=pytest.mark.slow)
                                  for a in BUILTIN_ALGORITHMS])
def test_a_nan_reward_stops_every_algorithm_at_its_first_update(algo, tmp_path):
    with pytest.raises(RemidiError) as err:
        driver.train_seeds(NAN_REWARD, CFG, algo, [0], out=tmp_path, progress=False)
    assert str(err.value) == ("training stopped: the environment returned a non-finite reward at update 1 (NaN or "
                              "inf; seed 0); no checkpoint was written")
    assert not (tmp_path / CHECKPOINT).exists()


class Stop(Exception):
    pass


def test_a_nan_observation_after_a_checkpoint_stops_the_run_and_keeps_that_checkpoint(tmp_path):
    def stop(done, metrics):
        raise Stop  # after update 1's checkpoint

    with pytest.raises(Stop):
        driver.train_seeds(lever_task(8), CFG, "plr", [0], out=tmp_path, progress=False, on_block=stop)
    with pytest.raises(RemidiError) as err:  # the same run resumed on an environment that returns inf
        driver.train_seeds(NAN_OBSERVATION, CFG, "plr", [0], out=driver.RunFolder(tmp_path, resume=True),
                           progress=False)
    assert str(err.value) == ("training stopped: the environment returned a non-finite observation at update 2 "
                              "(NaN or inf; seed 0); the last checkpoint before it (update 1) is kept")
    setup = tr.make_setup(lever_task(8), CFG, "plr")
    runner = jax.eval_shape(lambda k: jax.vmap(lambda key: tr.init_runner(setup, key))(k),
                            jax.vmap(jax.random.PRNGKey)(jnp.zeros((1,), jnp.uint32)))
    assert load_checkpoint(tmp_path / CHECKPOINT, runner)[1]["done"] == 1


@pytest.mark.slow
def test_a_nan_in_the_generators_episode_stops_paired():
    task = R(lever_task(8), level_builder=NaNBuilder(8))
    with pytest.raises(RemidiError, match=r"non-finite observation at update 1 \(NaN or inf; seed 0, in the "
                                          r"generator rollout\)$"):
        driver.train_seeds(task, CFG, "paired", [0], progress=False)


@pytest.mark.slow
def test_sfls_refresh_flags_a_nan_in_its_candidates_rollouts():
    setup = tr.make_setup(NAN_REWARD, CFG, "sfl")
    adversary = setup.algo.adversary

    @jax.jit
    def refresh(key):
        runner = tr.init_runner(setup, key)
        active = jax.tree.map(lambda x: x[0], runner.adversary.buffers)
        return adversary.refresh(setup, runner, key, active)[1]

    assert refresh(jax.random.PRNGKey(0)) == {"nonfinite/reward/candidates": 1.0,
                                              "nonfinite/observation/candidates": 0.0}


MODULE = """
import dataclasses

import jax.numpy as jnp

from remidi.envs.lever import LeverGame, lever_task


class NaNReward(LeverGame):
    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = super().step_env(rng, state, action, params)
        return obs, state, reward * jnp.nan, done, info


def make_task():
    return dataclasses.replace(lever_task(8), env=NaNReward(8))
"""


def test_remidi_run_of_a_task_with_a_nan_reward_is_one_error_line_and_no_summary(tmp_path, monkeypatch, capsys):
    (tmp_path / "nan_lever_task_i41.py").write_text(MODULE)
    monkeypatch.chdir(tmp_path)  # imported from the current folder
    out = tmp_path / "run"
    argv = ["run", "nan_lever_task_i41:make_task", "--algo", "plr", "--seeds", "1", "--quiet", "--out", str(out),
            "--set", "num_updates=2", "--set", "eval_every=1", "--set", "checkpoint_every=1", "--set", "num_envs=4",
            "--set", "num_steps=2", "--set", "eval_attempts=1", "--set", "ppo.epochs=1", "--set", "network=mlp"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.endswith("remidi: error: training stopped: the environment returned a non-finite reward at update 1 "
                        "(NaN or inf; seed 0); no checkpoint was written\n"), err
    for name in ("summary.json", "metrics.csv", CHECKPOINT):
        assert not (out / name).exists(), name
