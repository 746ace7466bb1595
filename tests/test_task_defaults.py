"""An import-path task's run starts from defaults chosen from what the task provides
(experiments/custom.task_defaults): the score, the rollout length and how often to evaluate, said
in one line; and from budgets derived from the run's size (budgets.budget_defaults: one buffer
capacity for every algorithm, duplicates updating their entry, ReMiDi's switches spread over the
run, SFL sized to the task), one line per algorithm at the start; nothing trains here."""

import dataclasses
import importlib.util
import sys
from pathlib import Path

import pytest

from remidi.engine.config import UEDConfig
from remidi.experiments.base import resolve_config
from remidi.experiments.custom import task_defaults, task_experiment

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"


@pytest.fixture(scope="module")
def task():
    spec = importlib.util.spec_from_file_location("corridor_defaults_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module.make_task()  # optimal and discounted optimal returns, solved, episodes of 14 steps


@pytest.mark.parametrize("change, score, discounted", [
    ({}, "perfect_regret", True),
    ({"optimal_discounted_return": None}, "perfect_regret", False),  # an undiscounted optimum only
    ({"optimal_return": None, "optimal_discounted_return": None}, "learnability", True),  # solved, no optimum
    ({"optimal_return": None, "optimal_discounted_return": None, "solved": None}, "pvl", True),  # neither
])
def test_the_score_comes_from_what_the_task_provides(task, change, score, discounted):
    config, why = task_defaults(dataclasses.replace(task, **change))
    assert (config.score, config.discounted_regret) == (score, discounted)
    assert config.num_steps == task.max_episode_steps == 14  # an episode ends inside a rollout
    assert config.eval_every == UEDConfig().num_updates // 20 == 125
    assert ("discounted_regret" in why) == (not discounted) and set(why) >= {"score", "num_steps", "eval_every"}


def test_a_long_episode_is_rolled_out_256_steps_at_most(task):
    config, why = task_defaults(dataclasses.replace(task, max_episode_steps=1000))
    assert config.num_steps == 256 and "1000" in why["num_steps"]


def test_a_short_run_evaluates_every_ten_updates_and_the_defaults_are_said_in_one_line(task):
    exp = task_experiment("mine", lambda: task)
    notes = []
    cfg = resolve_config(exp, "default", {"num_updates": 30}, notes)
    assert cfg.eval_every == 10  # not 125 × 30 / 2500 → 1: three evaluations, not thirty
    assert notes[0] == ("defaults for this task: score perfect_regret (the task gives its optimal return); "
                        "num_steps 14 (the task's episode bound); eval_every 10 (20 evaluations per run, at least 10 "
                        "updates apart); --set KEY=VALUE chooses another")
    assert notes[1].startswith("num_updates 2500 → 30, so scaled eval_every 125 → 10, ")
    assert resolve_config(exp, "default", {"num_updates": 7}).eval_every == 7  # shorter than the floor: one block
    assert resolve_config(exp, "default", {"num_updates": 5000}).eval_every == 250  # still 20 evaluations
    notes = []
    resolve_config(exp, "default", {"score": "pvl", "num_steps": 8, "eval_every": 5}, notes)
    assert notes == []  # every default set by hand: nothing to say
    for algo in ("plr", "remidi"):
        exp.validate(resolve_config(exp, "default", {}), algo)
    # a configuration given in Python is used as it is
    given = task_experiment("given", lambda: task, UEDConfig(eval_every=50))
    assert given.config_factory() == UEDConfig(eval_every=50) and given.config_note is None


def test_the_exact_trackers_cost_is_said_with_the_option_that_lowers_it(task):
    """engine/trackers.tracker_cost_note: ReMiDi with a frozen adversary and at least 8 slots per env
    (or the reference tracker) is said, naming remidi.tracker_budget and tracker_overflow; PLR⊥, a
    single buffer, a learned tracker or few slots are not."""
    from types import SimpleNamespace

    from remidi.engine.algorithms import get_algorithm
    from remidi.engine.config import ReMiDiConfig
    from remidi.engine.trackers import tracker_cost_note

    def note(deterministic=True, **remidi):
        cfg = UEDConfig(remidi=ReMiDiConfig(**{"num_buffers": 2, "buffer_capacity": 512, **remidi}))
        return tracker_cost_note(dataclasses.replace(task, deterministic_reset=deterministic), cfg,
                                 get_algorithm("remidi"))  # a task whose observations the belief tracker reads

    line = note()
    assert line.startswith("ReMiDi's exact tracker steps up to 64 frozen levels (remidi.tracker_budget=64) beside "
                           "each rollout env once an adversary is frozen: a rollout steps this environment up to 65× ")
    assert "--set remidi.tracker_budget=8 makes it 9×" in line and "tracker_overflow" in line and "\n" not in line
    assert "up to 9×" in note(tracker_budget=8) and "remidi.buffer_capacity" in note(tracker_budget=8)
    assert note(tracker_budget=4) is None  # 5 environment steps per env step: not said
    assert note(buffer_capacity=4) is None  # 4 frozen levels: the candidate tracker follows 4 at most
    reference = note(tracker_budget=0)
    assert "every frozen level (512: the reference tracker)" in reference and "up to 513×" in reference
    assert "remidi.tracker=belief" in note(deterministic=False)  # no slots where the reset draws its start
    assert note(tracker="belief") is None and note(num_buffers=1) is None
    cfg = UEDConfig(remidi=ReMiDiConfig(num_buffers=2))
    assert tracker_cost_note(SimpleNamespace(deterministic_reset=True), cfg, get_algorithm("plr")) is None


def test_a_task_without_an_optimum_whose_episodes_outlast_the_rollout_is_scored_by_pvl(task):
    long = dataclasses.replace(task, optimal_return=None, optimal_discounted_return=None, max_episode_steps=1000)
    config, why = task_defaults(long)  # it defines solved, but no episode of 1,000 steps ends in 256
    assert config.score == "pvl" and config.num_steps == 256
    assert "1000 steps" in why["score"] and "bootstrapped value" in why["score"]
    config, _ = task_defaults(dataclasses.replace(task, max_episode_steps=1000))  # an optimum: perfect regret
    assert config.score == "perfect_regret"


@pytest.fixture(scope="module")
def exp(task):
    return task_experiment("mine", lambda: task)


def budgets(cfg):
    return (cfg.buffer.capacity, cfg.remidi.buffer_capacity, cfg.buffer.duplicate_check, cfg.remidi.steps_per_buffer,
            cfg.sfl.buffer_size, cfg.sfl.rollout_steps, cfg.sfl.batch_size, cfg.sfl.num_batches, cfg.sfl.refresh_every)


def test_the_budgets_are_derived_from_the_run_and_follow_num_updates(exp):
    """By hand, the example's task (episodes of 14 steps, num_steps 14): C = ⌈num_updates ×
    num_envs × (1 − 0.8) / 16⌉ clamped to [64, 4000]; switch every ⌈num_updates / 2⌉; SFL keeps C
    of 4·C candidates played 4 × 14 = 56 steps, in batches of ⌈8 × num_envs × 14 / 56⌉."""
    cfg = resolve_config(exp, "default", {})  # 2,500 × 32 × 0.2 = 16,000 fresh levels: C = 1,000
    assert budgets(cfg) == (1000, 1000, True, 1250, 1000, 56, 64, 63, 125)  # 63 batches: 4,032 ≥ 4,000 candidates
    cfg = resolve_config(exp, "default", {"num_updates": 200})  # 1,280 fresh levels: C = 80
    assert budgets(cfg) == (80, 80, True, 100, 80, 56, 64, 5, 10)
    cfg = resolve_config(exp, "default", {"num_updates": "30", "num_envs": "8"})  # 48 fresh levels: C = 64
    assert budgets(cfg) == (64, 64, True, 15, 64, 56, 16, 16, 10)
    assert resolve_config(exp, "default", {"num_updates": 10**6}).buffer.capacity == 4000  # 400,000 → 4,000
    cfg = resolve_config(exp, "default", {"buffer.replay_prob": 0.5})  # 40,000 fresh levels: C = 2,500
    assert cfg.buffer.capacity == cfg.remidi.buffer_capacity == 2500
    cfg = resolve_config(exp, "default", {"remidi.num_buffers": 3})
    assert cfg.remidi.steps_per_buffer == 834  # ⌈2,500 / 3⌉: the last buffer gets updates too
    for algo in ("plr", "minimax-return", "remidi", "sfl", "remidi-sfl"):
        exp.validate(resolve_config(exp, "default", {"num_updates": 30, "num_envs": 8}), algo)


def test_a_key_the_user_sets_is_kept_and_the_others_follow_it(task, exp):
    cfg = resolve_config(exp, "default", {"buffer.capacity": "500", "remidi.steps_per_buffer": 700,
                                          "buffer.duplicate_check": "false", "sfl.rollout_steps": 28})
    assert (cfg.buffer.capacity, cfg.remidi.steps_per_buffer, cfg.buffer.duplicate_check) == (500, 700, False)
    assert cfg.remidi.buffer_capacity == cfg.sfl.buffer_size == 500  # one capacity: the one the user chose
    assert (cfg.sfl.rollout_steps, cfg.sfl.batch_size, cfg.sfl.num_batches) == (28, 128, 16)  # 8·32·14/28; 2,000/128
    cfg = resolve_config(exp, "default", {"remidi.buffer_capacity": 50, "num_updates": 100})
    assert (cfg.buffer.capacity, cfg.remidi.buffer_capacity, cfg.remidi.steps_per_buffer) == (50, 50, 50)
    given = task_experiment("given", lambda: task, UEDConfig(num_updates=40))  # a whole config: nothing derived,
    assert budgets(resolve_config(given, "default", {"num_updates": 20}))[:4] == (4000, 32, False, 500)  # scaled


def test_the_run_says_each_algorithms_budget_in_one_line(task, exp, monkeypatch, tmp_path):
    from remidi import run_ued
    from remidi.experiments import running

    seen = {}
    monkeypatch.setattr(running, "_write_and_train", lambda spec, config, out, notes, progress: seen.update(
        notes=notes, config=config) or {algo: {} for algo in spec.algos})
    run_ued(task, {"num_updates": 200}, ["dr", "plr", "remidi", "sfl", "remidi-sfl"], 1, tmp_path / "o",
            progress=False)
    lines = [line for line in seen["notes"] if line.split(":")[0] in ("dr", "plr", "remidi", "sfl", "remidi-sfl")]
    assert lines == [
        "dr: no buffer, 32 fresh levels every update",
        "plr: 1 buffer of 80 levels (duplicates update their entry), replay 0.8, score perfect_regret",
        "remidi: 2 buffers of 80 (duplicates update their entry), switch every 100 updates, replay 0.8, "
        "score perfect_regret",
        "sfl: 1 buffer of 80 levels, the most learnable of 320 candidates (5 batches of 64, 56 steps each) every "
        "10 updates; 0.5 of each update's levels from it",
        "remidi-sfl: 2 buffers of 80, switch every 100 updates, the most learnable of 320 candidates (5 batches of "
        "64, 56 steps each) every 10 updates; 0.5 of each update's levels from it",
    ]
    assert seen["notes"].index(lines[0]) > 0  # after the defaults note, before any warning
    assert exp.budget_line(seen["config"], "accel") == (  # a task with a level mutator: ACCEL's edits too
        "accel: 1 buffer of 80 levels (duplicates update their entry), replay 0.8, 5 edits per edited level, "
        "score perfect_regret")
    assert seen["notes"][0].startswith("defaults for this task: ")
