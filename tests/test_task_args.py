"""``make_task`` with keyword arguments (``remidi run mypkg.tasks:make_task --task-arg size=9``,
``run_ued(..., task_ref=..., task_args={...})``): each value read as a JSON scalar, else a string;
checked against the function's parameters (a wrong one is one line naming it and what the function
accepts, before anything is written); recorded in config.json beside the import path and used
again by ``--resume``, ``remidi evaluate`` and ``remidi render`` (:func:`saved_run`); a
config.json without ``args`` (written before them) still works. Nothing trains here."""

import json
import sys
from pathlib import Path

import pytest

from remidi.cli import main
from remidi.errors import ConfigError
from remidi.experiments import running, saved_experiment
from remidi.experiments.base import RunSpec, resolve_config
from remidi.experiments.custom import import_experiment, parse_task_args, task_source
from remidi.experiments.resuming import saved_run

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"
MODULE = "corridor_task_args"  # the example under a name no other test imports
FUNCTIONS = '''

def make_sized(max_steps=14, hidden=True):
    """The corridor with another episode bound (``max_steps``: the default num_steps follows it)."""
    import dataclasses

    if not isinstance(max_steps, int):
        raise TypeError(f"max_steps must be an integer, got {max_steps!r}")
    return dataclasses.replace(make_task(), max_episode_steps=max_steps)


def make_required(size, hidden=True):
    return make_sized(size)


def make_any(**options):
    return make_sized(**options)
'''


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    where = tmp_path_factory.mktemp("project")
    (where / f"{MODULE}.py").write_text(EXAMPLE.read_text() + FUNCTIONS)
    return where


@pytest.fixture
def here(folder, monkeypatch):
    monkeypatch.chdir(folder)
    return folder


def test_values_are_json_scalars_else_strings():
    assert parse_task_args(["size=9", "dark=true", "name=big", "ratio=0.5", "none=null", 'quoted="9"', "size=11",
                            "pair=[1, 2]", "big=1e999"]) == {
        "size": 11, "dark": True, "name": "big", "ratio": 0.5, "none": None, "quoted": "9", "pair": "[1, 2]",
        "big": "1e999"}  # the last of a name given twice; a list or an infinity: the string given
    for bad in ("size", "=9", "two words=1"):
        with pytest.raises(ConfigError, match=r"^--task-arg: expected NAME=VALUE .*, got "):
            parse_task_args([bad])


def test_the_arguments_build_the_task_and_are_recorded_beside_the_import_path(here):
    exp = import_experiment(f"{MODULE}:make_sized", args={"max_steps": 20})
    assert exp.task_ref == {"import": f"{MODULE}:make_sized", "folder": str(here.resolve()), "args": {"max_steps": 20}}
    assert resolve_config(exp, "default", {}).num_steps == 20  # the task's bound: the arguments were used
    assert import_experiment(f"{MODULE}:make_sized").task_ref == {"import": f"{MODULE}:make_sized",
                                                                 "folder": str(here.resolve())}  # none: no "args"
    assert import_experiment(f"{MODULE}:make_any", args={"max_steps": 12}).make_task(None).max_episode_steps == 12


@pytest.mark.parametrize("path, args, message", [
    ("make_sized", {"size": 9}, "--task-arg: size is no parameter of {m}:make_sized; it accepts: max_steps, hidden"),
    ("make_sized", {"max_steps": "long"}, "--task-arg: {m}:make_sized refused max_steps='long' (TypeError: max_steps "
                                          "must be an integer, got 'long'); it accepts: max_steps, hidden"),
    ("make_required", {"hidden": False}, "--task-arg: {m}:make_required cannot be called with hidden=False (missing "
                                         "a required argument: 'size'); it accepts: size, hidden"),
    ("make_task", {"size": 9}, "--task-arg: size is no parameter of {m}:make_task; it accepts: none"),
])
def test_a_wrong_argument_is_one_line_naming_it_and_the_accepted_parameters(here, path, args, message):
    with pytest.raises(ConfigError) as err:
        import_experiment(f"{MODULE}:{path}", args=args)
    assert str(err.value) == message.format(m=MODULE)


def test_the_command_line_refuses_a_wrong_argument_before_writing_anything(here, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", f"{MODULE}:make_sized", "--task-arg", "size=9", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == f"remidi: error: --task-arg: size is no parameter of {MODULE}:make_sized; it accepts: max_steps, " \
                  f"hidden\n" and not out.exists()
    assert main(["run", "lever", "--task-arg", "size=9", "--out", str(out)]) == 2
    assert "--task-arg: gives keyword arguments to a task's function" in capsys.readouterr().err and not out.exists()
    assert main(["run", "--resume", str(out), "--task-arg", "size=9"]) == 2
    assert "--resume: takes only the run folder" in capsys.readouterr().err


def test_run_ued_records_task_args_and_refuses_them_without_task_ref(here, tmp_path, monkeypatch):
    from remidi import run_ued

    task = import_experiment(f"{MODULE}:make_sized", args={"max_steps": 20}).make_task(None)
    with pytest.raises(ConfigError, match=r"^task_args: records how task_ref's function built the task, so it needs "
                                          r"task_ref"):
        run_ued(task, {}, ["plr"], 1, tmp_path / "a", task_args={"max_steps": 20})
    with pytest.raises(ConfigError, match=rf"^task_args: size is no parameter of {MODULE}:make_sized; it accepts: "):
        run_ued(task, {}, ["plr"], 1, tmp_path / "a", task_ref=f"{MODULE}:make_sized", task_args={"size": 9})
    with pytest.raises(ConfigError, match=r"^task_args: max_steps must be a JSON scalar .*, got \[20\]$"):
        run_ued(task, {}, ["plr"], 1, tmp_path / "a", task_ref=f"{MODULE}:make_sized", task_args={"max_steps": [20]})
    assert not (tmp_path / "a").exists()
    seen = {}
    monkeypatch.setattr(running, "_write_and_train", lambda spec, *rest: seen.update(spec=spec) or {"plr": {}})
    run_ued(task, {}, ["plr"], 1, tmp_path / "a", task_ref=f"{MODULE}:make_sized", task_args={"max_steps": 20})
    assert seen["spec"].exp.task_ref["args"] == {"max_steps": 20}


def test_resume_evaluate_and_render_rebuild_the_task_with_its_arguments_from_any_folder(here, tmp_path, monkeypatch):
    """saved_run (what --resume, remidi evaluate and remidi render read a run folder with) rebuilds
    the task from config.json's record, its arguments included; a record without "args" (written
    before them) rebuilds the function called without."""
    exp = import_experiment(f"{MODULE}:make_sized", args={"max_steps": 20})
    config = resolve_config(exp, "default", {"num_updates": 20})
    run = tmp_path / "run"
    run.mkdir()
    running.write_run_config(run, RunSpec(exp, ["plr"], "default", [0]), "plr", config)
    saved = json.loads((run / "config.json").read_text())
    assert saved["task"] == {"import": f"{MODULE}:make_sized", "folder": str(here.resolve()),
                             "args": {"max_steps": 20}}
    monkeypatch.chdir(tmp_path)  # neither the module's folder nor on sys.path
    monkeypatch.delitem(sys.modules, MODULE)
    again, algo, _, seeds, cfg = saved_run(saved_experiment, run)
    assert (algo, seeds, cfg) == ("plr", [0], config) and again.make_task(cfg).max_episode_steps == 20
    del saved["task"]["args"]  # as written before task arguments were recorded
    (run / "config.json").write_text(json.dumps(saved))
    again, *_, cfg = saved_run(saved_experiment, run)
    assert again.make_task(cfg).max_episode_steps == 14  # make_sized's default
    saved["task"]["args"] = {"size": 9}  # a record that no longer fits the function: one line
    (run / "config.json").write_text(json.dumps(saved))
    with pytest.raises(ConfigError) as err:
        saved_run(saved_experiment, run)
    assert str(err.value) == (f"--resume: {run / 'config.json'}: task.args: size is no parameter of "
                              f"{MODULE}:make_sized; it accepts: max_steps, hidden")
    assert task_source(f"{MODULE}:make_sized", str(here))["folder"] == str(here.resolve())


TINY_SETS = ["--set", "num_updates=2", "--set", "eval_every=1", "--set", "checkpoint_every=1", "--set", "num_envs=4",
             "--set", "eval_attempts=1", "--set", "ppo.epochs=1", "--set", "ppo.minibatches=1", "--set", "hidden_size=16"]


@pytest.mark.slow  # trains two updates of PLR⊥, resumes and evaluates them: compiles for about 15 s
def test_the_command_line_trains_resumes_and_evaluates_with_the_recorded_arguments(here, tmp_path, monkeypatch,
                                                                                  capsys):
    run = tmp_path / "run"
    assert main(["run", f"{MODULE}:make_sized", "--task-arg", "max_steps=12", "--algo", "plr", "--seeds", "1",
                 "--out", str(run), "--quiet", *TINY_SETS]) == 0, capsys.readouterr().err
    saved = json.loads((run / "config.json").read_text())
    assert saved["task"]["args"] == {"max_steps": 12} and saved["config"]["num_steps"] == 12
    assert "remidi: plr: 1 buffer of 64 levels (duplicates update their entry)" in capsys.readouterr().err
    (run / "summary.json").unlink()  # unfinished again: --resume trains from its last checkpoint
    monkeypatch.chdir(tmp_path)
    monkeypatch.delitem(sys.modules, MODULE)
    assert main(["run", "--resume", str(run), "--quiet"]) == 0, capsys.readouterr().err
    assert main(["evaluate", str(run), "--attempts", "1", "--cvar-levels", "4", "--cvar-attempts", "1"]) == 0, \
        capsys.readouterr().err
    assert (run / "evaluate.json").exists()
