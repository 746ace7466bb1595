"""cond_per_seed: a rarely taken branch stays a branch under the driver's seed vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.run.driver import over_seeds
from remidi.engine.core.seeds import any_seed, cond_per_seed


def _counting_branch(calls):
    def true_fn(x):
        jax.debug.callback(lambda: calls.append(1))
        return x * 2.0 + 1.0
    return true_fn


def _run(cond, preds, xs):
    calls = []
    out = jax.jit(over_seeds(lambda p, x: cond(p, _counting_branch(calls), lambda y: y - 1.0, x)))(preds, xs)
    jax.effects_barrier()
    return np.asarray(out), len(calls)


def test_each_seed_keeps_its_own_branch():
    xs = jnp.arange(6.0).reshape(3, 2)
    preds = jnp.array([True, False, True])
    out, calls = _run(cond_per_seed, preds, xs)
    np.testing.assert_array_equal(out, np.where(np.asarray(preds)[:, None], xs * 2 + 1, xs - 1))
    assert calls > 0
    out1, _ = _run(cond_per_seed, preds[:1], xs[:1])  # a one-seed program: no seed axis, an ordinary cond
    np.testing.assert_array_equal(out1, xs[:1] * 2 + 1)


def test_the_branch_does_not_run_when_no_seed_takes_it():
    xs, preds = jnp.ones((3, 2)), jnp.zeros((3,), bool)
    out, calls = _run(cond_per_seed, preds, xs)
    np.testing.assert_array_equal(out, xs - 1)
    assert calls == 0
    _, plain_calls = _run(jax.lax.cond, preds, xs)  # vmap turns a plain cond into both branches and a select
    assert plain_calls > 0


def test_any_seed_is_one_value_for_the_batch():
    got = jax.jit(over_seeds(lambda p: any_seed(p)))(jnp.array([False, True, False]))
    np.testing.assert_array_equal(got, [True, True, True])
    assert not jax.jit(over_seeds(lambda p: any_seed(p)))(jnp.array([False]))[0]


def _conds(jaxpr) -> int:
    """The ``cond`` equations of a jaxpr and of every jaxpr inside it."""
    n = 0
    for eqn in jaxpr.eqns:
        n += eqn.primitive.name == "cond"
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else (value,):
                inner = getattr(sub, "jaxpr", None)
                if inner is not None:
                    n += _conds(getattr(inner, "jaxpr", inner))
    return n


def test_a_multi_seed_run_keeps_the_simulated_models_rare_work_in_branches():
    """Two seeds of lever-noisy with the simulated tracker and its reference: the traced train
    step keeps the calibration at a switch and the reference's fit on fresh levels as branches (a
    vmapped ``lax.cond`` leaves none, running them at every update: 8× the cost per update at the
    cpu preset's 5 seeds, docs/performance.md)."""
    from remidi.engine.run import driver
    from remidi.engine import train as tr
    from remidi.experiments import get_experiment
    from remidi.experiments.base import resolve_config

    exp = get_experiment("lever-noisy")
    cfg = resolve_config(exp, "smoke", {"num_envs": "8", "remidi.tracker": "simulated",
                                        "remidi.belief_reference": "true", "remidi.belief_hidden": "8"})
    setup = tr.make_setup(exp.make_task(cfg), cfg, "remidi")
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(2, dtype=jnp.uint32))
    runner = jax.eval_shape(lambda k: driver._init(setup, k), keys)
    closed = jax.make_jaxpr(lambda r: driver.run_steps(setup, r, 1))(runner)
    assert _conds(closed.jaxpr) >= 2


def test_the_belief_models_calibration_is_a_branch_over_several_seeds():
    """The learned belief tracker's freeze (its calibration at a switch) over two seeds stays a
    branch, and calibrates only the seed that switches."""
    from remidi.engine.trackers import belief
    from remidi.engine.trackers import belief_model as bm

    model = bm.BeliefModel(bm.ObsCoding((1.0,), (2,), (3,)), num_actions=2, hidden=4)
    opt = bm.make_optimizer()
    one = belief.init_memory(model, opt, 2, 2, (4, 3), jax.random.PRNGKey(0)).replace(written=jnp.ones((), jnp.int32))
    memory = jax.tree.map(lambda x: jnp.stack([x, x]), one)  # two seeds, each with one recorded rollout
    freeze = over_seeds(lambda m, s: belief.freeze(opt, m, 0, s, 0.05).threshold)
    switch = jnp.array([True, False])
    assert _conds(jax.make_jaxpr(freeze)(memory, switch).jaxpr) >= 1
    threshold = np.asarray(jax.jit(freeze)(memory, switch))
    assert np.isfinite(threshold[0, 0]).all() and np.isinf(threshold[1]).all()
