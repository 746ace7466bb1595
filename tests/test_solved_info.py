"""A task that says solved from its episodes' last-step info (``UEDTask(solved="success")``): a
constructed game whose reward is always 0, so the return never tells; evaluation's solve rate,
the learnability score and SFL's refresh read the info flag, and tell a policy that succeeds from
one that never does."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from remidi.engine import learner as lrn
from remidi.engine import train as tr
from remidi.engine.adversaries import scores as sc
from remidi.engine.adversaries.sfl import learnability_of
from remidi.engine.config import UEDConfig
from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.run import evaluation
from remidi.engine.run.task_checks import validate_task
from remidi.envs.interface import UEDTask, UnderspecifiedEnv, info_flag
from remidi.errors import ConfigError

K = 6


@struct.dataclass
class SignalState:
    target: jax.Array  # i32[]


class Signal(UnderspecifiedEnv):
    """A level is a target in [0, K), shown one-hot; one step; the reward is 0 whatever the action,
    and the step's info says whether the target was chosen (``success``)."""

    @property
    def default_params(self):
        return None

    def action_space(self, params):
        from gymnax.environments import spaces

        return spaces.Discrete(K)

    def reset_env_to_level(self, rng, level, params):
        return jax.nn.one_hot(level, K), SignalState(target=level)

    def step_env(self, rng, state, action, params):
        info = {"success": action == state.target, "steps": jnp.ones((), jnp.int32)}
        return jax.nn.one_hot(state.target, K), state, jnp.float32(0.0), jnp.asarray(True), info


def signal_task(**changes) -> UEDTask:
    return UEDTask(**{"env": Signal(), "params": None, "sample_level": lambda k: jax.random.randint(k, (), 0, K),
                      "num_actions": K, "max_episode_steps": 1, "solved": "success", "deterministic_reset": True,
                      "eval_sets": {"all": jnp.arange(K)}, **changes})


TASK = signal_task()


def policy(kind: str):
    """``apply`` of a hand policy over the one-hot target: ``good`` picks it, ``bad`` never does,
    ``half`` picks it or the next action, evenly."""
    def apply(variables, carry, obs, reset):
        target = obs  # [1, N, K]
        logits = {"good": 30.0 * target, "bad": -30.0 * target,
                  "half": 30.0 * (target + jnp.roll(target, 1, axis=-1))}[kind]
        return carry, (logits, jnp.zeros(obs.shape[:2]))
    return apply


def test_the_task_checks_accept_an_info_key_and_refuse_a_missing_one():
    validate_task(TASK)
    with pytest.raises(ConfigError, match=r"^task\.solved: names the info key 'won', but a step's info holds only "
                                          r"steps, success$"):
        validate_task(signal_task(solved="won"))
    with pytest.raises(ConfigError, match=r"^task\.solved: must be a function of the episode's return, the name of a "
                                          r"key of the step's info, or None, got 3$"):
        validate_task(signal_task(solved=3))


def test_info_flag_is_truthy_and_all_of_an_array():
    assert bool(info_flag({"s": jnp.float32(1.0)}, "s")) and not bool(info_flag({"s": jnp.int32(0)}, "s"))
    assert bool(info_flag({"s": jnp.array([True, True])}, "s")) and not bool(info_flag({"s": jnp.array([1, 0])}, "s"))


def test_the_rollout_records_the_flag_and_the_scores_read_it():
    """4 steps × 12 envs: the trajectory's ``solved`` is the step's success; solve rate and
    learnability count it, the return (always 0) would say no episode is solved."""
    levels = jnp.arange(12) % K
    envs = Stepping(TASK.env, None, True, solved_info="success")
    for kind, want_p in (("good", 1.0), ("bad", 0.0)):
        traj, _ = rollout(jax.random.PRNGKey(0), envs, Policy(policy(kind), {}, jnp.zeros(12)), levels, 4)
        np.testing.assert_array_equal(np.asarray(traj.solved), np.asarray(traj.action == levels[None]))
        p, count = sc.solve_rate(traj.reward, traj.done, "success", traj.solved)
        np.testing.assert_array_equal(count, 4)
        np.testing.assert_allclose(p, want_p)
    traj, _ = rollout(jax.random.PRNGKey(1), envs, Policy(policy("half"), {}, jnp.zeros(12)), levels, 4)
    hand = np.asarray(traj.action == levels[None]).mean(axis=0)  # each env's share of solved episodes
    assert 0 < hand.mean() < 1
    np.testing.assert_allclose(sc.learnability(traj.reward, traj.done, "success", flags=traj.solved),
                               hand * (1 - hand), rtol=1e-6)
    np.testing.assert_allclose(sc.learnability(traj.reward, traj.done, lambda r: r > 0), 0.0)  # the return: never
    inputs = sc.ScoreInputs(mean_return=jnp.zeros(12), values=traj.value, advantages=traj.value,
                            max_return=jnp.zeros(12), done=traj.done, reward=traj.reward, solved="success",
                            solved_flags=traj.solved)
    np.testing.assert_allclose(sc.score_levels("learnability", inputs), hand * (1 - hand), rtol=1e-6)


def test_the_first_episode_flag_is_its_last_steps():
    done = jnp.array([[False, True, False], [True, False, False], [True, True, False]])
    flags = jnp.array([[True, False, True], [False, True, True], [True, True, True]])
    # env 0: first episode ends at t1 (flag False); env 1: at t0 (False); env 2: never ends
    np.testing.assert_array_equal(evaluation.first_episode_flag(done, flags), [False, False, False])
    np.testing.assert_array_equal(evaluation.first_episode_flag(done, ~flags), [True, True, False])


@pytest.fixture(scope="module")
def setup_and_runner():
    cfg = dataclasses.replace(UEDConfig(), num_envs=4, num_steps=2, eval_attempts=3, hidden_size=8)
    setup = tr.make_setup(TASK, cfg, "sfl")
    return setup, tr.init_runner(setup, jax.random.PRNGKey(0))


@pytest.mark.parametrize("kind, rate", [("good", 1.0), ("bad", 0.0)])
def test_evaluation_solve_rate_reads_the_info(setup_and_runner, monkeypatch, kind, rate):
    setup, runner = setup_and_runner
    monkeypatch.setattr(evaluation, "policy_apply", lambda setup, learner: policy(kind))
    out = evaluation.evaluate(setup, runner, jax.random.PRNGKey(3))
    assert float(out["solve_rate/all"]) == rate
    assert float(out["return/all"]) == 0.0  # the return tells nothing


def test_sfl_keeps_levels_by_the_infos_learnability(setup_and_runner, monkeypatch):
    """SFL's candidates played by a policy that succeeds half of the time: a solve rate near 1/2
    and a positive learnability per level from the info; the return form sees p = 0 everywhere."""
    setup, runner = setup_and_runner
    monkeypatch.setattr(lrn, "policy_apply", lambda setup, learner: policy("half"))
    levels = jnp.arange(16) % K
    traj, _ = lrn.play(setup, runner.learner, jax.random.PRNGKey(4), levels, 8, None)
    score, p = learnability_of(setup, traj)
    hand = np.asarray(traj.action == levels[None]).mean(axis=0)
    np.testing.assert_allclose(p, hand, rtol=1e-6)
    np.testing.assert_allclose(score, hand * (1 - hand), rtol=1e-6)
    assert 0.3 < hand.mean() < 0.7 and float(jnp.mean(score)) > 0.1
    by_return = dataclasses.replace(setup, task=dataclasses.replace(TASK, solved=lambda r: r > 0))
    _, p_return = learnability_of(by_return, traj)
    np.testing.assert_allclose(p_return, 0.0)
