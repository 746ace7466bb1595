"""SFL's adversary (engine/adversaries/sfl.py): its selection on rollouts of known learnability,
the update's mix, the refresh period, and ReMiDi over SFL's exclusion of the levels a frozen
buffer explains. The end-to-end runs are in tests/test_sfl_smoke.py (slow)."""

import dataclasses
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine import train as tr
from remidi.engine.adversaries import level_buffer as buf
from remidi.engine.adversaries.sfl import LearnabilityBuffers, learnability_of, mix_mask, select_top
from remidi.engine.algorithms import ALGORITHMS
from remidi.engine.config import SFLConfig
from remidi.engine.run.validation import validate_ued_config
from remidi.envs.lever import LeverLevel, lever_task
from remidi.errors import ConfigError
from remidi.experiments.lever import paper_config


def test_the_top_k_are_the_most_learnable_and_unfinished_levels_are_never_kept():
    scores = jnp.array([0.09, 0.25, -jnp.inf, 0.21, 0.0, 0.16, -jnp.inf])
    rates = jnp.array([0.1, 0.5, 0.0, 0.3, 1.0, 0.2, 0.0])
    top, valid = select_top(scores, rates, 3)
    assert top.tolist() == [1, 3, 5] and valid.all()
    top, valid = select_top(scores, rates, 7)  # more room than levels that can be kept
    assert top.tolist()[:5] == [1, 3, 5, 0, 4] and valid.tolist() == [True] * 5 + [False] * 2


def test_ties_go_to_the_higher_solve_rate_then_to_the_earlier_level():
    # p = 0.3 and p = 0.7 have the same p(1 − p); so do p = 0 and p = 1 (score 0)
    scores = jnp.array([0.21, 0.21, 0.0, 0.0, 0.21, 0.0])
    rates = jnp.array([0.3, 0.7, 0.0, 1.0, 0.7, 1.0])
    top, _ = select_top(scores, rates, 6)
    assert top.tolist() == [1, 4, 0, 3, 5, 2]


def test_learnability_of_given_rollouts():
    # 4 levels, 6 steps: solved 1 of 2, 2 of 2, no episode ended, solved 1 of 3 (explained at every step)
    done = np.zeros((6, 4), bool)
    reward = np.zeros((6, 4), np.float32)
    done[[2, 5], 0] = True
    reward[2, 0] = 1.0
    done[[1, 3], 1] = True
    reward[[1, 3], 1] = 1.0
    done[[1, 3, 5], 3] = True
    reward[3, 3] = 1.0
    indist = np.zeros((6, 4), bool)
    indist[:, 3] = True
    traj = SimpleNamespace(reward=jnp.asarray(reward), done=jnp.asarray(done), indist=jnp.asarray(indist), solved=None)
    setup = SimpleNamespace(task=SimpleNamespace(solved=lambda ret: ret > 0))
    score, p = learnability_of(setup, traj)
    np.testing.assert_allclose(score[:2], [0.25, 0.0])
    assert np.isneginf(score[2]) and np.isneginf(score[3])  # unfinished; a complete overlap
    np.testing.assert_allclose(p, [0.5, 1.0, 0.0, 1 / 3], rtol=1e-6)


@pytest.mark.parametrize("ratio, n, want", [(0.5, 32, 16), (0.3, 10, 3), (0.0, 8, 0), (1.0, 8, 8), (0.25, 6, 2)])
def test_the_mix_takes_round_ratio_n_envs_from_the_buffer(ratio, n, want):
    mask = mix_mask(n, ratio)
    assert int(mask.sum()) == want == round(ratio * n) and (not want or bool(mask[-1]))


TINY_SFL = SFLConfig(batch_size=16, num_batches=2, rollout_steps=4, buffer_size=8, refresh_every=3,
                     sampled_envs_ratio=0.25)


def tiny(algo):
    cfg = paper_config()
    cfg = dataclasses.replace(cfg, num_envs=8, num_steps=4, hidden_size=8, num_updates=20, eval_every=10, sfl=TINY_SFL,
                              remidi=dataclasses.replace(cfg.remidi, buffer_capacity=8, steps_per_buffer=5))
    validate_ued_config(cfg, algo, lever_task())
    return tr.make_setup(lever_task(), cfg, algo)


@pytest.fixture(scope="module")
def remidi_sfl():
    """ReMiDi over SFL's set-up, a fresh runner, its jitted ``propose``: one compiled program for
    every test here (on buffer 0 nothing is frozen and it is SFL's proposal)."""
    setup = tiny("remidi-sfl")
    runner = jax.jit(lambda key: tr.init_runner(setup, key))(jax.random.PRNGKey(0))
    def propose(r, key):
        k_branch, k_levels, k_sample = jax.random.split(key, 3)
        return setup.algo.adversary.propose(setup, r, jax.vmap(setup.task.sample_level)(jax.random.split(k_levels, setup.cfg.num_envs)), k_branch, k_levels, k_sample)

    propose = jax.jit(propose)
    return setup, runner, propose


def test_refresh_at_the_start_and_every_refresh_every_updates_then_the_mix(remidi_sfl):
    setup, runner, propose = remidi_sfl
    first = propose(runner, jax.random.PRNGKey(1))
    assert int(first.buffer.time) == 1 and bool(first.buffer.valid.any())  # refreshed before update 0
    np.testing.assert_array_equal(first.replay, mix_mask(8, 0.25))  # exactly round(0.25 · 8) = 2 from the buffer
    assert bool(first.train)
    replayed = buf.get_levels(first.buffer, first.slots)
    for leaf, got in zip(jax.tree.leaves(replayed), jax.tree.leaves(first.levels)):
        np.testing.assert_array_equal(np.asarray(got)[-2:], np.asarray(leaf)[-2:])
    assert bool(first.buffer.valid[first.slots[-2:]].all())  # drawn among the kept levels only
    state = runner.adversary.replace(buffers=buf.replace_buffer(runner.adversary.buffers, 0, first.buffer))
    for count in range(1, 7):
        r = runner.replace(adversary=state.replace(count=jnp.asarray(count, jnp.int32)))
        p = propose(r, jax.random.PRNGKey(10 + count))
        assert int(p.buffer.time) == (2 if count % 3 == 0 else 1), count  # refreshed at updates 3 and 6 only
        assert int(p.replay.sum()) == 2


def test_advance_counts_every_update_and_a_sequence_switches(remidi_sfl):
    remidi, runner, _ = remidi_sfl
    proposal = SimpleNamespace(replay=jnp.zeros(8, bool))
    sfl = tr.make_setup(remidi.task, remidi.cfg, "sfl")
    r = runner.replace(adversary=runner.adversary.replace(count=jnp.asarray(4, jnp.int32)))
    outcome = SimpleNamespace(collection=SimpleNamespace(traj=None))
    state = sfl.algo.adversary.advance(sfl, r, proposal, outcome)[0].adversary  # one buffer: counts on, never switches
    assert int(state.count) == 5 and int(state.active) == 0
    state = remidi.algo.adversary.advance(remidi, r, proposal, outcome)[0].adversary  # the 5th update: switch
    assert int(state.active) == 1 and int(state.count) == 0  # the next update refreshes buffer 1


def test_remidi_sfl_never_keeps_a_level_a_frozen_buffer_explains(remidi_sfl):
    """Lever game: a frozen hidden level explains every hidden level's rollout (all show the same
    observation), a frozen visible level the visible levels with its lever; buffer 1's refresh
    keeps neither."""
    setup, runner, propose = remidi_sfl
    frozen = LeverLevel(correct=jnp.arange(8, dtype=jnp.int32), visible=jnp.arange(8) > 0)  # one hidden, 7 visible
    bufs = runner.adversary.buffers
    levels = jax.tree.map(lambda all_, f: all_.at[0].set(f), bufs.levels, frozen)
    bufs = bufs.replace(levels=levels, valid=bufs.valid.at[0].set(True))
    runner = runner.replace(adversary=runner.adversary.replace(buffers=bufs, active=jnp.asarray(1, jnp.int32)))
    proposal = propose(runner, jax.random.PRNGKey(3))
    kept = proposal.buffer
    assert bool(kept.valid.any())
    correct, visible = np.asarray(kept.levels.correct)[kept.valid], np.asarray(kept.levels.visible)[kept.valid]
    assert visible.all()  # no hidden level
    assert not np.isin(correct, np.arange(1, 8)).any()  # no visible level whose lever a frozen one shows


def test_sfl_refuses_a_task_without_a_solve_criterion_and_bad_keys():
    task = dataclasses.replace(lever_task(), solved=None)
    # the lever task edits and builds levels: it runs every registered algorithm but SFL's
    allowed = ", ".join(name for name, a in ALGORITHMS.items() if not isinstance(a.adversary, LearnabilityBuffers))
    with pytest.raises(ConfigError, match=r"^--algo: sfl keeps the levels whose solve rate p maximises p\(1 − p\), "
                                          r"but this task has no solve criterion \(UEDTask.solved\); "
                                          rf"allowed: {allowed}$"):
        validate_ued_config(paper_config(), "sfl", task)
    cfg = paper_config()
    for change, message in (
            ({"sfl": dataclasses.replace(cfg.sfl, refresh_every=0)}, "^sfl.refresh_every: must be an integer ≥ 1"),
            ({"sfl": dataclasses.replace(cfg.sfl, sampled_envs_ratio=1.5)}, "^sfl.sampled_envs_ratio: must be a number"),
            ({"sfl": dataclasses.replace(cfg.sfl, buffer_size=2000)}, r"^sfl.buffer_size: must be at most sfl.batch_size"),
            ({"remidi": dataclasses.replace(cfg.remidi, count="replays")}, "^remidi.count: must be updates with SFL")):
        with pytest.raises(ConfigError, match=message) as err:
            validate_ued_config(dataclasses.replace(cfg, **change), "sfl", lever_task())
        assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="^remidi.tracker: must be prefix, per_step or tolerance with ReMiDi over SFL"):
        validate_ued_config(dataclasses.replace(cfg, remidi=dataclasses.replace(cfg.remidi, tracker="belief")),
                            "remidi-sfl", lever_task())
