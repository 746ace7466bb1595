"""The UED engine end to end on small configs: determinism, resume, atomic checkpoints,
ReMiDi's rejection invariant, config validation, and jaxued's own Maze through our interface."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine.adversaries.scores import SCORES
from remidi.engine.run import driver
from remidi.engine.run.checkpoint import load_checkpoint, save_checkpoint
from remidi.engine.run.validation import validate_ued_config
from remidi.engine.trackers import TRACKERS
from remidi.envs.interface import UEDTask
from remidi.envs.lever import lever_task
from remidi.errors import ConfigError
from remidi.experiments.lever import paper_config

R = dataclasses.replace
BASE = paper_config()
# tests/test_cli.py's LEVER_TINY (the CLI's default preset, smoke, with its 64-unit agent): the same
# configuration, so the compiled programs are shared through the persistent compilation cache
TINY = R(BASE, hidden_size=64, num_updates=40, num_envs=8, num_steps=4, eval_every=10, eval_attempts=2,
         checkpoint_every=10,
         ppo=R(BASE.ppo, epochs=1),
         buffer=R(BASE.buffer, capacity=16, topk_k=8, min_fill=0.25),
         remidi=R(BASE.remidi, buffer_capacity=8, steps_per_buffer=8))
TASK = lever_task(64)


class Crash(Exception):
    pass


def test_same_seed_same_result_and_resume_matches_uninterrupted(tmp_path):
    first = driver.train_seeds(TASK, TINY, "remidi", [0, 1], out=tmp_path / "a", progress=False)
    steps, full, raw, runner = first.steps, first.history, first.per_step, first.runner
    again = driver.train_seeds(TASK, TINY, "remidi", [0, 1], progress=False).history
    for name in full:
        np.testing.assert_array_equal(full[name], again[name], err_msg=name)

    def crash(done, metrics):
        if done == 20:
            raise Crash

    with pytest.raises(Crash):
        driver.train_seeds(TASK, TINY, "remidi", [0, 1], out=tmp_path / "b", progress=False, on_block=crash)
    second = driver.train_seeds(TASK, TINY, "remidi", [0, 1], out=driver.RunFolder(tmp_path / "b", resume=True),
                                progress=False)
    steps_b, resumed, raw_b, runner_b = second.steps, second.history, second.per_step, second.runner
    np.testing.assert_array_equal(steps, steps_b)
    for name in full:
        np.testing.assert_array_equal(full[name], resumed[name], err_msg=name)
    for name in raw:
        np.testing.assert_array_equal(raw[name], raw_b[name], err_msg=name)
    for a, b in zip(jax.tree.leaves(runner), jax.tree.leaves(runner_b)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_a_fresh_runner_is_typed_as_a_restored_one(monkeypatch):
    """A checkpoint restores every leaf strongly typed; ``driver._init`` gives the fresh runner
    the same types even where a state's constructor made a weak-typed leaf (``jnp.full(shape,
    jnp.inf)``), so a resumed run reuses the fresh run's compiled programs."""
    from remidi.engine import train as tr

    real = tr.init_runner
    monkeypatch.setattr(tr, "init_runner", lambda setup, key: (lambda r: r.replace(learner=r.learner.replace(
        frozen_params=jnp.full((3,), jnp.inf))))(real(setup, key)))  # a weak-typed leaf
    setup = tr.make_setup(TASK, TINY, "dr")
    keys = jax.vmap(jax.random.PRNGKey)(jnp.arange(2, dtype=jnp.uint32))
    shapes = jax.eval_shape(lambda k: driver._init.__wrapped__(setup, k), keys)  # traced afresh (jit's cache holds the real one)
    assert shapes.learner.frozen_params.shape == (2, 3)
    assert not any(leaf.weak_type for leaf in jax.tree.leaves(shapes))


def test_a_diverged_network_never_replaces_the_last_good_checkpoint(tmp_path, monkeypatch):
    """Parameters that turn NaN in the block after update 20 (a NaN reward, a learning rate too
    high): one line saying so, and the checkpoint of update 20 stays as it was."""
    from remidi.errors import RemidiError

    real = driver._run_block

    def diverging(setup, runner, length):
        runner, metrics = real(setup, runner, length)
        if int(np.asarray(runner.updates_done).max()) > 20:
            params = jax.tree.map(lambda x: x * jnp.nan, runner.learner.train_state.params)
            runner = runner.replace(learner=runner.learner.replace(
                train_state=runner.learner.train_state.replace(params=params)))
        return runner, metrics

    from remidi.engine.run import programs

    monkeypatch.setattr(programs, "_run_block", diverging)  # what ued_programs calls
    with pytest.raises(RemidiError, match="^training diverged: .* after update 30 .*the last checkpoint before it is kept$"):
        driver.train_seeds(TASK, TINY, "remidi", [0, 1], out=tmp_path, progress=False)
    from remidi.engine import train as tr

    runner, meta = driver.load_run_state(tr.make_setup(TASK, TINY, "remidi"), [0, 1], tmp_path / "checkpoint.npz")
    assert meta["done"] == 20 and all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(runner.learner.train_state.params))


def test_killed_checkpoint_write_leaves_previous_checkpoint_intact(tmp_path, monkeypatch):
    path = tmp_path / "checkpoint.npz"
    runner = {"a": jnp.arange(3), "b": jnp.ones(2)}
    save_checkpoint(path, runner, {"done": 1})
    before = path.read_bytes()

    def dying_savez(fh, **arrays):
        fh.write(b"partial garbage")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez", dying_savez)
    with pytest.raises(KeyboardInterrupt):
        save_checkpoint(path, {"a": jnp.arange(3) + 5, "b": jnp.zeros(2)}, {"done": 2})
    monkeypatch.undo()
    assert path.read_bytes() == before
    restored, meta = load_checkpoint(path, runner)
    assert meta == {"done": 1}
    np.testing.assert_array_equal(restored["a"], [0, 1, 2])
    assert [p.name for p in tmp_path.iterdir()] == ["checkpoint.npz"]


def test_remidi_second_buffer_never_holds_levels_overlapping_the_first():
    # seeds 0 and 1: the program compiled for the determinism test (shared through the cache)
    result = driver.train_seeds(TASK, TINY, "remidi", [0, 1], progress=False)
    hist, runner = result.history, result.runner
    levels, valid = runner.adversary.buffers.levels, np.asarray(runner.adversary.buffers.valid)  # [S, K, C]
    correct, visible = np.asarray(levels.correct), np.asarray(levels.visible)
    assert np.asarray(runner.adversary.active).tolist() == [1, 1]
    for s in range(2):
        first = {(int(c), bool(v)) for c, v, ok in zip(correct[s, 0], visible[s, 0], valid[s, 0]) if ok}
        second = {(int(c), bool(v)) for c, v, ok in zip(correct[s, 1], visible[s, 1], valid[s, 1]) if ok}
        assert any(not v for _, v in first), "PLR's first buffer should hold hidden levels"
        # hidden levels all look alike, so any hidden level overlaps the first buffer completely
        assert all(v for _, v in second), second
        assert not (first & second)
    assert hist["rejected"][:, -1].sum() > 0


@pytest.mark.parametrize("change, needle", [
    (dict(num_updates=0), "num_updates: must be an integer ≥ 1"),
    (dict(score="regret"), f"score: unknown value 'regret'; allowed: {', '.join(SCORES)}"),
    (dict(network="transformer"), "transformer"),
    (dict(buffer=R(BASE.buffer, capacity=-3)), "buffer.capacity"),
    (dict(buffer=R(BASE.buffer, replay_prob=1.5)), "buffer.replay_prob"),
    (dict(ppo=R(BASE.ppo, minibatches=5)), "ppo.minibatches"),
    (dict(remidi=R(BASE.remidi, num_buffers=5)), "remidi.num_buffers: must be small enough"),
    # the belief model's keys are checked under the exact tracker too (a value there is a mistake either way)
    (dict(remidi=R(BASE.remidi, belief_false_rate=1.5)), "remidi.belief_false_rate: must be a number in [0, 1), got 1.5"),
])
def test_invalid_configs_name_the_key(change, needle):
    with pytest.raises(ConfigError) as err:
        validate_ued_config(R(BASE, **change), "remidi", TASK)
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_an_unknown_tracker_names_every_tracker():
    """The refusal names each tracker with what it is: every name of the registry, in order."""
    with pytest.raises(ConfigError) as err:
        validate_ued_config(R(BASE, remidi=R(BASE.remidi, tracker="loose")), "remidi", TASK)
    message = str(err.value)
    assert message.startswith("remidi.tracker: unknown value 'loose'; allowed: prefix (the exact tracker, the default)")
    allowed = message.split("; allowed: ", 1)[1]
    where = [allowed.find(f"{name} (") for name in TRACKERS]  # each name, then what it is
    assert -1 not in where and where == sorted(where) and "\n" not in message


def test_unknown_algorithm_and_missing_optimal_return():
    with pytest.raises(ConfigError, match="--algo: unknown value 'poet'"):
        validate_ued_config(BASE, "poet", TASK)
    no_optimum = dataclasses.replace(TASK, optimal_return=None)
    with pytest.raises(ConfigError, match="perfect_regret needs"):
        validate_ued_config(BASE, "plr", no_optimum)
    validate_ued_config(BASE, "minimax-return", no_optimum)  # scores by return: fine


def test_a_scores_declared_needs_are_what_validation_checks():
    """Each score declares what it needs (engine/adversaries/scores.py's SCORES); validation refuses a task
    without it and lists the scores that fit the task."""
    assert SCORES["perfect_regret"].needs_optimum and SCORES["learnability"].needs_solved
    bare = dataclasses.replace(TASK, optimal_return=None, solved=None)
    allowed = ", ".join(name for name, s in SCORES.items() if not (s.needs_optimum or s.needs_solved))
    for name, score in SCORES.items():
        cfg = dataclasses.replace(BASE, score=name)
        if not (score.needs_optimum or score.needs_solved):
            validate_ued_config(cfg, "plr", bare)
            continue
        what = "the environment's optimal return" if score.needs_optimum else "a solve criterion"
        with pytest.raises(ConfigError, match=rf"^score: {name} needs {what}.*; allowed: {allowed}$"):
            validate_ued_config(cfg, "plr", bare)


def test_discounted_regret_needs_the_tasks_discounted_optimum():
    no_discounted = dataclasses.replace(TASK, optimal_discounted_return=None)
    with pytest.raises(ConfigError, match="discounted_regret: this task gives no discounted optimal return"):
        validate_ued_config(BASE, "plr", no_discounted)
    validate_ued_config(R(BASE, discounted_regret=False), "plr", no_discounted)


def test_an_environment_that_fails_is_reported_once_not_once_per_network():
    """A user's environment whose reset raises (or a level generator that gives no level): its
    own error, once, in one line; never a recursion through every network."""

    class Broken(type(TASK.env)):
        def reset_env_to_level(self, rng, level, params):
            raise ValueError("boom: no such level\nsecond line")

    broken = dataclasses.replace(TASK, env=Broken(64))
    with pytest.raises(ConfigError) as err:
        validate_ued_config(BASE, "plr", broken)
    text = str(err.value)
    assert "\n" not in text and text.count("boom") == 1 and "ValueError: boom: no such level" in text
    assert text.startswith("task: sampling a level and resetting the environment to it failed")
    # not an UnderspecifiedEnv at all (gymnax's CartPole with its params as the level)
    import gymnax

    env, params = gymnax.make("CartPole-v1")
    raw = UEDTask(env=env, params=params, sample_level=lambda rng: params, num_actions=2, max_episode_steps=10)
    with pytest.raises(ConfigError, match="^task.env: must be a jaxued UnderspecifiedEnv, got a CartPole$"):
        validate_ued_config(R(BASE, score="pvl"), "plr", raw)


@pytest.mark.slow  # compiles jaxued's maze into a training program: 11 s of a cold quick tier
def test_jaxued_maze_trains_through_our_interface():
    from jaxued.environments import Maze
    from jaxued.environments.maze import make_level_generator

    env = Maze(max_height=13, max_width=13, agent_view_size=5, normalize_obs=True)
    task = UEDTask(env=env, params=env.default_params, sample_level=make_level_generator(13, 13, 25),
                   num_actions=env.action_space(env.default_params).n, max_episode_steps=6)
    cfg = R(TINY, num_updates=4, num_envs=4, num_steps=6, eval_every=2, score="pvl", network="maze_lstm", hidden_size=0,
            remidi=R(TINY.remidi, steps_per_buffer=2, buffer_capacity=4),
            buffer=R(TINY.buffer, capacity=4, topk_k=2, min_fill=0.25))
    validate_ued_config(cfg, "remidi", task)
    result = driver.train_seeds(task, cfg, "remidi", [0], progress=False)
    hist, runner = result.history, result.runner
    assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(runner.learner.train_state.params))
    assert np.isfinite(hist["mean_return"]).all()


@pytest.mark.parametrize("algo", ["dr", "plr", "remidi", "accel", "remidi-accel"])
def test_one_update_rolls_out_once(algo, monkeypatch):
    """Replay or fresh levels, an update performs a single rollout (chosen levels first, then one
    rollout), and so traces the environment's step once for the agent's envs."""
    from remidi.engine import learner as lrn
    from remidi.engine import train as tr
    real_rollout = lrn.rollout
    calls = []

    def counting_rollout(*args, **kwargs):
        calls.append(1)
        return real_rollout(*args, **kwargs)

    monkeypatch.setattr(lrn, "rollout", counting_rollout)
    setup = tr.make_setup(TASK, TINY, algo)
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    jax.make_jaxpr(lambda r: tr.train_step(setup, r))(runner)
    assert len(calls) == 1


def test_degenerate_but_valid_runs_are_warned_about():
    from remidi.engine.run.validation import run_warnings
    from remidi.envs.maze import maze_task
    from remidi.experiments.maze import paper_config as maze_paper

    maze = maze_task("tmaze")
    # pvl scores a rollout in which no episode ends with the bootstrapped value: no warning
    assert run_warnings(R(maze_paper(), score="pvl", num_steps=32), "plr", maze) == []
    (warning,) = run_warnings(R(maze_paper(), score="learnability", num_steps=32), "plr", maze)
    assert "num_steps (32) is shorter than an episode can last (250)" in warning and "\n" not in warning
    assert run_warnings(R(maze_paper(), score="pvl"), "plr", maze) == []  # 256 steps ≥ 250
    # perfect regret (and minimax return) credit an unfinished episode with its partial return: warned too
    (warning,) = run_warnings(R(maze_paper(), num_steps=32), "plr", maze)
    assert warning.startswith("score perfect_regret uses the episodes that end inside a rollout, but num_steps (32)")
    assert "are scored by the reward collected so far" in warning and "\n" not in warning
    (warning,) = run_warnings(R(maze_paper(), num_steps=32), "minimax-return", maze)
    assert warning.startswith("score neg_return ")
    assert run_warnings(R(maze_paper()), "plr", maze) == []  # 256 steps ≥ 250
    assert run_warnings(R(maze_paper(), score="pvl", num_steps=32), "dr", maze) == []  # DR keeps no buffer

    class Noisy(type(TASK.env)):  # a reset that draws from its key, as gymnax's CartPole does
        def reset_env_to_level(self, rng, level, params):
            obs, state = super().reset_env_to_level(rng, level, params)
            return obs + jax.random.uniform(rng, obs.shape), state

    noisy = dataclasses.replace(TASK, env=Noisy(64), deterministic_reset=False)
    (warning,) = run_warnings(BASE, "remidi", noisy)
    assert warning.startswith("this task's reset depends on its random key"), warning  # printed after "remidi: warning: "
    assert run_warnings(BASE, "plr", noisy) == []  # only ReMiDi's tracker assumes determinism
    assert run_warnings(BASE, "remidi", dataclasses.replace(TASK, deterministic_reset=False)) == []


def test_ppo_diagnostics_are_logged_for_the_updates_that_train():
    """``ppo/<name>`` per update: defined where the update trained (PLR⊥: a replay; DR: always),
    NaN where it did not; a logged point is the mean over the block's training updates only."""
    from remidi.engine import train as tr
    from remidi.engine.learner import PPO_METRICS
    from remidi.engine.run import driver as drv

    for algo in ("plr", "dr"):
        setup = tr.make_setup(TASK, TINY, algo)
        runner = jax.vmap(lambda k: tr.init_runner(setup, k))(jax.random.split(jax.random.PRNGKey(0), 1))
        _, steps = jax.jit(lambda r: drv.run_steps(setup, r, 12))(runner)
        trained = np.asarray(steps["replay"][0]) > 0 if algo == "plr" else np.ones(12, bool)
        assert trained.any() and (algo == "dr" or not trained.all())  # both kinds of update occur for PLR⊥
        for name in PPO_METRICS:
            values = np.asarray(steps[f"ppo/{name}"][0])
            assert np.isfinite(values[trained]).all() and np.isnan(values[~trained]).all(), (algo, name)
        block = drv._block_metrics({k: np.asarray(v) for k, v in steps.items()}, TINY.num_envs)
        np.testing.assert_allclose(block["ppo/value_loss"], [np.asarray(steps["ppo/value_loss"][0])[trained].mean()],
                                   rtol=1e-6)
        assert (np.asarray(steps["ppo/value_loss"][0])[trained] > 0).all()  # a critic that is not exact has a loss


def test_an_algorithm_is_its_adversary_and_nonsense_is_refused_when_built():
    from remidi.engine.adversaries.accel import EditingBuffers
    from remidi.engine.adversaries.base import RandomLevels
    from remidi.engine.adversaries.plr import LevelBuffers
    from remidi.engine.algorithms import ALGORITHMS, Algorithm

    kinds = {name: (type(a.adversary).__name__, a.replays, a.buffer_sequence, a.edits, a.trains_on_fresh)
             for name, a in ALGORITHMS.items()}
    assert kinds == {"dr": ("RandomLevels", False, False, False, True),
                     "plr": ("LevelBuffers", True, False, False, False),
                     "minimax-return": ("LevelBuffers", True, False, False, False),
                     "remidi": ("LevelBuffers", True, True, False, False),
                     "accel": ("EditingBuffers", True, False, True, False),
                     "remidi-accel": ("EditingBuffers", True, True, True, False),
                     "paired": ("LevelGenerator", False, False, False, True),
                     "remidi-paired": ("GeneratorSequence", False, True, False, True),
                     "sfl": ("LearnabilityBuffers", False, False, False, True),
                     "remidi-sfl": ("LearnabilityBuffers", False, True, False, True)}
    with pytest.raises(ConfigError, match="would never train the agent"):
        RandomLevels(trains_on_fresh=False)
    from remidi.engine.adversaries.paired import GeneratorSequence, LevelGenerator

    with pytest.raises(ConfigError, match="^adversary: LevelGenerator without trains_on_fresh would never train the agent"):
        LevelGenerator(trains_on_fresh=False)
    with pytest.raises(ConfigError, match="^adversary: GeneratorSequence without trains_on_fresh would never train"):
        GeneratorSequence(trains_on_fresh=False)
    with pytest.raises(ConfigError, match="^adversary: GeneratorSequence is a sequence of generators"):
        GeneratorSequence(buffer_sequence=False)
    with pytest.raises(ConfigError, match="adversary must be a remidi.engine.adversaries.base adversary"):
        Algorithm("bad", "plr")
    # non-robust PLR (trains on fresh levels too) is a valid adversary
    assert Algorithm("plr-nonrobust", LevelBuffers(trains_on_fresh=True)).trains_on_fresh
    assert EditingBuffers(buffer_sequence=True) != EditingBuffers()


@pytest.mark.slow  # trains PAIRED (three agents) twice: 29 s of a cold quick tier
def test_paired_needs_a_level_builder_and_resumes_exactly(tmp_path):
    """PAIRED's generator and antagonist live in the Runner: a run interrupted and resumed ends
    where an uninterrupted one does; a task without a level-building MDP is refused in one line."""
    no_builder = dataclasses.replace(TASK, level_builder=None)
    from remidi.engine.adversaries.paired import LevelGenerator
    from remidi.engine.algorithms import ALGORITHMS

    allowed = ", ".join(name for name, a in ALGORITHMS.items() if not isinstance(a.adversary, LevelGenerator))
    with pytest.raises(ConfigError, match=r"^--algo: paired learns a level generator, but this task has no "
                                          rf"level-building MDP \(UEDTask.level_builder\); allowed: {allowed}$"):
        validate_ued_config(TINY, "paired", no_builder)
    with pytest.raises(ConfigError, match="^paired.estimator: perfect needs the task's optimal return"):
        validate_ued_config(R(TINY, score="neg_return", paired=R(TINY.paired, estimator="perfect")), "paired",
                            dataclasses.replace(TASK, optimal_return=None, optimal_discounted_return=None))
    cfg = R(TINY, num_updates=20)

    def crash(done, metrics):
        if done == 10:
            raise Crash

    # ReMiDi over PAIRED interrupted after update 10, past its switch at update 8: the frozen
    # reservoir, the second generator and the fresh ones to come come back from the checkpoint
    for algo in ("paired", "remidi-paired"):
        full = driver.train_seeds(TASK, cfg, algo, [0, 1], progress=False)
        with pytest.raises(Crash):
            driver.train_seeds(TASK, cfg, algo, [0, 1], out=tmp_path / algo, progress=False, on_block=crash)
        resumed = driver.train_seeds(TASK, cfg, algo, [0, 1], out=driver.RunFolder(tmp_path / algo, resume=True),
                                             progress=False)
        for name in full.history:
            np.testing.assert_array_equal(full.history[name], resumed.history[name], err_msg=f"{algo}: {name}")
        for a, b in zip(jax.tree.leaves(full.runner), jax.tree.leaves(resumed.runner)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        assert {"paired/regret", "paired/antagonist_return", "paired/generator_entropy",
                "generated/hidden"} <= set(full.history)
        assert full.runner.adversary.generator is not None and full.runner.adversary.antagonist is not None
    assert (np.asarray(full.runner.adversary.active) == 1).all()  # remidi-paired switched before the crash
