"""ReMiDi's rehearsal (``remidi.rehearsal``): once a buffer is frozen, an update may
train on a batch of a frozen buffer's levels, on every step, without changing any buffer.

The lever game's tiny config (tests/test_ued_engine.py's TINY: 8 envs, one-step episodes, the
first buffer frozen after update 8)."""

import dataclasses

import jax
import numpy as np
import pytest

from remidi.engine.run import driver as drv
from remidi.engine import learner as lrn
from remidi.engine import train as tr
from remidi.engine.run.validation import validate_ued_config
from remidi.errors import ConfigError

from test_ued_engine import TASK, TINY

R = dataclasses.replace
SWITCH = TINY.remidi.steps_per_buffer  # the update after which buffer 0 is frozen


def rehearsing(p: float, algo: str = "remidi"):
    cfg = R(TINY, remidi=R(TINY.remidi, rehearsal=p))
    validate_ued_config(cfg, algo, TASK)
    return tr.make_setup(TASK, cfg, algo)


def start(setup, seeds):
    keys = jax.random.split(jax.random.PRNGKey(0), seeds)
    return jax.jit(lambda k: jax.lax.map(lambda key: tr.init_runner(setup, key), k))(keys)


def steps(setup, runner, n):
    """``n`` train steps (a fresh jit: the tests below patch the step's pieces)."""
    return jax.jit(lambda r: drv.run_steps(setup, r, n))(runner)


def levels_of(buffer_levels, valid):
    return {(int(c), bool(v)) for c, v, ok in zip(np.asarray(buffer_levels.correct), np.asarray(buffer_levels.visible),
                                                  np.asarray(valid)) if ok}


def test_with_p1_every_update_after_the_switch_trains_unmasked_on_frozen_levels_and_changes_no_buffer(monkeypatch):
    setup = rehearsing(1.0)
    seen, masks = {}, {}  # update -> the rollout's levels and the tracker's indist; the loss mask

    real_collect, real_ppo = lrn.collect, lrn.ppo_update
    # the learner's functions see no update count: ordered callbacks number the updates (one
    # rollout each, its training after it)

    def spy_collect(setup_, learner, rng, levels, frozen):
        out = real_collect(setup_, learner, rng, levels, frozen)
        jax.debug.callback(lambda c, v, i: seen.__setitem__(len(seen), (np.asarray(c), np.asarray(v), np.asarray(i))),
                           levels.correct, levels.visible, out.traj.indist, ordered=True)
        return out

    def spy_ppo(state, carry, batch, *args):
        jax.debug.callback(lambda m: masks.__setitem__(len(seen) - 1, np.asarray(m)), batch.mask, ordered=True)
        return real_ppo(state, carry, batch, *args)

    monkeypatch.setattr(lrn, "collect", spy_collect)
    monkeypatch.setattr(lrn, "ppo_update", spy_ppo)
    runner = start(setup, 1)
    # one program of SWITCH steps, run three times (its callbacks keep it out of the persistent
    # cache: each program compiles in every run of the suite)
    step8 = jax.jit(lambda r: drv.run_steps(setup, r, SWITCH))
    at_switch, before = step8(runner)
    middle, first_half = step8(at_switch)
    after, second_half = step8(middle)
    metrics = jax.tree.map(lambda a, b: np.concatenate([np.asarray(a), np.asarray(b)], axis=1), first_half, second_half)
    jax.effects_barrier()

    assert np.asarray(before["rehearsal"]).sum() == 0  # nothing frozen yet: no rehearsal
    assert int(at_switch.adversary.active[0]) == 1 and int(after.adversary.active[0]) == 1
    np.testing.assert_array_equal(np.asarray(metrics["rehearsal"][0]), np.ones(16))
    np.testing.assert_array_equal(np.asarray(metrics["replay"][0]), np.zeros(16))  # no replay of the active buffer
    np.testing.assert_array_equal(np.asarray(metrics["rejected"][0]), np.zeros(16))
    np.testing.assert_array_equal(np.asarray(metrics["inserted"][0]), np.zeros(16))
    # frozen and active buffers bit-identical before and after: nothing inserted, rescored or sampled
    for a, b in zip(jax.tree.leaves(at_switch.adversary.buffers), jax.tree.leaves(after.adversary.buffers)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    first = jax.tree.map(lambda x: x[0, 0], after.adversary.buffers)
    frozen = levels_of(first.levels, first.valid)
    assert frozen and len(seen) == SWITCH + 16
    for u in range(SWITCH, SWITCH + 16):
        correct, visible, indist = seen[u]
        assert {(int(c), bool(v)) for c, v in zip(correct, visible)} <= frozen, u
        assert not indist.any(), u  # a rehearsal's rollout explains no step of its frozen levels ...
        assert masks[u].all(), u  # ... so the loss trains on every one of them
    assert set(masks) >= set(range(SWITCH, SWITCH + 16))


def test_the_rehearsal_rate_is_p_and_the_switch_still_falls_on_its_update():
    p, seeds, n = 0.3, 2, 200
    setup = rehearsing(p)
    _, metrics = steps(setup, start(setup, seeds), n)
    rehearsal, active = np.asarray(metrics["rehearsal"]), np.asarray(metrics["active_buffer"])
    assert rehearsal[:, :SWITCH].sum() == 0
    np.testing.assert_array_equal(active[:, SWITCH - 1:], 1)  # count=updates counts rehearsals: the switch stays
    draws = rehearsal[:, SWITCH:]
    rate, sd = draws.mean(), np.sqrt(p * (1 - p) / draws.size)
    assert abs(rate - p) < 4 * sd, (rate, sd)
    # the other updates still replay the active buffer or offer it fresh levels
    assert np.asarray(metrics["replay"])[:, SWITCH:][draws == 0].any()
    assert np.asarray(metrics["inserted"])[:, SWITCH:][draws == 1].sum() == 0


def test_p0_is_todays_program_and_other_algorithms_are_refused():
    setup = tr.make_setup(TASK, TINY, "remidi")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    _, metrics = jax.eval_shape(lambda r: tr.train_step(setup, r), runner)
    assert "rehearsal" not in metrics  # P = 0: no rehearsal code traced (tests/test_engine_reference*.py: same results)
    for algo in ("plr", "dr", "accel", "remidi-paired"):
        with pytest.raises(ConfigError) as err:
            validate_ued_config(R(TINY, remidi=R(TINY.remidi, rehearsal=0.2)), algo, TASK)
        assert str(err.value).startswith(f"remidi.rehearsal: {algo} has no sequence of level buffers")
        assert "\n" not in str(err.value)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ConfigError, match=r"^remidi.rehearsal: must be a probability in \[0, 1\]"):
            validate_ued_config(R(TINY, remidi=R(TINY.remidi, rehearsal=bad)), "remidi", TASK)
    with pytest.raises(ConfigError, match="^remidi.policy: must be masked with remidi.rehearsal"):
        validate_ued_config(R(TINY, remidi=R(TINY.remidi, rehearsal=0.2, policy="combine")), "remidi", TASK)
    validate_ued_config(R(TINY, remidi=R(TINY.remidi, rehearsal=0.2)), "remidi-accel", TASK)


def test_remidi_over_accel_rehearses_but_never_on_an_edit_update():
    setup = rehearsing(0.5, "remidi-accel")
    _, metrics = steps(setup, start(setup, 1), 48)
    rehearsal, edit, replay = (np.asarray(metrics[k][0]) for k in ("rehearsal", "edit", "replay"))
    assert rehearsal[SWITCH:].any() and edit[SWITCH:].any()
    assert not (rehearsal * edit).any() and not (rehearsal * replay).any()
    np.testing.assert_array_equal(edit[1:], replay[:-1])  # the update after a replay (not after a rehearsal) edits


@pytest.mark.parametrize("count", ["updates", "replays"])
def test_the_switch_counter_counts_a_rehearsal_as_an_update_but_not_as_a_replay(count):
    cfg = R(TINY, remidi=R(TINY.remidi, rehearsal=1.0, num_buffers=3, count=count))
    validate_ued_config(cfg, "remidi", TASK)
    setup = tr.make_setup(TASK, cfg, "remidi")
    runner = start(setup, 1)
    runner, _ = steps(setup, runner, 30 if count == "replays" else SWITCH)  # count=replays: 8 replays take longer
    assert int(runner.adversary.active[0]) == 1
    after, metrics = steps(setup, runner, 2 * SWITCH)
    assert np.asarray(metrics["rehearsal"]).all()  # P = 1: every update rehearses buffer 0 ...
    # ... and counts towards the switch as an update, not as a replay of the active buffer
    assert int(after.adversary.active[0]) == (2 if count == "updates" else 1)
