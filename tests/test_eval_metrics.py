"""Evaluation metrics that tell policies apart: the exact expected regret per level (worst and mean
over an evaluation set) and the policy's entropy, checked on hand-set lever policies."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.run import evaluation
from remidi.engine import train as tr
from remidi.envs.lever import lever_task
from remidi.experiments.lever import paper_config

TASK = lever_task(64)
CFG = dataclasses.replace(paper_config(), num_envs=8, eval_attempts=4)
MMR_HIDDEN = 20 * (1 - 1 / 64)  # minimax regret on hidden levels: pull a lever uniformly at random


@pytest.fixture(scope="module")
def evaluate_with():
    setup = tr.make_setup(TASK, CFG, "plr")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    evaluate = jax.jit(lambda r: evaluation.evaluate(setup, r, jax.random.PRNGKey(1)))

    def run(bias):
        """Evaluate the policy whose logits are ``bias`` f32[64] whatever it observes."""
        params = jax.tree.map(lambda x: x, runner.learner.train_state.params)
        out = params["heads"]["policy_out"]
        params["heads"]["policy_out"] = {"kernel": jnp.zeros_like(out["kernel"]), "bias": jnp.asarray(bias)}
        metrics = evaluate(runner.replace(learner=runner.learner.replace(
            train_state=runner.learner.train_state.replace(params=params))))
        return {k: float(v) for k, v in metrics.items()}

    return run


def test_uniform_policy_is_minimax_regret_on_hidden_levels(evaluate_with):
    m = evaluate_with(jnp.zeros(64))
    assert m["regret/hidden/worst"] == pytest.approx(MMR_HIDDEN, abs=1e-4)
    assert m["regret/hidden/mean"] == pytest.approx(MMR_HIDDEN, abs=1e-4)
    assert m["regret/visible/mean"] == pytest.approx(2 * (1 - 1 / 64), abs=1e-5)
    assert m["entropy/hidden"] == pytest.approx(np.log(64), abs=1e-4)


def test_worst_case_regret_exposes_a_peaked_policy_that_the_solve_rate_cannot(evaluate_with):
    uniform = evaluate_with(jnp.zeros(64))
    peaked = evaluate_with(jnp.zeros(64).at[0].set(30.0))  # almost always lever 0
    # the mean over hidden levels is the same for every policy that cannot see the answer...
    assert peaked["regret/hidden/mean"] == pytest.approx(uniform["regret/hidden/mean"], abs=1e-3)
    # ...but the worst hidden level is not: 20 (never pulls its lever) against 19.6875
    assert peaked["regret/hidden/worst"] == pytest.approx(20.0, abs=1e-4)
    assert peaked["regret/hidden/worst"] > MMR_HIDDEN + 0.3
    assert peaked["entropy/hidden"] < 1e-3
    assert peaked["regret/visible/worst"] == pytest.approx(2.0, abs=1e-4)
    assert peaked["regret/visible/mean"] == pytest.approx(2.0 * 63 / 64, abs=1e-3)


def test_sampled_regret_where_no_expected_return_is_known(evaluate_with):
    """Without the exact expected return, the regret comes from the sampled episodes: a policy
    that always pulls lever 0 has regret 0 on the levels whose answer is lever 0 and 2 / 20 else."""
    task = dataclasses.replace(TASK, expected_return=None)
    setup = tr.make_setup(task, CFG, "plr")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    params = runner.learner.train_state.params
    out = params["heads"]["policy_out"]
    params["heads"]["policy_out"] = {"kernel": jnp.zeros_like(out["kernel"]), "bias": jnp.zeros(64).at[0].set(50.0)}
    m = jax.jit(lambda r: evaluation.evaluate(setup, r, jax.random.PRNGKey(1)))(
        runner.replace(learner=runner.learner.replace(train_state=runner.learner.train_state.replace(params=params))))
    assert float(m["regret/visible/worst"]) == pytest.approx(2.0)
    assert float(m["regret/visible/mean"]) == pytest.approx(2.0 * 63 / 64)
    assert float(m["regret/hidden/mean"]) == pytest.approx(20.0 * 63 / 64)
    assert "entropy/hidden" not in m
