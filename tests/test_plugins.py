"""remidi.register_algorithm and remidi.register_score: validated entries that the engine, the
validation and the command line use like the library's own."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_ued_engine import TASK, TINY

import remidi
from remidi.engine.adversaries import scores as sc
from remidi.engine import learner as lrn
from remidi.engine import train as tr
from remidi.engine.adversaries.plr import LevelBuffers
from remidi.engine.adversaries.level_buffer import select_buffer
from remidi.errors import ConfigError

pytestmark = pytest.mark.usefixtures("restore_registries")


def abs_gae(x):
    return sc.episode_mean(jnp.abs(x.advantages), x.done)


def test_a_registered_score_ranks_the_buffers_levels():
    """One update of PLR⊥ on fresh levels with score=abs_gae: the levels the buffer holds carry
    exactly abs_gae of their rollout (recomputed from the same rollout), not another score's."""
    remidi.register_score("abs_gae", abs_gae, needs_finished_episodes=True)
    cfg = dataclasses.replace(TINY, score="abs_gae", num_envs=8, buffer=dataclasses.replace(TINY.buffer, capacity=16))
    setup = tr.make_setup(TASK, cfg, "plr")
    runner = tr.init_runner(setup, jax.random.PRNGKey(3))
    # the rollout train_step makes (its keys split as train_step splits them)
    _, k_branch, k_roll, k_levels, _, k_sample = jax.random.split(runner.rng, 6)
    proposal = setup.algo.adversary.propose(setup, runner, jax.vmap(setup.task.sample_level)(jax.random.split(k_levels, setup.cfg.num_envs)), k_branch, k_levels,
                                            k_sample)
    assert not bool(proposal.replay)  # an empty buffer: fresh levels, scored and inserted
    collection = lrn.collect(setup, runner.learner, k_roll, proposal.levels, None)
    traj, advantages = collection.traj, collection.advantages
    inputs = sc.ScoreInputs(mean_return=collection.mean_return, values=traj.value, advantages=advantages,
                            max_return=collection.best_return, done=traj.done, reward=traj.reward)
    expected = np.sort(np.asarray(abs_gae(inputs)))
    pvl = np.sort(np.asarray(sc.positive_value_loss(advantages, traj.done)))
    assert np.all(np.isfinite(expected)) and not np.allclose(expected, pvl)  # the test tells the scores apart

    after, _ = jax.jit(lambda r: tr.train_step(setup, r))(runner)
    buffer = select_buffer(after.adversary.buffers, after.adversary.active)
    held = np.sort(np.asarray(buffer.scores)[np.asarray(buffer.valid)])
    assert len(held) == cfg.num_envs  # every fresh level inserted (capacity 16)
    np.testing.assert_allclose(held, expected, rtol=1e-6)


def test_a_registered_algorithm_is_its_adversary_and_score():
    algo = remidi.register_algorithm("remidi-maxmc", LevelBuffers(buffer_sequence=True), score="maxmc",
                                     description="ReMiDi ranking by MaxMC")
    setup = tr.make_setup(TASK, TINY, "remidi-maxmc")
    assert setup.algo is algo and algo.buffer_sequence and algo.replays and not algo.trains_on_fresh
    assert algo.score_name(TINY.score) == "maxmc"
    from remidi.experiments import get_experiment

    lever = get_experiment("lever")  # built before the registration: it sees it all the same
    assert "remidi-maxmc" in lever.algorithms and lever.algorithms[-1] == "remidi-maxmc"
    lever.validate(lever.config_factory(), "remidi-maxmc")


def test_validation_checks_what_a_registered_score_needs():
    from remidi.engine.run.validation import run_warnings, validate_ued_config

    remidi.register_score("needs-both", lambda x: x.optimal_return - x.mean_return, needs_optimum=True,
                          needs_solved=True, needs_finished_episodes=True)
    no_solved = dataclasses.replace(TASK, solved=None)
    cfg = dataclasses.replace(TINY, score="needs-both")
    with pytest.raises(ConfigError, match=r"^score: needs-both needs a solve criterion.*allowed: .*pvl"):
        validate_ued_config(cfg, "plr", no_solved)
    validate_ued_config(cfg, "plr", TASK)
    short = dataclasses.replace(TINY, score="needs-both", num_steps=1)
    long_task = dataclasses.replace(TASK, max_episode_steps=5)
    assert any(w.startswith("score needs-both uses the episodes that end") for w in run_warnings(short, "plr", long_task))
    with pytest.raises(ConfigError, match=r"^score: unknown value 'nope'; allowed: .*needs-both"):
        validate_ued_config(dataclasses.replace(TINY, score="nope"), "plr", TASK)


@pytest.mark.parametrize("call, needle", [
    (lambda: remidi.register_score("pvl", abs_gae), "register_score: a score named 'pvl' is already registered"),
    (lambda: remidi.register_score("a,b", abs_gae), "register_score: name must be a non-empty string"),
    (lambda: remidi.register_score("", abs_gae), "register_score: name must be a non-empty string"),
    (lambda: remidi.register_score(3, abs_gae), "register_score: name must be"),
    (lambda: remidi.register_score("x", "abs_gae"), "register_score: x: fn must be a function of ScoreInputs, got str"),
    (lambda: remidi.register_score("x", abs_gae, needs_optimum=1), "register_score: x: needs_optimum must be true or"),
    (lambda: remidi.register_score("x", lambda x: x.advantages), "returned float32[3, 2]"),
    (lambda: remidi.register_score("x", lambda x: x.done[0]), "must return one float score per level"),
    (lambda: remidi.register_score("x", lambda x: x.optimal_return - x.mean_return),
     "register_score: x: fn failed on a rollout of 3 steps × 2 levels: TypeError"),
    (lambda: remidi.register_algorithm("plr", LevelBuffers()),
     "register_algorithm: an algorithm named 'plr' is already registered"),
    (lambda: remidi.register_algorithm("all", LevelBuffers()), "register_algorithm: name must be"),
    (lambda: remidi.register_algorithm("x", LevelBuffers), "adversary must be an instance, e.g. LevelBuffers()"),
    (lambda: remidi.register_algorithm("x", "plr"), "algorithm x: adversary must be a remidi.engine.adversaries.base"),
    (lambda: remidi.register_algorithm("x", LevelBuffers(), score="nope"),
     f"register_algorithm: x: score must be a registered score or None, got 'nope'; allowed: {', '.join(sc.SCORES)}"),
])
def test_a_taken_or_malformed_entry_is_one_line_and_registers_nothing(call, needle):
    before = dict(sc.SCORES), tuple(remidi.engine.algorithms.ALGORITHMS)
    with pytest.raises(ConfigError) as err:
        call()
    assert needle in str(err.value) and "\n" not in str(err.value), str(err.value)
    assert (dict(sc.SCORES), tuple(remidi.engine.algorithms.ALGORITHMS)) == before


def test_the_command_line_imports_plugins_first(tmp_path, capsys, monkeypatch):
    """REMIDI_PLUGINS names modules the command line imports before it reads --algo: their
    algorithms and scores are listed, accepted and validated; a failing one is one line."""
    from remidi.cli import main
    from remidi.plugins import ENV

    (tmp_path / "my_plugin_mod.py").write_text(
        "import remidi\nfrom remidi.engine.adversaries.plr import LevelBuffers\n"
        "remidi.register_algorithm('plr-fresh', LevelBuffers(trains_on_fresh=True), description='PLR, fresh too')\n"
        "remidi.register_score('zero', lambda x: 0.0 * x.mean_return, help='all alike')\n")
    (tmp_path / "bad_plugin_mod.py").write_text("import remidi\nremidi.register_score('pvl', lambda x: x.mean_return)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv(ENV, "my_plugin_mod")
    assert main(["list", "lever"]) == 0
    out = capsys.readouterr().out
    # the plugin's names follow the built-in ones (the lever task can use every score)
    algorithms = ", ".join(remidi.engine.algorithms.BUILTIN_ALGORITHMS + ("plr-fresh",))
    assert f"  algorithms: {algorithms} (default" in out
    assert f"  scores:     {', '.join(sc.BUILTIN_SCORES + ('zero',))} (--set score=NAME)" in out
    # accepted by --algo and score=, refused with the registered names listed
    assert main(["run", "lever", "--algo", "plr-fresh", "--set", "score=nope", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("remidi: error: score: unknown value 'nope'") and "zero" in err and err.count("\n") == 1
    assert not (tmp_path / "x").exists()
    monkeypatch.setenv(ENV, "bad_plugin_mod")
    assert main(["list", "lever"]) == 2
    err = capsys.readouterr().err
    assert err == ("remidi: error: REMIDI_PLUGINS: bad_plugin_mod: register_score: a score named 'pvl' is already "
                   f"registered; taken: {', '.join(sc.SCORES)}\n")
    monkeypatch.setenv(ENV, "no_such_plugin_xyz")
    assert main(["list"]) == 2
    assert "REMIDI_PLUGINS: cannot import no_such_plugin_xyz (ModuleNotFoundError" in capsys.readouterr().err


def test_entry_points_of_the_group_remidi_plugins_are_loaded(monkeypatch, capsys):
    """An installed package's `remidi.plugins` entry point is loaded by the command line (once);
    one that fails to load is one line naming it."""
    import importlib.metadata

    from remidi import plugins
    from remidi.cli import main

    loaded = []

    class EntryPoint:
        def __init__(self, name, value, load):
            self.name, self.value, self._load = name, value, load

        def load(self):
            return self._load()

    def good():
        loaded.append("good")
        remidi.register_score("from-entry-point", lambda x: -x.mean_return)

    def bad():
        raise ImportError("no module named pkg_that_is_gone")

    eps = [EntryPoint("mine", "my_pkg.plugin", good)]
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: eps if group == plugins.GROUP else [])
    monkeypatch.setattr(plugins, "_loaded", set())
    monkeypatch.delenv(plugins.ENV, raising=False)
    assert main(["list", "lever"]) == 0 and main(["list", "lever"]) == 0
    assert loaded == ["good"] and "from-entry-point (--set score=NAME)" in capsys.readouterr().out
    eps.append(EntryPoint("broken", "gone_pkg.plugin", bad))
    assert main(["list"]) == 2
    assert capsys.readouterr().err == ("remidi: error: plugin broken (gone_pkg.plugin, entry point group remidi.plugins): "
                                       "cannot load it (ImportError: no module named pkg_that_is_gone)\n")
