"""``buffer_solve_rate/b<k>``: the current policy's solve rate on each buffer's valid levels,
checked on lever-game buffers filled by hand against hand-set policies (a policy that pulls one
lever solves exactly the levels whose answer it is)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine import train as tr
from remidi.engine.run import evaluation
from remidi.envs.lever import LeverLevel, lever_task
from remidi.experiments.lever import paper_config

TASK = lever_task(64)
CFG = dataclasses.replace(paper_config(), num_envs=8, eval_attempts=4)
CAPACITY = CFG.remidi.buffer_capacity  # 32


def _lever_policy(runner, lever=None):
    """The runner whose policy pulls ``lever`` whatever it sees (None: uniformly at random)."""
    params = jax.tree.map(lambda x: x, runner.learner.train_state.params)
    out = params["heads"]["policy_out"]
    bias = jnp.zeros(64) if lever is None else jnp.zeros(64).at[lever].set(50.0)
    params["heads"]["policy_out"] = {"kernel": jnp.zeros_like(out["kernel"]), "bias": bias}
    return runner.replace(learner=runner.learner.replace(train_state=runner.learner.train_state.replace(params=params)))


def _filled(runner, correct, valid):
    """The runner whose two buffers hold visible levels with answers ``correct`` i32[2, C] and
    validity ``valid`` bool[2, C]."""
    levels = LeverLevel(correct=jnp.asarray(correct, jnp.int32), visible=jnp.ones((2, CAPACITY), bool))
    buffers = runner.adversary.buffers.replace(levels=levels, valid=jnp.asarray(valid))
    return runner.replace(adversary=runner.adversary.replace(buffers=buffers))


@pytest.fixture(scope="module")
def remidi_rates():
    setup = tr.make_setup(TASK, CFG, "remidi")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    rates = jax.jit(lambda r: {k: v for k, v in evaluation.evaluate(setup, r, jax.random.PRNGKey(1)).items()
                               if k.startswith("buffer_solve_rate/")})
    return runner, lambda r: {k: float(v) for k, v in rates(r).items()}


def test_rates_are_each_buffers_valid_levels_solved(remidi_rates):
    runner, rates = remidi_rates
    # buffer 0: answers 0, 0, 3, 5 valid (the rest invalid, holding answer 0: must not count);
    # buffer 1: answer 0 twice valid, answer 7 in the invalid slots
    correct = np.zeros((2, CAPACITY), int)
    correct[0, 2], correct[0, 3] = 3, 5
    correct[1, 2:] = 7
    valid = np.zeros((2, CAPACITY), bool)
    valid[0, :4] = True
    valid[1, :2] = True
    filled = _filled(runner, correct, valid)
    m = rates(_lever_policy(filled, lever=0))
    assert set(m) == {"buffer_solve_rate/b0", "buffer_solve_rate/b1"}
    assert m["buffer_solve_rate/b0"] == pytest.approx(0.5)  # 2 of its 4 levels
    assert m["buffer_solve_rate/b1"] == pytest.approx(1.0)
    m = rates(_lever_policy(filled, lever=3))
    assert m["buffer_solve_rate/b0"] == pytest.approx(0.25)
    assert m["buffer_solve_rate/b1"] == pytest.approx(0.0)


def test_a_good_policy_scores_higher_than_a_random_one(remidi_rates):
    """Every valid level of buffer 0 answers lever 9: the policy that pulls it solves them all,
    the uniform policy about 1/64 of its attempts; an empty buffer has no rate (NaN)."""
    runner, rates = remidi_rates
    filled = _filled(runner, np.full((2, CAPACITY), 9), np.stack([np.ones(CAPACITY, bool), np.zeros(CAPACITY, bool)]))
    good, bad = rates(_lever_policy(filled, lever=9)), rates(_lever_policy(filled))
    assert good["buffer_solve_rate/b0"] == pytest.approx(1.0)
    assert bad["buffer_solve_rate/b0"] < 0.1
    assert np.isnan(good["buffer_solve_rate/b1"]) and np.isnan(bad["buffer_solve_rate/b1"])


def test_only_buffer_sequences_report_it():
    setup = tr.make_setup(TASK, CFG, "plr")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    metrics = jax.jit(lambda r: evaluation.evaluate(setup, r, jax.random.PRNGKey(1)))(runner)
    assert not any(k.startswith("buffer_solve_rate/") for k in metrics)
