"""The simulated belief model's parts (remidi.engine.trackers.simulated): replaying a level
reproduces a rollout of it, the noise table learns the identity where the environment is
deterministic and the noise's distribution where it is not, and the mixture over a buffer's
candidates is a mean of likelihoods."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import optimizing
from remidi.engine.trackers import belief_model as bm
from remidi.engine.trackers import calibration as cal
from remidi.engine.trackers import noise
from remidi.engine.trackers import simulated as sm
from remidi.engine.learner import Policy, Stepping, rollout

pytestmark = pytest.mark.usefixtures("no_png")  # no test here reads a plot

T, N = 24, 32


def _random_rollout(task, key, params=None):
    a, params = task.num_actions, task.params if params is None else params

    def policy(variables, carry, obs, reset):
        return carry, (jnp.zeros(reset.shape + (a,)), jnp.zeros(reset.shape))

    levels = jax.vmap(task.sample_level)(jax.random.split(key, N))
    traj, _ = rollout(jax.random.fold_in(key, 1), Stepping(task.env, params, task.deterministic_reset),
                      Policy(policy, {}, jnp.zeros(1)), levels, T)
    return levels, traj


def _coding(task, levels):
    example, _ = task.env.reset_to_level(jax.random.PRNGKey(0), jax.tree.map(lambda x: x[0], levels), task.params)
    return bm.coding_for(example)


@pytest.fixture(scope="module")
def lever():
    from remidi.envs.lever import lever_task

    task = lever_task(8)
    levels, traj = _random_rollout(task, jax.random.PRNGKey(3))
    return task, levels, traj, _coding(task, levels)


@pytest.fixture(scope="module")
def noisy_maze():
    from remidi.envs.noisy import noisy_blindfold_task

    import dataclasses

    task = noisy_blindfold_task(0.5, 25)
    # episodes of 7 steps: the 24-step rollout restarts each level three times
    task = dataclasses.replace(task, params=task.params.replace(max_steps_in_episode=7))
    levels, traj = _random_rollout(task, jax.random.PRNGKey(4))
    return task, levels, traj, _coding(task, levels)


def _replayed(task, coding, levels, traj, reseed=None):
    @jax.jit
    def go(levels, actions, resets, key):
        def one(level, acts, rs, k):
            k1, k2 = jax.random.split(k)
            level = level if reseed is None else reseed(k1, level)
            return noise.replay_level(task.env, task.params, coding, level, acts, rs, k2)
        return jax.vmap(one, in_axes=(0, 1, 1, 0), out_axes=1)(levels, actions, resets, jax.random.split(key, N))
    return go(levels, traj.action, traj.reset, jax.random.PRNGKey(9))


def test_replaying_a_level_with_the_rollouts_actions_gives_its_observations_and_ends(lever):
    """The lever game ends every episode after one step: each step's replay restarts, and the
    end entry records every end. Replayed codes equal the rollout's, end entries included."""
    task, levels, traj, coding = lever
    agent = noise.recorded_codes(coding, traj.obs, traj.reset)
    assert bool(jnp.all(agent[1:, :, -1] == 1)) and bool(jnp.all(agent[0, :, -1] == 0))
    np.testing.assert_array_equal(np.asarray(_replayed(task, coding, levels, traj)), np.asarray(agent))


def test_replaying_a_noisy_level_with_its_own_seed_gives_its_observations_through_restarts(noisy_maze):
    """blindfold-noisy with 7-step episodes: the replay restarts where the rollout did (the
    noise, a function of the seed and the episode's step, restarts with it)."""
    task, levels, traj, coding = noisy_maze
    agent = noise.recorded_codes(coding, traj.obs, traj.reset)
    assert int(agent[:, :, -1].sum()) >= 3 * N  # ends at steps 7, 14, 21 (and at the goal)
    np.testing.assert_array_equal(np.asarray(_replayed(task, coding, levels, traj)), np.asarray(agent))


def test_the_table_learns_the_identity_where_the_game_is_deterministic(lever):
    task, levels, traj, coding = lever
    counts = noise.count_rollout(noise.init_counts(coding), task.env, task.params, coding, None, levels, traj,
                                 jax.random.PRNGKey(5))
    assert float(counts.sum()) == T * N * (coding.num_entries + 1)
    assert float(counts[:, 0].sum()) == 0.0  # the copies always agree: d = 1
    logq = noise.log_q(counts)
    seen = np.asarray(counts[:, 1].sum(-1) > 0)  # [E+1, K, K] rows that were seen
    k = counts.shape[-1]
    diag = np.asarray(logq[:, 1][..., np.arange(k), np.arange(k), np.arange(k)])  # log q(o = a | a, a)
    rows = np.nonzero(seen[:, np.arange(k), np.arange(k)])
    assert np.all(diag[rows] > np.log(0.99))
    # the agent's own observation is likely, any other one is not
    agent = noise.recorded_codes(coding, traj.obs, traj.reset)
    own = noise.step_logq(logq, agent, agent, agent)
    other = noise.step_logq(logq, agent, jnp.roll(agent, 1, axis=1), jnp.roll(agent, 1, axis=1))
    differs = np.asarray(jnp.any(agent != jnp.roll(agent, 1, axis=1), axis=-1))
    assert np.all(np.asarray(own) > -0.1)
    assert np.all(np.asarray(other)[differs] < -5.0)


def test_on_a_noisy_tv_the_table_learns_uniform_noise_and_keeps_the_walls(noisy_maze):
    """blindfold-noisy: a blind level's copies under fresh seeds disagree (d = 0) and show the
    noise, drawn uniformly in each channel's range; an ordinary maze's copies agree (d = 1)."""
    task, levels, traj, coding = noisy_maze
    counts = noise.count_rollout(noise.init_counts(coding), task.env, task.params, coding, task.reseed_level, levels,
                                 traj, jax.random.PRNGKey(5))
    blind = np.asarray(jax.vmap(lambda l: task.level_tags(l)["blind"])(levels))
    assert 0 < blind.sum() < N
    noisy_share = float(counts[:, 0].sum() / counts.sum())
    assert abs(noisy_share - blind.mean()) < 0.05  # the steps of blind levels, and only those
    k = counts.shape[-1]
    off = 1 - np.asarray(counts[:-1, 0].sum(-1))[:, np.arange(k), np.arange(k)].sum() / float(counts[:-1, 0].sum())
    # the copies' noisy entries differ: 10/11, 5/6 and 2/3 of the time for the cells' three channels,
    # 3/4 for the direction: 0.80 of the 76 entries
    assert abs(off - (25 * (10 / 11 + 5 / 6 + 2 / 3) + 3 / 4) / 76) < 0.02
    # the object channel (first of each cell's three, 11 values): rows d = 0 are uniform over 0..10
    obj = np.asarray(counts[0:75:3, 0]).sum((0, 2))  # [ô¹, o], pooled over the cells and ô²
    freq = obj / obj.sum(-1, keepdims=True)  # ≈ 870 draws per row
    assert np.abs(freq - 1 / 11).max() < 0.05
    # ordinary mazes: the agent's view is one of the copies' (identity)
    logq = noise.log_q(counts)
    agent = noise.recorded_codes(coding, traj.obs, traj.reset)
    plain = _replayed(task, coding, levels, traj)
    own = np.asarray(noise.step_logq(logq, agent, plain, plain))
    assert np.all(own[:, ~blind] > -2.0)  # what the smoothing of rarely seen rows costs
    shifted = jnp.roll(plain, 1, axis=1)  # another env's level
    other = np.asarray(noise.step_logq(logq, agent, shifted, shifted))
    both = ~blind & np.roll(~blind, 1)
    differs = np.asarray(jnp.any(agent != shifted, axis=-1))[:, both]
    assert np.all(other[:, both][differs] < own[:, both][differs] - 5.0)


def test_the_mixture_is_the_log_mean_likelihood_over_each_buffers_valid_levels():
    valid = jnp.array([True, True, True, False, True, True, False, False])  # 2 buffers of 4
    index = jnp.array([0, 2, 4, -1])
    totals = jnp.array([-1.0, -2.0, -3.0, 0.0])
    mix = noise.mixture(totals, index, valid, 2, 4)
    np.testing.assert_allclose(np.asarray(mix), [np.log((np.exp(-1) + np.exp(-2)) / 3), np.log(np.exp(-3) / 2)],
                               rtol=1e-6)
    assert float(noise.mixture(totals, index, jnp.zeros(8, bool), 2, 4)[0]) == -np.inf


def test_candidates_are_the_most_likely_first_observations():
    logq = jnp.log(jnp.full((2, 2, 2, 2, 2), 0.5)).at[0, 1, 1, 1, 1].set(np.log(0.9)).at[0, 1, 1, 1, 0].set(np.log(0.1))
    first = jnp.array([[1, 0], [0, 0], [1, 0], [1, 0]])  # entry 0 (category), end entry
    index, lq = noise.candidates(logq, jnp.array([1, 0]), first, first, jnp.array([True, True, False, True]), 3)
    assert list(np.asarray(index)) == [0, 3, 1]
    assert np.asarray(lq)[0] > np.asarray(lq)[2]


def _judge_fresh_levels(task, tag, variants):
    """The probe of docs/notes/belief_probe_simulated.py through the tracker component in a rollout,
    smaller: a frozen buffer of 32 levels, 90 % irreducible (as PLR⊥'s at the cpu preset), a
    random policy; the table from fresh levels' rollouts, the reference fit on one, thresholds
    calibrated on a rollout of the buffer's levels with fresh randomness, then fresh generator
    levels judged beside the exact tracker, for each of ``variants`` ((judge by the ratio over
    the reference, false rate), ...). Returns ([explained per variant], exact, irreducible)."""
    from remidi.engine.trackers.base import Frozen
    from remidi.engine.trackers.exact import ExactTracker

    t, n, c = 16, 32, 32
    a = task.num_actions

    def policy(variables, carry, obs, reset):
        return carry, (jnp.zeros(reset.shape + (a,)), jnp.zeros(reset.shape))

    # each piece one jitted program (eager operations cost ~3 ms each here), indexing on the host
    roll = jax.jit(lambda levels, key, frozen=None: rollout(
        key, Stepping(task.env, task.params, task.deterministic_reset), Policy(policy, {}, jnp.zeros(1)), levels, t,
        frozen)[0])
    sample = jax.jit(lambda key, k: jax.vmap(task.sample_level)(jax.random.split(key, k)), static_argnums=1)
    tags = lambda levels: np.asarray(jax.jit(jax.vmap(lambda l: task.level_tags(l)[tag]))(levels))  # noqa: E731
    take = lambda tree, i: jax.tree.map(lambda x: jnp.asarray(np.asarray(x)[i]), tree)  # noqa: E731
    count = jax.jit(lambda counts, levels, traj, key: noise.count_rollout(
        counts, task.env, task.params, coding, task.reseed_level, levels, traj, key))
    pool = sample(jax.random.PRNGKey(0), 1000)
    irr = tags(pool)
    idx = np.concatenate([np.nonzero(irr)[0][:29], np.nonzero(~irr)[0][:3]])
    buffer = take(pool, idx)
    coding = _coding(task, buffer)
    counts = noise.init_counts(coding)
    for i in range(2):
        levels = sample(jax.random.PRNGKey(10 + i), n)
        counts = count(counts, levels, roll(levels, jax.random.PRNGKey(20 + i)), jax.random.PRNGKey(30 + i))
    model = bm.BeliefModel(coding, num_actions=a, hidden=32)
    ref = None
    if any(reference for reference, _ in variants):
        opt = bm.make_optimizer(1e-2)
        gen = roll(sample(jax.random.PRNGKey(40), n), jax.random.PRNGKey(41))
        params = model.init(jax.random.PRNGKey(42))
        ref = jax.jit(lambda p: jax.tree.map(lambda x: x[None], bm.fit_steps(model, opt, p, opt.init(p), gen.obs,
                                                                               gen.action, gen.reset, 150)[0]))(params)
    tracker = sm.SimulatedTracker(coding, model, num_buffers=1, budget=c, reseed=task.reseed_level)
    buckets = cal.num_length_buckets(t)

    def frozen(threshold, reference):
        return Frozen(levels=buffer, valid=jnp.ones((c,), bool), tracker=tracker,
                      belief=sm.FrozenSims(logq=noise.log_q(counts), threshold=threshold, valid=jnp.ones((1,), bool),
                                           key=jax.random.PRNGKey(50), ref=ref if reference else None))

    held_levels = take(buffer, np.asarray(jax.random.randint(jax.random.PRNGKey(60), (n,), 0, c)))
    if task.reseed_level is not None:
        held_levels = jax.jit(jax.vmap(task.reseed_level))(jax.random.split(jax.random.PRNGKey(61), n), held_levels)
    held = roll(held_levels, jax.random.PRNGKey(62))
    fresh = sample(jax.random.PRNGKey(70), n)
    judged = []
    for reference, false_rate in variants:
        scores = jax.jit(lambda f, codes, act, rs: sm.score_recorded(tracker, task.env, task.params, f, codes, act, rs,
                                                                     jax.random.PRNGKey(63)))(
            frozen(jnp.zeros((1, buckets)), reference), noise.recorded_codes(coding, held.obs, held.reset), held.action,
            held.reset)[..., 0]
        tau = cal.calibrate_monotone(scores[None], bm.prefix_lengths(held.reset)[None], false_rate, buckets)
        judged.append(np.asarray(roll(fresh, jax.random.PRNGKey(71), frozen(tau[None], reference)).indist))
    exact = roll(fresh, jax.random.PRNGKey(71), Frozen(levels=buffer, valid=jnp.ones((c,), bool), tracker=ExactTracker()))
    return judged, np.asarray(exact.indist), tags(fresh)


def test_on_the_t_maze_the_simulated_model_judges_as_the_exact_tracker_does():
    """Deterministic: the table learns the identity and the mixture over the buffer is the exact
    tracker (judged alone, at the default false rate); judged by the ratio over the generator's
    GRU at false rate 0 (the results page's configuration) it agrees too. Both measured 1.00;
    the ratio at 0.05 leaves ≈ 0.1 of T-maze steps unexplained (the false rate, measured 0.89)."""
    from remidi.envs.maze import maze_task

    with optimizing():  # rollouts that step 32 candidate levels twice per env: long enough to pay
        (alone, ratio), exact, tmaze = _judge_fresh_levels(maze_task("tmaze", 0.5, 25), "tmaze",
                                                           [(False, 0.05), (True, 0.0)])
    assert exact[:, tmaze].mean() > 0.9 and exact[:, ~tmaze].mean() < 0.05
    assert np.mean(alone == exact) >= 0.99
    assert np.mean(ratio == exact) >= 0.97
    assert np.all(alone <= exact) and np.all(ratio <= exact)  # never explains what no frozen level produced


def test_on_a_noisy_tv_the_ratio_explains_fresh_blind_levels_and_no_ordinary_maze():
    """blindfold-noisy: the exact tracker explains nothing (no noise draw repeats); the simulated
    model judged by the ratio over the generator explains fresh blind levels (measured 0.9 in the
    larger probe) and not ordinary mazes, which the mixture alone would explain (a uniform noisy
    TV makes any view as likely as any other)."""
    from remidi.envs.noisy import noisy_blindfold_task

    with optimizing():
        (judged,), exact, blind = _judge_fresh_levels(noisy_blindfold_task(0.5, 25), "blind", [(True, 0.0)])
    assert exact.mean() == 0.0
    assert judged[:, blind].mean() > 0.8
    assert judged[:, ~blind].mean() < 0.1


# ------------------------------------------------------------------------------ in a run
TINY = ["--set", "num_updates=24", "--set", "eval_every=6", "--set", "checkpoint_every=6", "--set", "remidi.num_buffers=3",
        "--set", "num_envs=8", "--set", "num_steps=4", "--set", "eval_attempts=2", "--set", "ppo.epochs=1",
        "--set", "remidi.buffer_capacity=8", "--set", "remidi.steps_per_buffer=8", "--set", "buffer.topk_k=8",
        "--set", "buffer.min_fill=0.25", "--set", "remidi.tracker=simulated", "--set", "remidi.belief_hidden=8",
        "--set", "remidi.belief_reference=true"]


def test_a_simulated_run_calibrates_at_each_switch_and_resumes_to_the_uninterrupted_result(tmp_path, monkeypatch):
    """lever-noisy, 3 buffers switching every 8 updates, interrupted after update 12 (past the
    first switch): the noise table, the thresholds, the reference and its frozen copies and the
    calibration record come back from the checkpoint. Every frozen buffer got a finite threshold
    at its switch, the last none; the audit compares the judgement with the exact tracker's."""
    from test_cli import assert_resumes_to_the_uninterrupted_result

    full = assert_resumes_to_the_uninterrupted_result(
        monkeypatch, ["run", "lever-noisy", "--algo", "remidi", "--seeds", "1", "--quiet", *TINY], tmp_path, at=12)
    with np.load(next((tmp_path / "full").rglob("checkpoint.npz"))) as data:
        threshold = data[next(n for n in data.files if n.endswith(".tracker.threshold"))]  # [seed, buffer, bucket]
        counts = data[next(n for n in data.files if n.endswith(".tracker.counts"))]
    assert np.isfinite(threshold[:, :-1]).all() and np.isinf(threshold[:, -1]).all()
    assert counts.sum() == 24 * 8 * 4 * counts.shape[1]  # every update's triples: T·N·(E + 1) each
    for name in ("belief/explained", "belief/exact_explained", "belief/agreement"):
        assert 0.0 <= full[name]["mean"] <= 1.0, name


@pytest.mark.parametrize("extra, needle", [
    (["--algo", "remidi-paired"], "or belief with a learned generator"),
    (["--algo", "remidi", "--set", "remidi.belief_false_rate=1"], "remidi.belief_false_rate"),
])
def test_the_simulated_model_is_refused_where_it_cannot_run(tmp_path, capsys, extra, needle):
    from remidi.cli import main

    out = tmp_path / "run"
    assert main(["run", "lever-noisy", *extra, "--seeds", "1", "--quiet", *TINY, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err
    assert not out.exists()


def test_each_seed_draws_its_own_simulation_noise():
    """The simulated tracker's random draws (the frozen copies' noise in the rollout, the counted
    replays, the calibration) come from the runner's key: two seeds at the same update draw
    different noise (they shared one fixed key per update), the same key the same noise."""
    import dataclasses

    from remidi.engine import train as tr
    from remidi.envs.noisy import noisy_lever_task
    from test_ued_engine import TINY as CFG

    r = dataclasses.replace
    cfg = r(CFG, remidi=r(CFG.remidi, num_buffers=3, tracker="simulated", belief_hidden=8))
    setup = tr.make_setup(noisy_lever_task(8), cfg, "remidi")
    shapes = jax.eval_shape(lambda k: tr.init_runner(setup, k), jax.random.PRNGKey(0))
    runner = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
    runner = runner.replace(adversary=runner.adversary.replace(active=jnp.asarray(1, jnp.int32)))

    def key(seed):
        return np.asarray(jax.random.key_data(setup.tracker.frozen(setup, runner.replace(rng=jax.random.PRNGKey(seed))).belief.key))

    assert not np.array_equal(key(0), key(1))
    np.testing.assert_array_equal(key(0), key(0))
