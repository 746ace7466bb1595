"""A user's UEDTask: checked before anything is written (one line naming the field), the
short-rollout warning for every score that reads finished episodes, and runs of a user's task that
the command line resumes and evaluates from any folder (the task rebuilt from its recorded import
path), or, where they cannot, a one-line message saying what to pass."""

import dataclasses
import json
import shutil
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.cli import main
from remidi.engine.config import BufferConfig
from remidi.engine.config import ReMiDiConfig, UEDConfig
from remidi.engine.core.ppo import PPOConfig
from remidi.errors import ConfigError

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"
MODULE = "corridor_task_i30"  # the example copied under a name no other test imports

# two updates of PLR⊥ on 4 envs: compiles in seconds
TINY = UEDConfig(num_updates=2, num_envs=4, num_steps=16, network="mlp", eval_every=1, eval_attempts=1,
                 checkpoint_every=1, ppo=PPOConfig(epochs=1, minibatches=1),
                 buffer=BufferConfig(capacity=8, min_fill=0.25), remidi=ReMiDiConfig(num_buffers=1))
TINY_SETS = ["--set", "num_updates=2", "--set", "eval_every=1", "--set", "checkpoint_every=1", "--set", "num_envs=4",
             "--set", "num_steps=16", "--set", "eval_attempts=1", "--set", "ppo.epochs=1", "--set", "network=mlp"]
EVAL_TINY = ["--attempts", "1", "--cvar-levels", "4", "--cvar-attempts", "1"]


def write_module(folder: Path, name: str = MODULE, extra: str = "") -> Path:
    """The example as module ``name`` in ``folder`` (plus ``extra`` source at its end)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.py").write_text(EXAMPLE.read_text() + extra)
    return folder


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    """The example's module, imported from a folder of its own."""
    folder = write_module(tmp_path_factory.mktemp("project"))
    sys.path.insert(0, str(folder))
    try:
        module = __import__(MODULE)
    finally:
        sys.path.remove(str(folder))
    return module


# ------------------------------------------------------------------------------ A: the task is checked
class _WideReward:  # mixed into the example's environment by broken()
    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = super().step_env(rng, state, action, params)
        return obs, state, jnp.stack([reward, reward]), done, info


class _IntDone:
    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = super().step_env(rng, state, action, params)
        return obs, state, reward, done.astype(jnp.int32), info


class _Slip:  # each step a coin from the step's key replaces the observation: randomness outside the level
    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = super().step_env(rng, state, action, params)
        return jax.tree.map(lambda x: jnp.where(jax.random.bernoulli(rng), x, x * 0), obs), state, reward, done, info


class _NoisyReward:  # randomness in the reward alone: the tracker compares observations and ends, not rewards
    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = super().step_env(rng, state, action, params)
        return obs, state, reward + 0.01 * jax.random.normal(rng), done, info


class _BrokenStep:  # a step that fails on the sampled level (e.g. one of the wrong shape)
    def step_env(self, rng, state, action, params):
        raise ValueError("cannot concatenate")


class _RandomStart:  # a start drawn from the reset's key, claimed deterministic by the example's task
    def reset_env_to_level(self, rng, level, params):
        obs, state = super().reset_env_to_level(rng, level, params)
        return jax.tree.map(lambda x: jnp.where(jax.random.bernoulli(rng), x, x * 0), obs), state


def broken(corridor, kind: str):
    task = corridor.make_task()
    env_class = type(task.env)
    if kind == "num_actions":
        return dataclasses.replace(task, num_actions=0)
    if kind == "max_episode_steps":
        return dataclasses.replace(task, max_episode_steps=0)
    if kind == "reward":
        return dataclasses.replace(task, env=type("Wide", (_WideReward, env_class), {})())
    if kind == "done":
        return dataclasses.replace(task, env=type("IntDone", (_IntDone, env_class), {})())
    if kind == "step":
        return dataclasses.replace(task, env=type("BrokenStep", (_BrokenStep, env_class), {})())
    if kind == "deterministic_reset":
        return dataclasses.replace(task, env=type("RandomStart", (_RandomStart, env_class), {})())
    if kind == "num_actions_space":  # more actions than the environment's Discrete(2)
        return dataclasses.replace(task, num_actions=5)
    if kind == "eval_sets":  # one level where a batch belongs
        return dataclasses.replace(task, eval_sets={"one": corridor.sample_level(jax.random.PRNGKey(0))})
    if kind == "eval_sets_numbers":  # one level of Python numbers, no arrays
        level = corridor.sample_level(jax.random.PRNGKey(0))
        return dataclasses.replace(task, eval_sets={"one": jax.tree.map(lambda x: x.item(), level)})
    if kind == "eval_sets_numpy":  # a batch built with NumPy: int64 where the level holds int32
        level = corridor.sample_level(jax.random.PRNGKey(0))
        return dataclasses.replace(task, eval_sets={"np": jax.tree.map(
            lambda x: np.asarray(x)[None].astype(np.int64 if x.dtype == jnp.int32 else x.dtype), level)})
    if kind == "reseed_level":  # a batch of two where one level belongs
        return dataclasses.replace(task, reseed_level=lambda rng, level: jax.tree.map(lambda x: jnp.stack([x, x]), level))
    if kind == "level_builder":  # builds another task's levels (the lever game's)
        from remidi.envs.lever import LeverBuilder

        return dataclasses.replace(task, level_builder=LeverBuilder(8))
    if kind == "level_builder_size":  # a builder of no design steps
        from remidi.envs.lever import LeverBuilder

        empty = LeverBuilder(8)
        empty.num_steps = 0
        return dataclasses.replace(task, level_builder=empty)
    raise AssertionError(kind)


@pytest.mark.parametrize("kind, message", [
    ("num_actions", "task.num_actions: must be an integer ≥ 1, got 0"),
    ("max_episode_steps", "task.max_episode_steps: must be an integer ≥ 1, got 0"),
    ("reward", "task.env: a step's reward must be a float scalar (f32[]) per environment, got float32[2]"),
    ("done", "task.env: a step's done must be a boolean scalar (bool[]) per environment, got int32[]"),
    ("num_actions_space", "task.num_actions: must be the environment's 2 actions (its action_space), got 5"),
    ("step", "task.env: a step of the environment failed: ValueError: cannot concatenate (from a level of "
             "sample_level: bool[], bool[], int32[])"),
    ("deterministic_reset", "task.deterministic_reset: true promises that env.reset_to_level ignores its key, but "
                            "what it returns depends on the key (traced)"),
    ("eval_sets", "task.eval_sets: 'one' must be a batch of levels"),
    ("eval_sets_numbers", "task.eval_sets: 'one' must be a batch of levels"),
    ("eval_sets_numpy", "task.eval_sets: the levels of 'np' must have the sampled level's dtypes and shapes; they "
                        "differ in .decor (int32[] sampled, int64[] here)"),
    ("reseed_level", "task.reseed_level: must return a level with the sampled level's shapes"),
    ("level_builder", "task.level_builder: must build a level with the sampled level's shapes"),
    ("level_builder_size", "task.level_builder.num_steps: must be an integer ≥ 1, got 0"),
])
def test_a_broken_task_is_one_line_naming_its_field_and_nothing_is_written(corridor, tmp_path, kind, message):
    from remidi import run_ued

    out = tmp_path / "out"
    with pytest.raises(ConfigError) as err:
        run_ued(broken(corridor, kind), TINY, ["plr"], [0], out, progress=False)
    assert str(err.value).startswith(message) and "\n" not in str(err.value), str(err.value)
    assert not out.exists()


def test_the_command_line_reports_a_broken_task_in_one_line(tmp_path, monkeypatch, capsys):
    folder = write_module(tmp_path / "proj", "broken_task_i30", extra=(
        "\n\ndef make_broken():\n    import dataclasses\n    return dataclasses.replace(make_task(), num_actions=0)\n"))
    monkeypatch.chdir(folder)  # imported from the current folder, as `python -m` would
    assert main(["run", "broken_task_i30:make_broken", "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == "remidi: error: task.num_actions: must be an integer ≥ 1, got 0\n"
    assert not (tmp_path / "out").exists()


def test_every_score_that_reads_finished_episodes_warns_of_a_short_rollout(corridor):
    """perfect_regret scores an unfinished episode by its partial return, learnability by -inf: both
    are warned of when num_steps is shorter than an episode can last (the registry says which); pvl
    and maxmc score a truncated rollout by the critic's bootstrap, so they are not."""
    from remidi.engine.adversaries.scores import SCORES
    from remidi.engine.run.validation import run_warnings

    task = corridor.make_task()  # episodes of at most 14 steps
    short = dataclasses.replace(TINY, num_steps=4)
    (warning,) = run_warnings(short, "plr", task)
    assert warning.startswith("score perfect_regret uses the episodes that end inside a rollout, but num_steps (4) "
                              "is shorter than an episode can last (14): levels whose episode does not end are "
                              "scored by the reward collected so far"), warning
    (warning,) = run_warnings(dataclasses.replace(short, score="learnability"), "plr", task)
    assert "score -inf and are never inserted" in warning and warning.endswith(", or --set score=pvl"), warning
    assert run_warnings(dataclasses.replace(short, score="pvl"), "plr", task) == []
    assert run_warnings(dataclasses.replace(TINY, num_steps=14), "plr", task) == []
    for name, score in SCORES.items():  # the registry's needs_finished_episodes says which scores are warned of
        assert bool(run_warnings(dataclasses.replace(short, score=name), "plr", task)) == score.needs_finished_episodes
    assert not SCORES["maxmc"].needs_finished_episodes


def test_the_short_rollout_warning_is_said_once_per_run_for_all_its_algorithms(corridor, tmp_path, capsys, monkeypatch):
    """A run of three algorithms on rollouts shorter than an episode: one warning line, before the
    first algorithm trains, naming each score with the algorithms it ranks levels for and the
    setting that scores every level by a finished episode, in run_ued's words for the UEDConfig it
    was given (it was one line per algorithm, and said --set)."""
    from remidi import run_ued
    from remidi.experiments import ued

    class Trained(Exception):
        pass

    def first_training(*args, **kwargs):
        raise Trained  # the first algorithm's training: what was said before it is all there is

    monkeypatch.setattr(ued, "train_seeds", first_training)
    short = dataclasses.replace(TINY, num_steps=4, num_updates=16, remidi=dataclasses.replace(
        TINY.remidi, num_buffers=2, steps_per_buffer=4))
    with pytest.raises(Trained):
        run_ued(corridor.make_task(), short, ["dr", "plr", "minimax-return", "remidi"], [0], tmp_path / "out",
                progress=False)
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("remidi: warning:")]
    assert warnings == [
        "remidi: warning: scores perfect_regret (plr, remidi) and neg_return (minimax-return) use the episodes that "
        "end inside a rollout, but num_steps (4) is shorter than an episode can last (14): with perfect_regret, "
        "levels whose episode does not end are scored by the reward collected so far as if the episode had ended "
        "(a goal not yet reached looks like a failure); with neg_return, levels whose episode does not end are "
        "scored by the reward collected so far as if the episode had ended; config.num_steps=14 (or more) scores "
        "every level by a finished episode, or config.score=pvl"], warnings


def test_the_short_rollout_warning_names_the_preset_that_chose_num_steps():
    """tmaze's smoke preset keeps rollouts short (64 steps of a 250-step episode) on purpose: the
    warning says it is that preset's choice; with the user's own num_steps it does not."""
    from remidi.experiments import get_experiment
    from remidi.experiments.base import RunSpec, resolve_config

    exp = get_experiment("tmaze")
    algos = ["dr", "plr", "minimax-return", "remidi"]
    (warning,) = exp.run_warnings(RunSpec(exp, algos, "smoke", [0, 1]), resolve_config(exp, "smoke", {}))
    assert warning.startswith("scores perfect_regret (plr, remidi) and neg_return (minimax-return) use the episodes "
                              "that end inside a rollout, but num_steps (64, the smoke preset's choice for a short "
                              "run) is shorter than an episode can last (250)"), warning
    assert warning.endswith("; --set num_steps=250 (or more) scores every level by a finished episode, or "
                            "--set score=pvl"), warning
    own = {"num_steps": 100}
    (warning,) = exp.run_warnings(RunSpec(exp, algos, "smoke", [0, 1], own), resolve_config(exp, "smoke", own))
    assert "num_steps (100) is shorter" in warning and "preset" not in warning
    assert exp.run_warnings(RunSpec(exp, algos, "cpu", [0, 1]), resolve_config(exp, "cpu", {})) == []


def test_list_offers_only_the_scores_the_task_can_use(tmp_path, capsys, monkeypatch):
    """remidi list names the level scores whose needs the task meets: an import-path task without
    an optimal return gets no perfect_regret, one without a solve criterion no learnability; so do
    gymnax's cartpole (no optimum) and Brax (no solve criterion), without building their tasks."""
    from remidi.engine.adversaries.scores import SCORES

    extra = ("\n\ndef make_plain():\n    import dataclasses\n"
             "    return dataclasses.replace(make_task(), optimal_return=None, optimal_discounted_return=None)\n"
             "\n\ndef make_unsolved():\n    import dataclasses\n"
             "    return dataclasses.replace(make_task(), solved=None)\n")
    monkeypatch.chdir(write_module(tmp_path / "proj", "scoreless_task_i30", extra=extra))

    def scores(name):
        assert main(["list", name]) == 0
        (line,) = [line for line in capsys.readouterr().out.splitlines() if line.startswith("  scores:")]
        return line.split(":", 1)[1].split(" (")[0].strip().split(", ")

    def fitting(optimum: bool, solved: bool) -> list[str]:  # the registry's scores whose needs a task meets
        return [name for name, s in SCORES.items()
                if (optimum or not s.needs_optimum) and (solved or not s.needs_solved)]

    assert "perfect_regret" not in fitting(False, True) and "learnability" not in fitting(True, False)
    assert scores("scoreless_task_i30:make_task") == fitting(True, True) == list(SCORES)
    assert scores("scoreless_task_i30:make_plain") == fitting(False, True)
    assert scores("scoreless_task_i30:make_unsolved") == fitting(True, False)
    assert scores("cartpole") == fitting(False, True)
    assert scores("brax-hopper") == fitting(True, False)


@pytest.mark.parametrize("name", ["lever", "lever-noisy", "tmaze", "blindfold-noisy", "cartpole", "acrobot", "pendulum",
                                  pytest.param("brax-hopper", marks=pytest.mark.slow)])
def test_the_scores_an_experiment_declares_are_those_its_tasks_can_use(name):
    """A built-in experiment says which scores its task can use without building it (remidi list,
    UEDSpec.task_gives): the same as the task of every preset, built, allows."""
    from remidi.engine.adversaries.scores import task_scores
    from remidi.experiments import get_experiment
    from remidi.experiments.base import resolve_config

    exp = get_experiment(name)
    for preset in exp.presets:
        cfg = resolve_config(exp, preset, {})
        assert exp.scores(cfg) == task_scores(exp.make_task(cfg)), (name, preset)


def test_remidi_with_the_exact_tracker_warns_of_a_step_that_draws_from_its_key(corridor):
    """ReMiDi's exact tracker steps frozen levels with the agent's draws: a step with randomness of
    its own is warned of (not for PLR⊥, nor with a belief tracker, nor for the example's step)."""
    from remidi.engine.run.validation import run_warnings

    task = corridor.make_task()
    slipping = dataclasses.replace(task, env=type("Slip", (_Slip, type(task.env)), {})())
    full = dataclasses.replace(TINY, num_steps=14, remidi=dataclasses.replace(TINY.remidi, num_buffers=2))
    (warning,) = run_warnings(full, "remidi", slipping, check_step=True)
    assert warning.startswith("this task's env.step_env draws from its random key, but ReMiDi's exact "
                              "tracker steps each frozen level with the agent's own draws"), warning
    assert run_warnings(full, "remidi", task, check_step=True) == []
    assert run_warnings(full, "plr", slipping, check_step=True) == []
    belief = dataclasses.replace(full, remidi=dataclasses.replace(full.remidi, tracker="belief"))
    assert run_warnings(belief, "remidi", slipping, check_step=True) == []
    assert run_warnings(full, "remidi", slipping) == []  # the library's own experiments skip the trace
    noisy_reward = dataclasses.replace(task, env=type("NoisyReward", (_NoisyReward, type(task.env)), {})())
    assert run_warnings(full, "remidi", noisy_reward, check_step=True) == []


# ------------------------------------------------------------------------------ B: rebuilt from anywhere
def test_remidi_run_imports_the_task_from_the_current_folder_and_records_it(tmp_path, monkeypatch):
    from remidi.experiments import saved_experiment
    from remidi.experiments.custom import task_source

    folder = write_module(tmp_path / "proj", "cwd_task_i30")
    monkeypatch.chdir(folder)
    assert task_source("cwd_task_i30:make_task") == {"import": "cwd_task_i30:make_task", "folder": str(folder.resolve())}
    exp = saved_experiment("cwd_task_i30:make_task")  # what `remidi run cwd_task_i30:make_task` looks up
    assert exp.task_ref == {"import": "cwd_task_i30:make_task", "folder": str(folder.resolve())}
    assert str(folder.resolve()) not in sys.path  # only for the import
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=r"^experiment: cannot import other_task_i30 \(ModuleNotFoundError: .*\); "
                                          r"looked in .* and the installed packages$"):
        saved_experiment("other_task_i30:make_task")


@pytest.fixture(scope="module")
def ued_run(corridor, tmp_path_factory):
    """A run written by run_ued with task_ref, in the folder holding the task's module."""
    from remidi import run_ued

    out = tmp_path_factory.mktemp("ued") / "run"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(Path(corridor.__file__).parent)
        run_ued(corridor.make_task(), TINY, ["plr"], [0], out, progress=False, name="corridor",
                task_ref=f"{MODULE}:make_task")
    return out


@pytest.mark.slow  # trains, evaluates and resumes a run: 13 s of a cold quick tier
def test_a_run_ued_run_is_evaluated_and_resumed_from_another_folder(corridor, ued_run, tmp_path, monkeypatch,
                                                                     capsys):
    saved = json.loads((ued_run / "config.json").read_text())
    assert saved["experiment"] == "corridor"
    assert saved["task"] == {"import": f"{MODULE}:make_task", "folder": str(Path(corridor.__file__).parent.resolve())}
    run = tmp_path / "run"
    shutil.copytree(ued_run, run)
    monkeypatch.chdir(tmp_path)  # neither the module's folder nor on sys.path
    monkeypatch.delitem(sys.modules, MODULE)  # imported again, from the recorded folder
    assert main(["evaluate", str(run), *EVAL_TINY]) == 0, capsys.readouterr().err
    doc = json.loads((run / "evaluate.json").read_text())
    assert set(doc["algorithms"]["plr"]["metrics"]) >= {"solve_rate/hidden", "solve_rate/visible", "cvar/return/100%"}
    assert main(["run", "--resume", str(run), "--quiet"]) == 0, capsys.readouterr().err
    assert json.loads((run / "summary.json").read_text())["experiment"] == "corridor"


def test_a_run_without_an_import_path_says_what_to_pass_and_evaluates_with_the_task(corridor, ued_run, tmp_path,
                                                                                    capsys):
    from remidi.runs.evaluate import EvalSettings, evaluate_run

    run = tmp_path / "run"
    shutil.copytree(ued_run, run)
    saved = json.loads((run / "config.json").read_text())
    del saved["task"]  # as run_ued writes it without task_ref
    (run / "config.json").write_text(json.dumps(saved))
    for argv in (["evaluate", str(run)], ["run", "--resume", str(run)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "'corridor' is a task given to run_ued without task_ref" in err, err
        assert "evaluate_run(RUN_DIR, task=...)" in err and "run_ued(..., task_ref='module:function')" in err
    assert not (run / "evaluate.json").exists()
    doc = evaluate_run(run, EvalSettings(attempts=1, cvar_levels=4, cvar_attempts=1), task=corridor.make_task())
    assert doc["algorithms"]["plr"]["seeds"] == [0] and (run / "evaluate.json").exists()


def test_run_ued_refuses_a_task_ref_that_does_not_import_before_writing(corridor, tmp_path):
    from remidi import run_ued

    with pytest.raises(ConfigError, match=f"^experiment: {MODULE} has no make_nothing$"):
        run_ued(corridor.make_task(), TINY, ["plr"], [0], tmp_path / "out", progress=False,
                task_ref=f"{MODULE}:make_nothing")
    assert not (tmp_path / "out").exists()


def test_the_discounted_utility_error_names_the_score_in_use(corridor, monkeypatch):
    """A score of a plugin that needs the optimum, on a task without a discounted one: the error
    names that score (it named perfect_regret whatever the score)."""
    from remidi.engine.adversaries import scores as sc
    from remidi.engine.run.validation import validate_ued_config

    monkeypatch.setitem(sc.SCORES, "gap", dataclasses.replace(sc.SCORES["perfect_regret"], name="gap"))
    task = dataclasses.replace(corridor.make_task(), optimal_discounted_return=None)
    with pytest.raises(ConfigError, match="so gap cannot use the discounted utility"):
        validate_ued_config(dataclasses.replace(TINY, score="gap", discounted_regret=True), "plr", task)


def test_all_algorithms_of_a_users_task_are_those_it_can_run(corridor):
    """`--algo all` on a user's task without a level mutator or builder trains what it can run;
    naming another says why, and every refusal lists the same algorithms (each listed the
    algorithms the other refused)."""
    from remidi.engine.run.validation import validate_ued_config
    from remidi.experiments.base import parse_algos
    from remidi.experiments.custom import task_experiment

    from remidi.engine.adversaries.paired import LevelGenerator
    from remidi.engine.algorithms import ALGORITHMS

    task = corridor.make_task()
    exp = task_experiment("corridor", lambda: task)
    # the registry's algorithms that neither edit levels nor learn a level generator
    runnable = [name for name, a in ALGORITHMS.items() if not (a.edits or isinstance(a.adversary, LevelGenerator))]
    assert "plr" in runnable and "accel" not in runnable and "paired" not in runnable
    assert parse_algos(exp, "all") == runnable
    with pytest.raises(ConfigError, match=r"^--algo: accel cannot run on corridor: accel edits levels, but this task "
                                          rf"has no level mutator .*; allowed: {', '.join(runnable)}, all$"):
        parse_algos(exp, "accel")
    for algo in ("accel", "paired"):
        with pytest.raises(ConfigError, match=rf"; allowed: {', '.join(runnable)}$"):
            validate_ued_config(TINY, algo, task)


def test_the_floor_of_uniform_actions_plays_a_discrete_tasks_evaluation_sets(corridor):
    """tools.results.floors on a discrete task: uniform random actions, one return per level
    and attempt (the corridor's returns lie in [-1, 1]); the continuous floors are refused."""
    from tools.results.floors import floor_returns

    task = corridor.make_task()
    name = sorted(task.eval_sets)[0]
    levels = jax.tree.leaves(task.eval_sets[name])[0].shape[0]
    returns = np.asarray(floor_returns(task, name, "uniform", 8))
    assert returns.shape == (levels, 8) and np.all(np.abs(returns) <= 1.0) and len(np.unique(returns)) > 1
    with pytest.raises(ValueError, match="allowed: uniform$"):
        floor_returns(task, name, "zero", 1)
