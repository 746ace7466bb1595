"""PAIRED's regret estimates against a hand computation on fixed rollouts (negative regret
included), and the generator's sparse reward with no bootstrap past its episode."""

import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.adversaries import paired
from remidi.engine.adversaries import scores as sc
from remidi.engine.learner import compute_gae

# two levels, 6 steps each; episodes end where done is True
PRO_REWARD = jnp.array([[0, 0], [1, 0], [0, 0], [3, 2], [0, 0], [0, 0]], jnp.float32)
PRO_DONE = jnp.array([[0, 0], [1, 0], [0, 1], [1, 0], [0, 0], [0, 1]], bool)
ANT_REWARD = jnp.array([[5, 0], [0, 0], [2, 0], [0, 1], [0, 0], [0, 0]], jnp.float32)
ANT_DONE = jnp.array([[1, 0], [0, 0], [1, 0], [0, 1], [0, 0], [0, 0]], bool)
# by hand: protagonist level 0 episodes 1, 3 → mean 2, best 3; level 1 episodes 0, 2 → mean 1, best 2
#          antagonist level 0 episodes 5, 2 → mean 3.5, best 5; level 1 episode 1 (and a tail of 0) → 1, 1
OPTIMAL = jnp.array([4.0, 0.5])


def returns(reward, done):
    mean, best, _ = sc.episode_returns(reward, done)
    return mean, best


def test_the_three_regret_estimates_equal_a_hand_computation():
    pm, pb = returns(PRO_REWARD, PRO_DONE)
    am, ab = returns(ANT_REWARD, ANT_DONE)
    np.testing.assert_allclose(pm, [2.0, 1.0])
    np.testing.assert_allclose(pb, [3.0, 2.0])
    np.testing.assert_allclose(am, [3.5, 1.0])
    np.testing.assert_allclose(ab, [5.0, 1.0])
    est = lambda kind, **kw: np.asarray(paired.regret_estimate(kind, pm, pb, am, ab, OPTIMAL, **kw))  # noqa: E731
    np.testing.assert_allclose(est("paired"), [5 - 2, 1 - 1])
    np.testing.assert_allclose(est("flexible"), [5 - 2, 2 - 1])  # the antagonist is better, then the protagonist
    np.testing.assert_allclose(est("perfect"), [4 - 2, 0.5 - 1])  # negative: the protagonist beats the optimum given
    np.testing.assert_allclose(est("perfect", clip_negative=True), [2.0, 0.0])
    with pytest.raises(ValueError, match="regret estimator must be one of"):
        paired.regret_estimate("max", pm, pb, am, ab)


def test_flexible_is_the_better_agents_best_minus_the_others_mean():
    """DCD's flexible PAIRED (adversarial_runner.py, ``flexible_paired``): whichever agent has the
    higher best return (the protagonist on a tie, the third level) is the antagonist of that
    level: 3, 3 and 4 here. Not the population regret max(best) − mean of means (2.25, 4 and
    3.5), nor the antagonist on a tie (3 at the third level)."""
    pm, pb = jnp.asarray([2.0, 1.0, 1.0]), jnp.asarray([3.0, 6.0, 4.0])
    am, ab = jnp.asarray([3.5, 3.0, 0.0]), jnp.asarray([5.0, 5.0, 4.0])
    np.testing.assert_allclose(paired.regret_estimate("flexible", pm, pb, am, ab), [5 - 2, 6 - 3, 4 - 0])


def test_flexible_reads_a_protagonist_with_no_ended_episode_by_its_partial_return():
    """The train step gives the protagonist's best as MaxMC's record: −inf where no episode ended.
    The flexible estimate then reads its partial return (the mean), as the antagonist's is read:
    the protagonist (−1) beats the antagonist's best (−3) and the regret is −1 − (−3) = 2 (with
    −inf the antagonist would have been the better agent: −3 − (−1) = −2)."""
    pm, pb = jnp.asarray([-1.0]), jnp.asarray([-jnp.inf])
    am, ab = jnp.asarray([-3.0]), jnp.asarray([-3.0])
    assert float(paired.regret_estimate("flexible", pm, pb, am, ab)[0]) == 2.0


def test_regret_by_tag_splits_the_estimate_and_the_antagonists_luck_by_level_tag():
    """Four levels, two hidden: each tag's mean of the estimate, of the antagonist's best − mean,
    and of the exact regret, by hand; a tag no level carries is NaN, never 0."""
    import jax

    levels = jnp.array([0, 1, 1, 0])  # 1: hidden
    tags = jax.vmap(lambda level: {"hidden": level == 1, "never": level < 0})(levels)
    regret = jnp.array([1.0, 4.0, 6.0, 3.0])
    luck = jnp.array([0.0, 2.0, 1.0, 0.5])
    out = {k: float(v) for k, v in paired.regret_by_tag(tags, regret, luck, jnp.array([5.0, 9, 9, 5]),
                                                         jnp.array([4.0, 1, 3, 2])).items()}
    assert out["paired/regret/hidden"] == 5.0 and out["paired/regret/untagged"] == 2.0
    assert out["paired/antagonist_luck/hidden"] == 1.5 and out["paired/antagonist_luck/untagged"] == 0.25
    assert out["paired/exact_regret/hidden"] == 7.0 and out["paired/exact_regret/untagged"] == 2.0
    assert np.isnan(out["paired/regret/never"]) and np.isnan(out["paired/antagonist_luck/never"])
    no_optimum = paired.regret_by_tag(tags, regret, luck, None, jnp.zeros(4))
    assert not any("exact_regret" in k for k in no_optimum)


def test_negative_paired_regret_is_passed_on_unless_clipped():
    pm, pb = jnp.array([3.0]), jnp.array([3.0])
    am, ab = jnp.array([1.0]), jnp.array([2.0])
    assert float(paired.regret_estimate("paired", pm, pb, am, ab)[0]) == -1.0
    assert float(paired.regret_estimate("paired", pm, pb, am, ab, clip_negative=True)[0]) == 0.0


def test_the_generator_is_paid_on_its_last_step_and_never_bootstraps_past_it():
    regret = jnp.array([2.0, -1.0])
    rewards, dones = paired.generator_rewards(regret, 4)
    np.testing.assert_array_equal(rewards, [[0, 0], [0, 0], [0, 0], [2, -1]])
    np.testing.assert_array_equal(dones, [[0, 0], [0, 0], [0, 0], [1, 1]])
    values = jnp.array([[0.5, 0.1], [0.4, 0.2], [0.3, 0.3], [0.2, 0.4]])
    for last_value in (jnp.zeros(2), jnp.array([100.0, -100.0])):  # what follows the episode does not count
        adv, _ = compute_gae(rewards, values, dones, last_value, gamma=0.9, lam=1.0)
        np.testing.assert_allclose(adv[-1], regret - values[-1], rtol=1e-6)
        # before the last step: the discounted regret to come minus the value (λ = 1: Monte Carlo)
        np.testing.assert_allclose(adv[0], 0.9 ** 3 * regret - values[0], rtol=1e-6)


def test_a_complete_overlap_pays_the_configured_regret():
    import dataclasses

    from remidi.engine.adversaries.paired import GeneratorSequence
    from test_ued_engine import TINY

    class Setup:  # what _pay reads
        cfg = TINY

    regret = jnp.array([3.0, -1.0, 5.0])
    overlap = jnp.array([True, False, False])
    seq = GeneratorSequence()
    np.testing.assert_allclose(seq._pay(Setup, regret, overlap), [-1.0, -1.0, 5.0])  # lowest of the update's
    Setup.cfg = dataclasses.replace(TINY, paired=dataclasses.replace(TINY.paired, overlap_regret="zero"))
    np.testing.assert_allclose(seq._pay(Setup, regret, overlap), [0.0, -1.0, 5.0])


@pytest.fixture(scope="module")
def generator_sequence():
    """Five runners of ReMiDi over PAIRED on the lever game (3 generators, a switch every 2
    updates: after updates 2 and 4) and, per update, what its compiled step computed: the regret
    estimate of each level, what the generator was paid for it, and the loss mask of each PPO
    update of an agent (the antagonist's, then the protagonist's)."""
    import dataclasses

    import jax

    from remidi.engine import learner as lrn
    from remidi.engine import train as tr
    from test_ued_engine import TASK, TINY

    records = {"regret": [], "paid": [], "mask": []}

    def record(name, x):
        jax.debug.callback(lambda v: records[name].append(np.asarray(v)), x, ordered=True)

    real_estimate, real_rewards, real_ppo = paired.regret_estimate, paired.generator_rewards, lrn.ppo_update

    def estimate(*args, **kwargs):
        regret = real_estimate(*args, **kwargs)
        record("regret", regret)
        return regret

    def rewards(paid, num_steps):
        record("paid", paid)
        return real_rewards(paid, num_steps)

    def ppo_update(state, carry, batch, *args):
        record("mask", batch.mask)
        return real_ppo(state, carry, batch, *args)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(paired, "regret_estimate", estimate)
        mp.setattr(paired, "generator_rewards", rewards)
        mp.setattr(lrn, "ppo_update", ppo_update)
        cfg = dataclasses.replace(TINY, remidi=dataclasses.replace(TINY.remidi, num_buffers=3, steps_per_buffer=2))
        setup = tr.make_setup(TASK, cfg, "remidi-paired")
        runners = [tr.init_runner(setup, jax.random.PRNGKey(0))]
        step = jax.jit(lambda r: tr.train_step(setup, r)[0])
        for _ in range(4):
            runners.append(step(runners[-1]))
        jax.effects_barrier()
    return setup, runners, records


def test_each_switch_starts_a_fresh_generator_and_keeps_the_antagonist(generator_sequence):
    import jax

    _, (r0, r1, r2, r3, r4), _ = generator_sequence
    fresh = [jax.tree.map(lambda x: x[k], r0.adversary.next_generators.params) for k in (0, 1)]
    same = lambda a, b: all(np.array_equal(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))  # noqa: E731
    assert int(r1.adversary.active) == 0 and not same(r1.adversary.generator.params, r0.adversary.generator.params)  # it learns, no switch
    # update 2 switches to buffer 1 with the first fresh generator, optimiser restarted; update 4
    # to buffer 2 with the second
    for runner, k in ((r2, 0), (r4, 1)):
        assert int(runner.adversary.active) == k + 1 and int(runner.adversary.count) == 0 and int(runner.adversary.generator.step) == 0
        assert same(runner.adversary.generator.params, fresh[k])
    assert int(r3.adversary.active) == 1 and not same(r3.adversary.generator.params, fresh[0])  # the first fresh one learnt
    # the antagonist is one for all generators: it kept learning across both switches
    for before, after in ((r1, r2), (r3, r4)):
        assert not same(after.adversary.antagonist.params, before.adversary.antagonist.params)
        assert int(after.adversary.antagonist.step) > int(before.adversary.antagonist.step)


def test_one_generator_is_paired_with_a_reservoir():
    """remidi.num_buffers=1 (as for remidi, where one buffer is PLR⊥): one generator, never
    switched. Its train step traces (before, it read the later generators, which do not exist,
    and failed with an AttributeError while compiling)."""
    import dataclasses

    import jax

    from remidi.engine import train as tr
    from remidi.engine.run.validation import validate_ued_config
    from test_ued_engine import TASK, TINY

    cfg = dataclasses.replace(TINY, remidi=dataclasses.replace(TINY.remidi, num_buffers=1))
    validate_ued_config(cfg, "remidi-paired", TASK)
    setup = tr.make_setup(TASK, cfg, "remidi-paired")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    assert runner.adversary.next_generators is None
    after, _ = jax.eval_shape(lambda r: tr.train_step(setup, r), runner)
    assert after.adversary.active.shape == () and after.adversary.generator.step.shape == ()


def test_a_complete_overlap_trains_the_protagonist_nothing_and_pays_the_lowest_regret(generator_sequence):
    """Update 3, the second generator's first: a level whose every step a level of the first
    generator's reservoir explains (the lever game: a hidden level, whichever lever) gives the
    protagonist's PPO update no unmasked step and pays the generator the update's lowest regret
    estimate; the other levels train and are paid their own estimate."""
    _, _, records = generator_sequence
    assert len(records["regret"]) == 4 and len(records["mask"]) == 8  # per update: antagonist, protagonist
    regret, paid = records["regret"][2], records["paid"][2]
    antagonist_mask, protagonist_mask = records["mask"][4], records["mask"][5]  # [T, N]
    assert antagonist_mask.all()  # the antagonist plays with nothing frozen
    overlap = ~protagonist_mask.any(axis=0)
    assert overlap.any() and not overlap.all()  # the test needs both kinds of level
    np.testing.assert_allclose(paid[overlap], np.min(regret))
    np.testing.assert_allclose(paid[~overlap], regret[~overlap])
    assert np.min(regret) < np.max(regret[overlap])  # the lowest estimate is a real cut for an overlapping level
    for k in range(2):  # before the first switch nothing is frozen: every step of every level trains
        assert records["mask"][2 * k + 1].all()
        np.testing.assert_allclose(records["paid"][k], records["regret"][k])


def test_the_reference_generator_reads_a_maze_design_by_conv_and_carries_its_lstm():
    """paired.generator_network=reference: the reference libraries' adversary (conv 128 over the
    maze design, the embedded step and the noise into a 256-unit LSTM); its outputs depend on the
    design and the noise, and its carry restarts where an episode does."""
    import jax

    from remidi.engine.core.networks import GeneratorLSTMActorCritic
    from remidi.envs.maze import maze_task

    builder = maze_task("tmaze").level_builder
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    obs, _ = jax.vmap(lambda k: builder.reset_env_to_level(k, None, None))(keys)
    obs = jax.tree.map(lambda x: x[None], obs)  # [T=1, N=3, ...]
    net = GeneratorLSTMActorCritic(num_actions=builder.num_actions)
    reset = jnp.ones((1, 3), bool)
    params = net.init(jax.random.PRNGKey(1), net.initialize_carry(3), obs, reset)
    assert params["params"]["conv"]["kernel"].shape == (3, 3, 4, 128)
    carry, (logits, value) = net.apply(params, net.initialize_carry(3), obs, reset)
    assert logits.shape == (1, 3, builder.num_actions) and value.shape == (1, 3)
    assert carry[0].shape == (3, 256)
    assert not np.allclose(logits[0, 0], logits[0, 1])  # the noise differs between the episodes
    # a reset step forgets the carry: the same observation after any carry gives the same output
    _, (again, _) = net.apply(params, carry, obs, reset)
    np.testing.assert_allclose(again, logits, rtol=1e-5, atol=1e-6)
    _, (kept, _) = net.apply(params, carry, obs, jnp.zeros((1, 3), bool))
    assert not np.allclose(kept, logits)


def test_paired_runs_with_the_reference_generator_and_refuses_an_unknown_one():
    import dataclasses

    import jax

    from remidi.engine import train as tr
    from remidi.errors import ConfigError
    from test_ued_engine import TASK, TINY

    cfg = dataclasses.replace(TINY, paired=dataclasses.replace(TINY.paired, generator_network="reference"))
    setup = tr.make_setup(TASK, cfg, "paired")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    assert "lstm" in runner.adversary.generator.params
    new, metrics = jax.jit(lambda r: tr.train_step(setup, r))(runner)
    assert np.isfinite(float(metrics["paired/generator_entropy"]))
    assert int(new.adversary.generator.step) > int(runner.adversary.generator.step)
    bad = dataclasses.replace(TINY, paired=dataclasses.replace(TINY.paired, generator_network="big"))
    from remidi.engine.run.validation import validate_ued_config

    with pytest.raises(ConfigError, match="paired.generator_network.*mlp, reference"):
        validate_ued_config(bad, "paired", TASK)


def test_paired_pays_in_the_agents_reward_units_and_normalises_both_agents_with_the_protagonists_statistics(
        monkeypatch):
    """PAIRED pays the generator regret × reward_scale (Brax: ÷ 10), as the agents learn from
    reward × reward_scale; the logged regret stays in the environment's units. normalize_obs
    (every Brax preset) with a learned generator: the antagonist acts and learns on observations
    normalised by the runner's statistics, which absorb the protagonist's rollout alone (T·N
    observations per update). (One configuration for both: each spy's callbacks keep its program
    out of the persistent cache, so every run of the suite compiles it.)"""
    import dataclasses

    import jax

    from remidi.engine import learner as lrn
    from remidi.engine import train as tr
    from remidi.engine.run.validation import validate_ued_config
    from test_ued_engine import TASK, TINY

    cfg = dataclasses.replace(TINY, normalize_obs=True, network="mlp", reward_scale=0.25)
    validate_ued_config(cfg, "paired", TASK)
    setup = tr.make_setup(TASK, cfg, "paired")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    seen, paid = [], []  # the statistics' count each rollout normalised with; the generator's pay
    real_collect, real_rewards = lrn.collect, paired.generator_rewards

    def spy(setup_, learner, rng, levels, frozen):
        jax.debug.callback(lambda c: seen.append(float(c)), learner.obs_stats.count)
        return real_collect(setup_, learner, rng, levels, frozen)

    def recording(regret, n):
        jax.debug.callback(lambda r: paid.append(np.asarray(r)), regret)
        return real_rewards(regret, n)

    monkeypatch.setattr(lrn, "collect", spy)
    monkeypatch.setattr(paired, "generator_rewards", recording)
    step = jax.jit(lambda r: tr.train_step(setup, r))
    r1, m1 = step(runner)
    r2, _ = step(r1)
    jax.effects_barrier()
    per_update = cfg.num_envs * cfg.num_steps
    assert float(r2.learner.obs_stats.count) == 2 * per_update  # the antagonist's rollouts add nothing
    assert sorted(seen) == [0, 0, per_update, per_update]  # both agents of an update read the same statistics
    assert int(r2.adversary.antagonist.step) > int(runner.adversary.antagonist.step)
    np.testing.assert_allclose(float(np.mean(paid[0])), 0.25 * float(m1["paired/regret"]), rtol=1e-5)
    assert abs(float(m1["paired/regret"])) > 0.1  # a regret of 0 would not tell the scales apart


def _reservoir(batches):
    """GeneratorSequence's reservoir after ``_keep`` of ``batches`` (each 8 lever level ids: id
    = correct + 64·hidden, so ids 0..127 are the 128 levels), update u drawing its keys from
    PRNGKey(100 + u) as the step would hand it: (held ids, held scores, the keys drawn)."""
    import jax

    from remidi.engine.adversaries import level_buffer as buf
    from remidi.engine import train as tr
    from remidi.engine.adversaries.base import Proposal
    from remidi.envs.lever import LeverLevel
    from test_ued_engine import TASK, TINY

    setup = tr.make_setup(TASK, TINY, "remidi-paired")
    assert setup.cfg.remidi.buffer_capacity == 8 == setup.cfg.num_envs
    assert setup.cfg.buffer.duplicate_check  # as in every preset
    seq = setup.algo.adversary

    @jax.jit
    def keep(runner, level_ids, rng):
        levels = LeverLevel(correct=(level_ids % 64).astype(jnp.int32), visible=level_ids < 64)
        proposal = Proposal(replay=jnp.asarray(False), levels=levels, buffer=None, slots=None, train=jnp.asarray(True))
        state, _ = seq._keep(setup, runner.adversary, proposal, rng)
        return runner.replace(adversary=state)

    runner, keys = tr.init_runner(setup, jax.random.PRNGKey(0)), []
    for u, ids in enumerate(batches):
        rng = jax.random.PRNGKey(100 + u)
        runner = keep(runner, jnp.asarray(ids, jnp.int32), rng)
        keys.append(np.asarray(jax.random.uniform(rng, (8,))))  # the keys _keep draws from that rng
    held = buf.select_buffer(runner.adversary.buffers, runner.adversary.active)
    assert np.asarray(held.valid).all()
    held_ids = np.asarray(held.levels.correct) + 64 * ~np.asarray(held.levels.visible)
    return held_ids, np.asarray(held.scores), np.concatenate(keys)


def test_a_generators_support_is_a_reservoir_of_the_levels_it_generated():
    """GeneratorSequence keeps a reservoir of its generator's levels: every generated level draws
    an i.i.d. uniform key and the active buffer keeps the remidi.buffer_capacity levels of highest
    key. A level generated again (buffer.duplicate_check, on in every preset) keeps the highest of
    its keys in its one entry, so the reservoir holds the distinct levels whose best draw is
    highest: a level generated m times is kept as if any of its m copies had been, a sample
    weighted by how often the generator makes it.

    Ten updates of 8 distinct levels (80 in all) into a reservoir of 8: exactly the 8 of highest
    key. Then twenty updates over 12 levels, with repeats within an update and across updates:
    the 8 whose highest key is highest. (Before, a repeat overwrote its entry's key with the
    newest draw: a level made in every update had one uniform key like a level made once, and
    a lever generator that made visible levels 3 % of the time still froze about a third of its
    reservoir visible, each of them then masked for the protagonist.)"""
    distinct = [np.arange(8 * u, 8 * u + 8) for u in range(10)]
    held, scores, keys = _reservoir(distinct)
    ids = np.concatenate(distinct)
    assert sorted(held.tolist()) == sorted(ids[np.argsort(keys)[-8:]].tolist())
    np.testing.assert_allclose(np.sort(scores), np.sort(keys)[-8:])

    draw = np.random.default_rng(0)
    repeated = [draw.choice(12, size=8, replace=True) for _ in range(20)]  # in-batch repeats too
    held, scores, keys = _reservoir(repeated)
    ids = np.concatenate(repeated)
    best = {int(i): float(keys[ids == i].max()) for i in np.unique(ids)}
    top = sorted(best, key=best.get)[-8:]
    assert sorted(held.tolist()) == sorted(top)
    np.testing.assert_allclose(np.sort(scores), np.sort([best[i] for i in top]))