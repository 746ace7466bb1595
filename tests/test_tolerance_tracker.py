"""The tolerance tracker (engine/trackers/tolerance.py): its comparison against hand-computed cases,
its judgement at tolerance 0 against the exact tracker's, its choice from the config, and the
start-up warning that recommends only trackers that can read the task."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.config import ReMiDiConfig, UEDConfig
from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.trackers import REPLAYING
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import CandidateTracker, ExactTracker
from remidi.engine.trackers.tolerance import ToleranceCandidates, ToleranceTracker, close_to, tree_close
from remidi.envs.darkreach import darkreach_task
from remidi.envs.lever import lever_task
from remidi.errors import ConfigError


def test_float_entries_are_close_within_atol_plus_rtol_and_others_must_be_equal():
    a = {"x": jnp.array([1.0, 2.0]), "n": jnp.array([3], jnp.int32)}
    close = lambda b, atol, rtol=0.0: bool(tree_close(a, b, atol, rtol))  # noqa: E731
    assert close({"x": jnp.array([1.04, 1.96]), "n": jnp.array([3], jnp.int32)}, 0.05)
    assert not close({"x": jnp.array([1.06, 2.0]), "n": jnp.array([3], jnp.int32)}, 0.05)
    # an integer entry is compared exactly, whatever the tolerance
    assert not close({"x": jnp.array([1.0, 2.0]), "n": jnp.array([4], jnp.int32)}, 10.0)
    # rtol is relative to the frozen entry b: |2.0 − 2.5| = 0.5 ≤ 0.25·2.5 but |1 − 1.4| = 0.4 > 0.25·1.4
    assert close({"x": jnp.array([1.0, 2.5]), "n": jnp.array([3], jnp.int32)}, 0.0, 0.25)
    assert not close({"x": jnp.array([1.4, 2.0]), "n": jnp.array([3], jnp.int32)}, 0.0, 0.25)
    # tolerance 0 is equality, equal infinities included; booleans are exact
    inf = jnp.array([jnp.inf, 2.0])
    assert bool(tree_close({"x": inf}, {"x": inf}, 0.0, 0.0))
    assert not bool(tree_close({"x": jnp.array([1.0, 2.0])}, {"x": jnp.array([1.0, 2.0 + 1e-6])}, 0.0, 0.0))
    assert not bool(tree_close(jnp.array([True]), jnp.array([False]), 1.0, 0.0))
    np.testing.assert_array_equal(close_to(jnp.array([[0.0], [0.1], [0.3]]), jnp.array([0.05]), 0.06, 0.0),
                                  [True, True, False])


def uniform_policy(num_actions):
    def apply(variables, carry, obs, reset):
        return carry, (jnp.zeros((1, reset.shape[1], num_actions)), jnp.zeros((1, reset.shape[1])))

    return apply


@functools.partial(jax.jit, static_argnums=(0, 3, 4))
def _indist(task, agents, frozen_levels, tracker, steps):
    n = jax.tree.leaves(agents)[0].shape[0]
    valid = jnp.ones(jax.tree.leaves(frozen_levels)[0].shape[0], bool)
    frozen = Frozen(levels=frozen_levels, valid=valid, tracker=tracker)
    traj, _ = rollout(jax.random.PRNGKey(0), Stepping(task.env, task.params, task.deterministic_reset),
                      Policy(uniform_policy(4), {}, jnp.zeros(n)), agents, steps, frozen)
    return traj.indist


def indist(task, agents, frozen_levels, tracker, steps):
    """bool[T, N]: the rollout's indistinguishable steps under ``tracker`` (uniform random actions,
    one compiled program per tracker)."""
    return np.asarray(_indist(task, agents, frozen_levels, tracker, steps))


@pytest.fixture(scope="module")
def noisy_case():
    """Dark reach: 8 agent levels, 12 frozen ones (4 of them exact copies of agent levels, the
    others fresh): the exact tracker matches the copies only."""
    task = darkreach_task()
    sample = jax.jit(jax.vmap(task.sample_level))
    agents = sample(jax.random.split(jax.random.PRNGKey(1), 8))
    others = sample(jax.random.split(jax.random.PRNGKey(2), 8))
    frozen = jax.tree.map(lambda a, o: jnp.concatenate([a[:4], o]), agents, others)
    return task, agents, frozen


@pytest.mark.parametrize("candidates", [False, True], ids=["reference", "candidates"])
def test_tolerance_zero_is_the_exact_trackers_judgement(noisy_case, candidates):
    task, agents, frozen = noisy_case
    exact = CandidateTracker(budget=16) if candidates else ExactTracker()
    zero = ToleranceCandidates(budget=16) if candidates else ToleranceTracker()
    want = indist(task, agents, frozen, exact, 24)
    np.testing.assert_array_equal(indist(task, agents, frozen, zero, 24), want)
    assert want[:, :4].all() and not want[:, 4:].any()  # the copies match throughout, nothing else ever
    if candidates:  # a tolerance wider than the noise matches more (dark levels), never less
        wide = indist(task, agents, frozen, dataclasses.replace(zero, atol=0.05), 24)
        assert (wide >= want).all() and (wide & ~want).any()


def test_the_tolerance_tracker_is_chosen_from_the_config_and_checked():
    from remidi.engine.algorithms import get_algorithm
    from remidi.engine.trackers import tracker_for, validate_tracker

    task, algo = darkreach_task(), get_algorithm("remidi")
    cfg = UEDConfig(remidi=ReMiDiConfig(tracker="tolerance", tracker_tolerance=0.05, tracker_budget=8))
    assert tracker_for(task, cfg, algo) == ToleranceCandidates(budget=8, atol=0.05, rtol=0.0)
    reference = dataclasses.replace(cfg, remidi=dataclasses.replace(cfg.remidi, tracker_budget=0, tracker_rtol=0.1))
    assert tracker_for(task, reference, algo) == ToleranceTracker(atol=0.05, rtol=0.1)
    assert tracker_for(task, cfg, algo).at_first_observation() == ToleranceTracker(atol=0.05)
    validate_tracker(cfg, algo, task)
    for bad, match in (({"tracker_tolerance": 0.0}, "remidi.tracker_tolerance: .*> 0 with remidi.tracker=tolerance"),
                       ({"tracker_tolerance": -1.0}, "remidi.tracker_tolerance: .*finite number ≥ 0"),
                       ({"tracker_rtol": float("nan")}, "remidi.tracker_rtol")):
        with pytest.raises(ConfigError, match=match):
            validate_tracker(dataclasses.replace(cfg, remidi=dataclasses.replace(cfg.remidi, **bad)), algo, task)
    # the learned trackers refuse float observations and name the tolerance tracker instead
    belief = dataclasses.replace(cfg, remidi=dataclasses.replace(cfg.remidi, tracker="belief"))
    with pytest.raises(ConfigError, match=f"belief cannot read this task.*allowed here: {', '.join(REPLAYING)} "):
        validate_tracker(belief, algo, task)


class _KeyNoise:
    """An environment mixin whose step adds noise drawn from the step's key to its observation."""

    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = super().step_env(rng, state, action, params)
        return obs + 0.01 * jax.random.normal(rng, obs.shape), state, reward, done, info


def test_the_start_up_warning_recommends_only_trackers_that_can_read_the_task():
    from remidi.engine.run.validation import run_warnings
    from remidi.engine.trackers import readable_trackers

    floats, categorical = darkreach_task(), lever_task(num_levers=4)
    assert readable_trackers(floats) == ("tolerance",)
    assert readable_trackers(categorical) == ("belief", "simulated")
    cfg = UEDConfig(num_steps=20, remidi=ReMiDiConfig(num_buffers=2))
    noisy_floats = dataclasses.replace(floats, env=type("F", (_KeyNoise, type(floats.env)), {})())
    (warning,) = run_warnings(cfg, "remidi", noisy_floats, check_step=True)
    assert "draws from its random key" in warning and "--set remidi.tracker=tolerance" in warning, warning
    assert "belief" not in warning and "simulated" not in warning, warning
    noisy_levers = dataclasses.replace(categorical, env=type("L", (_KeyNoise, type(categorical.env)), {})())
    (warning,) = run_warnings(cfg, "remidi", noisy_levers, check_step=True)
    assert warning.endswith("or judge with --set remidi.tracker=belief or --set remidi.tracker=simulated"), warning
    # a user who chose a tolerance has judged the noise: no warning
    tolerant = dataclasses.replace(cfg, remidi=dataclasses.replace(cfg.remidi, tracker="tolerance",
                                                                   tracker_tolerance=0.05))
    assert run_warnings(tolerant, "remidi", noisy_floats, check_step=True) == []
