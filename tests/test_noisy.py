"""The stochastic test domains (:mod:`remidi.envs.noisy`): the noise is the level's
(deterministic given the level, unrelated to the answer), visible levels stay solvable, and the
exact tracker, exact as ever, finds no complete overlap between two irreducible levels that
differ only in their seeds, where the plain domains' levels overlap completely."""

import functools
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import optimizing
from remidi.cli import main
from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import ExactTracker
from remidi.envs.lever import LeverLevel, lever_task
from remidi.envs.maze import maze_task
from remidi.envs.noisy import NOISE_BITS, SeededLevel, noisy_blindfold_task, noisy_lever_task

pytestmark = pytest.mark.usefixtures("no_png")  # no test here reads a plot

LEVERS = 8  # a small lever game: the same code paths as the experiment's 64
NOISY, PLAIN = noisy_lever_task(LEVERS), lever_task(LEVERS)


def stack(*levels):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *levels)


def lever(correct, visible, seed):
    return SeededLevel(level=LeverLevel(correct=jnp.asarray(correct, jnp.int32), visible=jnp.asarray(visible)),
                       seed=jnp.asarray(seed, jnp.uint32))


@functools.lru_cache(maxsize=None)
def play(task, steps):
    """jit: (levels [N], actions i32[steps]) -> observations (leaves [N, steps + 1, ...]), rewards
    f32[N, steps]: a reset, then the same action sequence on every level, twice over (the second
    run's observations and rewards are returned with the first's for the determinism check)."""
    env, params = task.env, task.params

    def one(level, actions, key):
        obs, state = env.reset_to_level(key, level, params)

        def body(state, inp):
            action, k = inp
            obs, state, reward, _, _ = env.step(k, state, action, params)
            return state, (obs, reward)

        _, (seen, rewards) = jax.lax.scan(body, state, (actions, jax.random.split(key, steps)))
        seen = jax.tree.map(lambda a, b: jnp.concatenate([a[None], b]), obs, seen)
        return seen, rewards

    def run(levels, actions):
        n = jax.tree.leaves(levels)[0].shape[0]
        first = jax.vmap(one, in_axes=(0, None, 0))(levels, actions, jax.random.split(jax.random.PRNGKey(1), n))
        again = jax.vmap(one, in_axes=(0, None, 0))(levels, actions, jax.random.split(jax.random.PRNGKey(2), n))
        return first, again

    return jax.jit(run)


def indistinguishable(task, agents, frozen_levels, steps, action=0):
    """bool[steps, N]: the exact tracker's verdict on each env's prefix (all frozen levels valid),
    under a constant action."""
    n = jax.tree.leaves(agents)[0].shape[0]

    def apply(variables, carry, obs, reset):
        return carry, (jnp.zeros((1, n, task.num_actions)).at[..., action].set(10.0), jnp.zeros((1, n)))

    f = jax.tree.leaves(frozen_levels)[0].shape[0]
    traj, _ = rollout(jax.random.PRNGKey(0), Stepping(task.env, task.params, task.deterministic_reset),
                      Policy(apply, {}, jnp.zeros(n)), agents, steps,
                      Frozen(levels=frozen_levels, valid=jnp.ones(f, bool), tracker=ExactTracker("prefix")))
    return np.asarray(traj.indist)


# ------------------------------------------------------------------------------------ lever-noisy
def test_lever_noise_code_varies_with_the_seed_only_and_is_deterministic():
    levels = jax.jit(jax.vmap(NOISY.sample_level))(jax.random.split(jax.random.PRNGKey(0), 256))
    (obs, rewards), (obs2, rewards2) = play(NOISY, 2)(levels, jnp.zeros(2, jnp.int32))
    obs, obs2 = np.asarray(obs), np.asarray(obs2)
    assert obs.shape == (256, 3, LEVERS + 1 + NOISE_BITS)
    np.testing.assert_array_equal(obs, obs2)  # reset + steps twice (other keys): the same observations
    np.testing.assert_array_equal(rewards, rewards2)
    assert (obs == obs[:, :1]).all()  # the level's code, in every observation of every episode
    plain = np.asarray(jax.vmap(PLAIN.env.observation)(levels.level))
    np.testing.assert_array_equal(obs[:, 0, :LEVERS + 1], plain)  # the plain observation, then the code
    codes = {tuple(c) for c in obs[:, 0, LEVERS + 1:].astype(int)}
    assert len(codes) > 250  # 256 levels, 2^16 codes: (almost) all distinct
    assert set(np.unique(obs[:, 0, LEVERS + 1:])) == {0.0, 1.0}
    assert 0.45 < obs[:, 0, LEVERS + 1:].mean() < 0.55  # fair bits
    hidden = ~np.asarray(levels.level.visible)
    assert 0.3 < hidden.mean() < 0.7
    np.testing.assert_array_equal(np.asarray(jax.vmap(NOISY.level_tags)(levels)["hidden"]), hidden)
    np.testing.assert_array_equal(np.asarray(jax.vmap(NOISY.optimal_return)(levels)), np.where(hidden, 10.0, 1.0))


def test_lever_noise_is_independent_of_the_answer_and_visible_levels_stay_solvable():
    seeds = jax.random.bits(jax.random.PRNGKey(3), (64,), jnp.uint32)
    for visible in (False, True):
        by_answer = [stack(*[lever(a, visible, s) for s in seeds]) for a in (1, 5)]
        (obs_a, _), _ = play(NOISY, 1)(by_answer[0], jnp.zeros(1, jnp.int32))
        (obs_b, _), _ = play(NOISY, 1)(by_answer[1], jnp.zeros(1, jnp.int32))
        obs_a, obs_b = np.asarray(obs_a), np.asarray(obs_b)
        # the code is the same for either answer, given the seed
        np.testing.assert_array_equal(obs_a[..., LEVERS + 1:], obs_b[..., LEVERS + 1:])
        if not visible:  # a hidden level's observation says nothing about the answer
            np.testing.assert_array_equal(obs_a, obs_b)
    # a hand policy that pulls the lever the observation shows solves every visible level
    levels = NOISY.eval_sets["visible"]
    obs, _ = jax.vmap(NOISY.env.reset_to_level, in_axes=(None, 0, None))(jax.random.PRNGKey(0), levels, NOISY.params)
    pull = jnp.argmax(obs[:, 1:LEVERS + 1], axis=1)
    _, _, reward, done, _ = jax.vmap(NOISY.env.step, in_axes=(None, 0, 0, None))(
        jax.random.PRNGKey(0), jax.vmap(NOISY.env.reset_to_level, in_axes=(None, 0, None))(
            jax.random.PRNGKey(0), levels, NOISY.params)[1], pull, NOISY.params)
    np.testing.assert_array_equal(np.asarray(reward), 1.0)
    assert np.asarray(done).all()
    probs = jax.nn.one_hot(pull, LEVERS)
    np.testing.assert_allclose(np.asarray(jax.vmap(NOISY.expected_return)(levels, probs)), 1.0)
    assert len({int(s) for s in np.asarray(NOISY.eval_sets["hidden"].seed)}) == LEVERS  # fixed, distinct seeds


def test_lever_builder_and_editor_draw_fresh_seeds():
    builder = NOISY.level_builder
    keys = jax.random.split(jax.random.PRNGKey(4), 2)
    built = [builder.build(k, jnp.asarray([LEVERS + 3])) for k in keys]  # hidden, lever 3
    assert all(int(b.level.correct) == 3 and not bool(b.level.visible) for b in built)
    assert int(built[0].seed) != int(built[1].seed)
    edited = NOISY.mutate_level(jax.random.PRNGKey(5), built[0], 3)
    assert not bool(edited.level.visible) and int(edited.seed) != int(built[0].seed)


def test_exact_tracker_finds_no_complete_overlap_between_noisy_hidden_levels():
    seeds = jax.random.bits(jax.random.PRNGKey(6), (8,), jnp.uint32)
    agents = stack(*[lever(i % LEVERS, False, seeds[i]) for i in range(4)])
    frozen = stack(*[lever((i + 1) % LEVERS, False, seeds[i + 4]) for i in range(4)])
    # the plain lever game: every hidden level is a complete overlap of every other
    assert indistinguishable(PLAIN, agents.level, frozen.level, 3).all()
    # with the seed in the level: no hidden level is explained by another seed's ...
    assert not indistinguishable(NOISY, agents, frozen, 3).any()
    # ... while the tracker stays exact: the same seed (another answer) is a complete overlap
    same_seed = frozen.replace(seed=agents.seed)
    assert indistinguishable(NOISY, agents, same_seed, 3).all()


# -------------------------------------------------------------------------------- blindfold-noisy
MAZE_NOISY, MAZE_PLAIN = noisy_blindfold_task(), maze_task("blindfold")


def maze_levels(count, blind, key=7):
    levels = jax.jit(jax.vmap(MAZE_NOISY.sample_level))(jax.random.split(jax.random.PRNGKey(key), count))
    return levels.replace(level=levels.level.replace(blind=jnp.full((count,), blind)))


def test_blind_levels_show_a_noisy_tv_from_their_seed():
    levels = maze_levels(6, True)
    turns = jnp.zeros(4, jnp.int32)  # turning left: the agent never moves, the episode never ends
    (obs, _), (obs2, _) = play(MAZE_NOISY, 4)(levels, turns)
    image, direction = np.asarray(obs.image), np.asarray(obs.agent_dir)  # [6, 5, 5, 5, 3], [6, 5]
    np.testing.assert_array_equal(image, np.asarray(obs2.image))  # deterministic given the level
    np.testing.assert_array_equal(direction, np.asarray(obs2.agent_dir))
    assert all(len({image[i, t].tobytes() for t in range(5)}) == 5 for i in range(6))  # across steps
    assert all(len({image[i, t].tobytes() for i in range(6)}) == 6 for t in range(5))  # across levels
    assert set(np.unique(direction)) == {0, 1, 2, 3}
    for c, high in enumerate((11, 6, 3)):  # each channel takes every value of its range
        assert set(np.unique(np.round(image[..., c] * 10).astype(int))) == set(range(high))
    highs = np.asarray([10, 5, 2]) / 10  # object, colour, state ranges
    assert (image >= 0).all() and (image <= highs + 1e-6).all()
    # independent of the goal: the same blind level with its goal moved (same seed) looks the same
    moved = levels.replace(level=levels.level.replace(goal_pos=levels.level.agent_pos))
    (obs_m, _), _ = play(MAZE_NOISY, 4)(moved, turns)
    np.testing.assert_array_equal(image, np.asarray(obs_m.image))
    # an ordinary level is the plain maze's, whatever its seed
    seen = maze_levels(6, False)
    (obs_n, _), _ = play(MAZE_NOISY, 4)(seen, turns)
    (obs_p, _), _ = play(MAZE_PLAIN, 4)(seen.level, turns)
    np.testing.assert_array_equal(np.asarray(obs_n.image), np.asarray(obs_p.image))
    np.testing.assert_array_equal(np.asarray(obs_n.agent_dir), np.asarray(obs_p.agent_dir))
    tags = jax.vmap(MAZE_NOISY.level_tags)(levels)["blind"]
    assert np.asarray(tags).all()


def test_exact_tracker_finds_no_complete_overlap_between_noisy_blind_levels():
    agents, frozen = maze_levels(3, True, key=8), maze_levels(3, True, key=9)
    # plain blind levels show zeros: under the same turns, a complete overlap of each other
    assert indistinguishable(MAZE_PLAIN, agents.level, frozen.level, 4).all()
    assert not indistinguishable(MAZE_NOISY, agents, frozen, 4).any()
    assert indistinguishable(MAZE_NOISY, agents, frozen.replace(seed=agents.seed), 4).all()


def test_noisy_experiments_are_registered_with_their_parents_presets():
    from remidi.experiments import lever as L
    from remidi.experiments import maze as M

    names = {e.name: e for e in L.EXPERIMENTS + M.EXPERIMENTS}
    for noisy, parent, presets in (("lever-noisy", "lever", {"smoke", "paper"}),
                                   ("blindfold-noisy", "blindfold", {"smoke", "cpu", "paper"})):
        assert presets <= set(names[noisy].presets)  # the presets the results page runs
        assert names[noisy].presets == names[parent].presets  # the same run lengths and sizes as the parent's
        assert names[noisy].preset_seeds == names[parent].preset_seeds
        assert names[noisy].algorithms == names[parent].algorithms


# ------------------------------------------------------------------------------- the headline run
@pytest.mark.slow  # one end-to-end run (≈ 10 s on a 2-core CPU): `pytest -m "not slow"` skips it
def test_remidi_on_lever_noisy_takes_hidden_levels_into_its_later_buffer(tmp_path):
    """``remidi run lever-noisy --algo remidi --preset smoke --seeds 1 --set num_updates=150``: on
    the plain lever game ReMiDi's second buffer never takes a hidden level
    (tests/test_lever_smoke.py: complete overlap with the first); with the noise code nothing
    overlaps, so after the switch (update 100) the second buffer fills with hidden levels again
    and ReMiDi behaves as PLR⊥ (measured at the full smoke preset, 1 seed: buffer and replay
    fractions of hidden levels 1.0, visible solve rate 0.02 against 0.19 on the plain game; after
    150 updates, 2 seeds: 1.0 and 1.0). The results page has the 10-seed paper-preset runs."""
    out = tmp_path / "remidi"
    with optimizing():  # 150 updates of the smoke preset run long enough to pay for XLA's optimisations
        assert main(["run", "lever-noisy", "--algo", "remidi", "--preset", "smoke", "--seeds", "1", "--out", str(out),
                     "--quiet", "--set", "num_updates=150"]) == 0
    m = {k: v["mean"] for k, v in json.loads((out / "summary.json").read_text())["metrics"].items()}
    assert m["active_buffer"] == 1
    assert m["buffer_fraction/hidden/b0"] > 0.9
    assert m["buffer_fraction/hidden"] > 0.5  # the later buffer accepts hidden levels
    assert m["replay_fraction/hidden"] > 0.5
    assert m["regret/hidden/worst"] >= 20 * (1 - 1 / 64) - 1e-3


def test_reseed_plays_each_rollout_with_the_levels_randomness_drawn_afresh():
    """``reseed``: the same plain level, a new seed per rollout, so the noise code the agent sees
    is not the stored level's; without it the rollout shows the stored seed's code."""
    import dataclasses

    from remidi.engine.run import driver
    from remidi.engine import learner as lrn
    from remidi.engine import train as tr
    from remidi.engine.config import UEDConfig

    level = lever(3, False, 12345)
    again = NOISY.reseed_level(jax.random.PRNGKey(0), level)
    assert again.level == level.level and int(again.seed) != 12345
    levels = stack(*[level] * 4)
    stored = NOISY.env.reset_to_level(jax.random.PRNGKey(0), level, NOISY.params)[0]
    for reseed in (False, True):
        cfg = dataclasses.replace(UEDConfig(num_envs=4, num_steps=2), reseed=reseed)
        setup = tr.make_setup(NOISY, cfg, "dr")
        runner = driver._init(setup, jax.random.PRNGKey(1)[None])
        runner = jax.tree.map(lambda x: x[0], runner)
        traj = lrn.collect(setup, runner.learner, jax.random.PRNGKey(2), levels, None).traj
        same = [bool(jnp.array_equal(traj.obs[0, n], stored)) for n in range(4)]
        assert same == [not reseed] * 4, (reseed, same)


def test_reseed_is_refused_for_a_task_whose_levels_carry_no_randomness(tmp_path, capsys):
    code = main(["run", "lever", "--algo", "dr", "--preset", "smoke", "--seeds", "1", "--set", "reseed=true",
                 "--out", str(tmp_path / "run"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "reseed" in err and "reseed_level" in err
    assert not (tmp_path / "run").exists()
