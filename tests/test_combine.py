"""ReMiDi's exact ``Combine`` (``remidi.policy=combine``): a frozen copy of the policy per buffer
acts on the trajectories realisable under that buffer's levels, so earlier behaviour is kept
bit for bit while the current policy goes on training; the masked single network drifts."""

import dataclasses

import jax
import numpy as np
import pytest

from remidi.engine.run import driver
from remidi.engine.run import evaluation
from remidi.engine import train as tr
from remidi.engine.config import POLICIES
from remidi.engine.run.validation import validate_ued_config
from remidi.errors import ConfigError
from test_ued_engine import TASK, TINY  # the task object too: programs are cached per task object

R = dataclasses.replace


def hidden_policy(setup, runner):
    """f32[S, 64, 64]: every seed's first-step action probabilities on the 64 hidden levels."""
    levels = TASK.eval_sets["hidden"]
    return np.asarray(jax.jit(jax.vmap(lambda r: evaluation.first_step_policy(setup, r, TASK.env, levels)))(runner))


def run(setup, runner, updates):
    for _ in range(updates // TINY.eval_every):
        runner, _ = driver._run_block(setup, runner, TINY.eval_every)
    return runner


@pytest.mark.parametrize("policy", ["combine", "masked"])
def test_behaviour_on_earlier_buffers_levels_is_kept_only_by_combine(policy):
    cfg = R(TINY, remidi=R(TINY.remidi, policy=policy))
    setup = tr.make_setup(TASK, cfg, "remidi")
    runner = driver._init(setup, jax.vmap(jax.random.PRNGKey)(np.arange(2, dtype=np.uint32)))
    # 20 updates (the switch happens after 8) in blocks of TINY's eval_every: the programs of
    # tests/test_engine_reference.py's remidi and remidi-combine runs, compiled once for both files
    runner = run(setup, runner, 20)
    assert np.asarray(runner.adversary.active).tolist() == [1, 1]
    # the first buffer (plain PLR⊥) holds hidden levels: the hidden observation is realisable under it
    assert (~np.asarray(runner.adversary.buffers.levels.visible[:, 0]) & np.asarray(runner.adversary.buffers.valid[:, 0])).any(axis=1).all()
    before, params_before = hidden_policy(setup, runner), runner.learner.train_state.params
    runner = run(setup, runner, 20)
    after = hidden_policy(setup, runner)
    moved = max(float(np.abs(a - b).max()) for a, b in zip(jax.tree.leaves(params_before),
                                                           jax.tree.leaves(runner.learner.train_state.params)))
    assert moved > 0  # the current policy trained on
    if policy == "combine":
        np.testing.assert_array_equal(after, before)  # bit-identical where the earlier buffer acts
        frozen = jax.tree.map(lambda x: x[:, 0], runner.learner.frozen_params)
        np.testing.assert_array_equal(np.asarray(jax.tree.leaves(frozen)[0]).shape[0], 2)
    else:
        assert np.abs(after - before).max() > 1e-6  # masking alone does not freeze the shared weights


def test_combine_needs_the_exact_prefix_or_the_belief_tracker():
    cfg = R(TINY, remidi=R(TINY.remidi, policy="combine", tracker="per_step"))
    with pytest.raises(ConfigError, match="remidi.tracker: must be prefix, tolerance or belief with remidi.policy=combine"):
        validate_ued_config(cfg, "remidi", TASK)
    with pytest.raises(ConfigError, match=f"remidi.policy: unknown value 'exact'; allowed: {', '.join(POLICIES)}$"):
        validate_ued_config(R(TINY, remidi=R(TINY.remidi, policy="exact")), "remidi", TASK)


@pytest.mark.parametrize("threshold", [-np.inf, np.inf])
def test_with_the_belief_tracker_a_frozen_policy_acts_where_its_buffers_model_explains_the_prefix(threshold):
    """``remidi.policy=combine`` with ``remidi.tracker=belief``: the first buffer's frozen policy
    acts where the first buffer's frozen model explains the prefix (threshold −inf: everywhere),
    the current policy where it does not (+inf: nowhere); here at the first step of the 64 hidden
    levels, through the evaluation's combined policy."""
    cfg = R(TINY, remidi=R(TINY.remidi, policy="combine", tracker="belief"))
    validate_ued_config(cfg, "remidi", TASK)
    setup = tr.make_setup(TASK, cfg, "remidi")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    # a different policy, frozen: another initialisation, scaled so that it is far from uniform
    other = jax.tree.map(lambda x: 10 * x, tr.init_runner(setup, jax.random.PRNGKey(1)).learner.train_state.params)
    belief = runner.tracker.replace(threshold=runner.tracker.threshold.at[0].set(threshold))
    runner = runner.replace(adversary=runner.adversary.replace(active=jax.numpy.asarray(1)), tracker=belief,
                            learner=runner.learner.replace(frozen_params=jax.tree.map(lambda x: x[None], other)))
    levels = TASK.eval_sets["hidden"]
    acting = np.asarray(evaluation.first_step_policy(setup, runner, TASK.env, levels))
    single = tr.make_setup(TASK, R(cfg, remidi=R(cfg.remidi, policy="masked")), "remidi")  # one policy acts
    frozen = np.asarray(evaluation.first_step_policy(
        single, runner.replace(learner=runner.learner.replace(train_state=runner.learner.train_state.replace(params=other))), TASK.env, levels))
    current = np.asarray(evaluation.first_step_policy(single, runner, TASK.env, levels))
    assert np.abs(frozen - current).max() > 1e-3  # the two policies differ on these levels
    np.testing.assert_allclose(acting, frozen if threshold < 0 else current, rtol=1e-6)
