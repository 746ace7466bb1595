"""What a new user meets first: answers to bad arguments without importing JAX, one line for an
error inside their own code (a JAX callback), for a missing optional package, and error lines
that stand on a line of their own below a progress bar."""

import json
import subprocess
import sys

import jax
import jax.numpy as jnp
import pytest

from conftest import subprocess_env

from remidi.cli import main
from remidi.cli.common import _say
from remidi.errors import DEBUG_ENV, callback_failure
from remidi.experiments import CATALOG, catalog, catalog_entries


def test_the_catalog_is_what_the_experiment_modules_define():
    assert json.loads(CATALOG.read_text()) == catalog_entries(), "run: python -m remidi.experiments"


@pytest.mark.parametrize("argv, needle", [
    (["run", "levr"], f"experiment: unknown value 'levr'; allowed: {', '.join(catalog())}"),
    (["run", "lever", "--preset", "fast"],
     f"--preset: unknown value 'fast'; allowed: {', '.join(catalog()['lever']['presets'])}"),
    (["run", "lever", "--algo", "plr,foo"],
     f"--algo: unknown value 'foo'; allowed: {', '.join(catalog()['lever']['algorithms'])}"),
    (["run", "tmaze", "--seeds", "0"], "--seeds: must be an integer ≥ 1, got 0"),
    (["run", "tmaze", "--seed", "-1"], "--seed: must be an integer ≥ 0, got -1"),
    (["table", "/nonexistent/run"], "RUN: /nonexistent/run does not exist"),
    (["evaluate", "/nonexistent/run"], "RUN_DIR: /nonexistent/run does not exist"),
    (["status", "/nonexistent/run"], "RUN_DIR: /nonexistent/run does not exist"),
    (["list"], None),
    (["run", "--help"], None),
])
def test_argument_errors_and_listings_answer_without_importing_jax(argv, needle):
    """Importing JAX takes seconds (3.9 s on an idle 2-core machine, 12–22 s under load): an
    answer that needs no compiled program must not pay for it."""
    code = ("import sys; from remidi.cli import main\n"
            "try:\n    code = main(sys.argv[1:])\nexcept SystemExit as e:\n    code = e.code\n"
            "print('JAX IMPORTED' if 'jax' in sys.modules else 'no jax', file=sys.stderr); sys.exit(code)")
    done = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                          env=subprocess_env(__name__), timeout=120)
    lines = done.stderr.splitlines()
    assert lines[-1] == "no jax", done.stderr
    if needle is None:
        assert done.returncode == 0 and done.stdout, done.stderr
    else:
        assert done.returncode == 2 and len(lines) == 2 and needle in lines[0], done.stderr


def _failing_program():
    """A compiled program whose callback (the user's code) raises, as an environment's would."""
    def check(t):
        if int(t) == 3:
            raise ValueError(f"runtime failure in my env at t={int(t)}")

    def program(t):
        jax.debug.callback(check, t)
        return t + 1

    jax.block_until_ready(jax.jit(program)(jnp.asarray(3)))


def test_an_exception_in_a_callback_is_read_back_from_jaxs_runtime_error():
    with pytest.raises(Exception) as raised:
        _failing_program()
    message = str(callback_failure(raised.value))
    assert "raised ValueError: runtime failure in my env at t=3 (test_first_hour.py:" in message
    assert f"{DEBUG_ENV}=1 shows the traceback" in message
    assert callback_failure(ValueError("not from a callback")) is None


def test_an_environment_raising_at_run_time_is_one_line_and_its_traceback_on_request(capsys, monkeypatch):
    from remidi.cli import experiments

    monkeypatch.setattr(experiments, "_cmd_run", lambda args: _failing_program())
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    assert main(["run", "lever"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("remidi: error: the environment") and "Traceback" not in err, err
    monkeypatch.setenv(DEBUG_ENV, "1")
    with pytest.raises(Exception, match="runtime failure in my env"):
        main(["run", "lever"])


def test_a_missing_optional_package_names_the_install(tmp_path, capsys):
    try:
        import kinetix  # noqa: F401
        pytest.skip("kinetix is installed here")
    except ModuleNotFoundError:
        pass
    assert main(["run", "kinetix-s", "--set", "num_updates=2", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and 'pip install "remidi[kinetix]"' in err and "Traceback" not in err, err
    assert not (tmp_path / "run").exists()


def test_an_error_line_closes_the_progress_bar_instead_of_running_into_it(capsys):
    from tqdm import tqdm

    bar = tqdm(total=4, desc="plr × 1 seed", file=sys.stderr)
    bar.update(1)
    _say("remidi: error: something")
    err = capsys.readouterr().err
    assert "\nremidi: error: something\n" in err and err.endswith("remidi: error: something\n")
    assert bar not in getattr(tqdm, "_instances", ())


def test_a_failing_task_factory_is_one_line_with_where_and_its_traceback_on_request(tmp_path, capsys, monkeypatch):
    (tmp_path / "broken_factory.py").write_text("def make_task():\n    return {}['factory bug']\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv(DEBUG_ENV, raising=False)
    assert main(["run", "broken_factory:make_task", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "building the task of broken_factory:make_task failed (KeyError: 'factory bug', at broken_factory.py:2; " \
           f"{DEBUG_ENV}=1 shows the traceback)" in err
    monkeypatch.setenv(DEBUG_ENV, "1")
    with pytest.raises(KeyError, match="factory bug"):
        main(["run", "broken_factory:make_task", "--out", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()


def test_a_config_json_of_another_experiment_is_refused_before_anything_is_trained():
    from remidi.engine.config import UEDConfig
    from remidi.errors import ConfigError
    from remidi.experiments.overrides import config_from_dict
    from remidi.tabular.learner import TabularUEDConfig

    lever = {"num_updates": 4, "num_envs": 8, "ppo": {"gamma": 0.99, "total_updates": 4}}
    assert config_from_dict(UEDConfig, lever).num_updates == 4  # a derived key (total_updates) is no foreign key
    with pytest.raises(ConfigError, match="config.json: num_updates, num_envs, ppo.gamma … are no keys"):
        config_from_dict(TabularUEDConfig, lever)


def test_repeated_seeds_are_refused(tmp_path):
    from remidi.errors import ConfigError
    from remidi.experiments.running import check_seeds

    with pytest.raises(ConfigError, match="seed 0 is given twice"):
        check_seeds([0, 0])


def test_a_module_that_exits_on_import_is_a_plugin_error(tmp_path, monkeypatch, capsys):
    (tmp_path / "exits_on_import.py").write_text("import sys\nsys.exit(3)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("REMIDI_PLUGINS", "exits_on_import")
    assert main(["list"]) == 2
    assert "REMIDI_PLUGINS: cannot import exits_on_import (SystemExit: 3)" in capsys.readouterr().err
