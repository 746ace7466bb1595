"""The examples run, write their outputs and show the pattern they are about:
bring_your_own_env.py, my_score.py, my_algorithm.py and my_network.py."""

import importlib.util
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import optimizing

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "bring_your_own_env.py"


def load_example(path=EXAMPLE):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it loads
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_bring_your_own_env_example(tmp_path, capsys):
    example = load_example()
    out = tmp_path / "byo"
    # in-process, so the suite's compilation cache (tests/conftest.py) applies; 150 updates, not
    # the default 200, to save the suite time (PLR⊥'s hidden replay share at 150: 0.86 and 0.89)
    with optimizing():  # 2 × 150 updates: long enough to pay for XLA's optimisations
        assert example.main([str(out), "--updates", "150"]) == 0
    printed = capsys.readouterr().out
    assert "next:" in printed and str(out / "training.png") in printed
    assert (out / "training.png").stat().st_size > 10_000
    saved = json.loads((out / "plr" / "config.json").read_text())
    assert saved["config"]["num_updates"] == 150
    assert saved["task"] == {"import": "bring_your_own_env:make_task", "folder": str(EXAMPLE.parent)}
    shares = {}
    for algo in ("plr", "remidi"):
        for name in ("config.json", "metrics.csv", "summary.json", "checkpoint.npz", "checkpoint.history.npz"):
            assert (out / algo / name).exists(), (algo, name)
        summary = json.loads((out / algo / "summary.json").read_text())
        assert summary["seeds"] == [0, 1]
        m = {name: v["mean"] for name, v in summary["metrics"].items()}
        for name in ("solve_rate/visible", "solve_rate/hidden"):
            assert 0 <= m[name] <= 1, (algo, name)
        assert m["regret/visible/mean"] >= -1e-6
        # the hidden levels keep their regret: a guess at best (half the optimal return ≥ 0.425)
        assert m["regret/hidden/worst"] > 0.2
        shares[algo] = m["replay_fraction/hidden"]
    assert shares["plr"] > 0.5  # PLR⊥ replays mostly the levels it cannot learn
    # ReMiDi's second buffer rejects every hidden level (their rollouts are the frozen ones')
    assert shares["remidi"] is None or shares["remidi"] == 0 or math.isnan(shares["remidi"])


def test_bring_your_own_env_example_bad_input_is_one_line(tmp_path, capsys):
    example = load_example()
    assert example.main([str(tmp_path / "x"), "--updates", "1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bring_your_own_env: error: remidi.num_buffers") and err.count("\n") == 1
    assert not (tmp_path / "x").exists()


def test_a_users_task_runs_from_the_command_line_by_import_path(tmp_path, capsys, monkeypatch):
    """`remidi run module:function` trains the UEDTask the function returns on the engine's
    default config with the given --set keys, writes the standard outputs, and resumes by name."""
    from remidi.cli import main

    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    out = tmp_path / "cli"
    argv = ["run", "bring_your_own_env:make_task", "--algo", "plr", "--seeds", "1", "--quiet", "--out", str(out),
            "--set", "num_updates=4", "--set", "eval_every=2", "--set", "checkpoint_every=2", "--set", "num_envs=4",
            "--set", "num_steps=16", "--set", "eval_attempts=1", "--set", "ppo.epochs=1"]
    assert main(argv) == 0
    for name in ("config.json", "metrics.csv", "summary.json", "training.png", "checkpoint.npz"):
        assert (out / name).exists(), name
    summary = json.loads((out / "summary.json").read_text())
    assert summary["experiment"] == "bring_your_own_env:make_task" and summary["preset"] == "default"
    assert list(summary["metrics"])[:2] == ["solve_rate/hidden", "solve_rate/visible"]
    saved = json.loads((out / "config.json").read_text())
    assert saved["task"] == {"import": "bring_your_own_env:make_task", "folder": str(EXAMPLE.parent)}
    capsys.readouterr()
    monkeypatch.chdir(tmp_path)  # found again by its import path, in the recorded folder
    assert main(["run", "--resume", str(out), "--quiet"]) == 0


def test_the_extending_guides_worked_example_runs_as_written(monkeypatch):
    """docs/extending.md's core of the worked example runs as written, from examples/: every name it
    uses exists (it once called make_config, which only the example defines) and run_ued takes its
    arguments (a config dict) and validates the run; only the training is left out."""
    from remidi.experiments import running

    guide = (EXAMPLE.parent.parent / "docs" / "extending.md").read_text(encoding="utf-8")
    core = guide[guide.index("what to change to make it yours. Its core:"):]
    block = re.search(r"^```python\n(.*?)^```", core, re.DOTALL | re.MULTILINE).group(1)
    trained = {}

    def validated_only(spec, config, out, notes, progress):  # what run_experiment calls once all is checked
        trained.update(algos=spec.algos, seeds=spec.seeds, config=config, out=out)
        return {algo: {} for algo in spec.algos}

    monkeypatch.setattr(running, "_write_and_train", validated_only)
    monkeypatch.chdir(EXAMPLE.parent)  # "in examples/": the task_ref imports from here
    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    namespace = {}
    exec(compile(block, "docs/extending.md", "exec"), namespace)
    assert namespace["summaries"] == {"plr": {}, "remidi": {}}
    assert trained["algos"] == ["plr", "remidi"] and trained["seeds"] == [0, 1]
    assert trained["config"].num_updates == 200 and trained["config"].network == "mlp"
    assert trained["config"].score == "perfect_regret"  # the task's default: it gives its optimal return


@pytest.mark.parametrize("target, needle", [
    ("no_such_module_xyz:make", "experiment: cannot import no_such_module_xyz (ModuleNotFoundError"),
    ("bring_your_own_env:nothing", "experiment: bring_your_own_env has no nothing"),
    ("bring_your_own_env:sample_level", "building the task of bring_your_own_env:sample_level failed"),
    ("json:dumps", "building the task of json:dumps failed"),
    ("bring_your_own_env:LENGTH", "gives an int, not a remidi UEDTask"),  # once "a int"
])
def test_an_import_path_that_is_no_task_is_one_line(tmp_path, capsys, monkeypatch, target, needle):
    from remidi.cli import main

    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    assert main(["run", target, "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("remidi: error: ") and err.count("\n") == 1 and needle in err, err
    assert not (tmp_path / "x").exists()


@pytest.mark.usefixtures("no_png")
def test_my_score_example_registers_a_score_and_trains_with_it(tmp_path, capsys, restore_registries):
    """examples/my_score.py: abs_gae is registered at import and a tiny PLR⊥ run ranks its buffer by it."""
    from remidi.engine.adversaries.scores import SCORES

    example = load_example(EXAMPLE.parent / "my_score.py")
    assert SCORES["abs_gae"].fn is example.abs_gae and SCORES["abs_gae"].needs_finished_episodes
    out = tmp_path / "score"
    assert example.main([str(out)]) == 0
    assert json.loads((out / "config.json").read_text())["config"]["score"] == "abs_gae"
    assert json.loads((out / "summary.json").read_text())["algo"] == "plr"
    assert "score=abs_gae" in capsys.readouterr().err


@pytest.mark.usefixtures("no_png")
def test_my_algorithm_example_registers_two_algorithms_trains_them_and_resumes_with_the_plugin(
        tmp_path, capsys, monkeypatch, restore_registries):
    """examples/my_algorithm.py: plr-classic and remidi-maxmc are registered at import, listed by
    the lever experiment and trained by a tiny run; a resume finds them by name. A process that has
    not registered the run's algorithm says so in one line; REMIDI_PLUGINS naming the example's
    module makes `remidi run --resume` find it (one run serves both checks)."""
    from remidi.cli import main
    from remidi.engine.algorithms import ALGORITHMS

    example = load_example(EXAMPLE.parent / "my_algorithm.py")
    assert ALGORITHMS["plr-classic"].trains_on_fresh and ALGORITHMS["remidi-maxmc"].score == "maxmc"
    out = tmp_path / "algo"
    assert example.main([str(out)]) == 0
    for algo in ("plr-classic", "remidi-maxmc"):
        summary = json.loads((out / algo / "summary.json").read_text())
        assert summary["algo"] == algo and summary["seeds"] == [0]
    # remidi-maxmc is a buffer sequence (two buffers: b0, b1); plr-classic one buffer
    assert "buffer_fraction/hidden/b1" in json.loads((out / "remidi-maxmc" / "summary.json").read_text())["metrics"]
    assert "buffer_fraction/hidden/b1" not in json.loads((out / "plr-classic" / "summary.json").read_text())["metrics"]
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--quiet"]) == 0  # finished: nothing left, found by name

    del ALGORITHMS["plr-classic"], ALGORITHMS["remidi-maxmc"], sys.modules["my_algorithm"]  # a fresh process
    (out / "remidi-maxmc" / "summary.json").unlink()  # left unfinished
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"remidi: error: --resume: {out / 'plr-classic' / 'config.json'}: the run's algorithm "
                          "'plr-classic' is unknown here (registered by a plugin? load it again: REMIDI_PLUGINS")
    assert err.count("\n") == 1
    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    monkeypatch.setenv("REMIDI_PLUGINS", "my_algorithm")
    assert main(["run", "--resume", str(out), "--quiet"]) == 0
    assert (out / "remidi-maxmc" / "summary.json").exists()


@pytest.mark.usefixtures("no_png")
def test_my_network_plugin_trains_through_the_command_line_and_resumes_with_it(tmp_path, capsys, monkeypatch,
                                                                              restore_registries):
    """examples/my_network.py as a plugin (REMIDI_PLUGINS=my_network): `remidi run lever --set
    network=ln_mlp` trains the registered network for a few updates and writes the run's outputs;
    a process without the plugin cannot resume it (one line saying so), one with it resumes it."""
    from remidi import plugins
    from remidi.cli import main
    from remidi.engine.core.networks import NETWORKS

    monkeypatch.setattr(plugins, "_loaded", set())
    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    monkeypatch.setenv("REMIDI_PLUGINS", "my_network")
    out = tmp_path / "net"
    sets = {"network": "ln_mlp", "hidden_size": 16, "num_updates": 4, "eval_every": 2, "checkpoint_every": 2,
            "num_envs": 8, "eval_attempts": 1, "ppo.epochs": 1}
    argv = ["run", "lever", "--algo", "plr", "--preset", "smoke", "--seeds", "1", "--quiet", "--out", str(out),
            *(item for key, value in sets.items() for item in ("--set", f"{key}={value}"))]
    assert main(argv) == 0
    assert NETWORKS["ln_mlp"].__name__ == "LayerNormMLP"
    for name in ("config.json", "metrics.csv", "summary.json", "checkpoint.npz"):
        assert (out / name).exists(), name
    assert json.loads((out / "config.json").read_text())["config"]["network"] == "ln_mlp"
    with np.load(out / "checkpoint.npz") as saved:  # the registered network's parameters were trained and saved
        assert any("norm_1" in key for key in saved.files) and any("dense_0" in key for key in saved.files)

    del NETWORKS["ln_mlp"], sys.modules["my_network"]  # a fresh process
    plugins._loaded.clear()
    monkeypatch.delenv("REMIDI_PLUGINS")
    (out / "summary.json").unlink()  # left unfinished
    capsys.readouterr()
    assert main(["run", "--resume", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"remidi: error: --resume: {out / 'config.json'}: the run's network 'ln_mlp' is unknown "
                          "here (registered by a plugin? load it again: REMIDI_PLUGINS") and err.count("\n") == 1
    monkeypatch.setenv("REMIDI_PLUGINS", "my_network")
    assert main(["run", "--resume", str(out), "--quiet"]) == 0
    assert (out / "summary.json").exists() and "ln_mlp" in NETWORKS


def test_my_replay_rule_example_sets_the_replay_distribution(restore_registries):
    """examples/my_replay_rule.py: ``buffer.prioritization=proportional`` is accepted and the
    buffer replays by (1-ρ)·score/Σscore + ρ·staleness, computed here by hand; draws follow it."""
    import jax
    import jax.numpy as jnp

    from remidi.engine.adversaries import level_buffer as B
    from remidi.engine.adversaries.level_buffer import validate_buffer_config
    from remidi.engine.config import BufferConfig

    load_example(EXAMPLE.parent / "my_replay_rule.py")
    cfg = BufferConfig(capacity=4, prioritization="proportional", staleness_coef=0.2)
    validate_buffer_config(cfg)
    state = B.init_buffer(cfg, jnp.zeros(()))
    state = state.replace(scores=jnp.asarray([3.0, 1.0, -2.0, 5.0]), valid=jnp.asarray([True, True, True, False]),
                          last_seen=jnp.asarray([0, 1, 2, 0]), time=jnp.asarray(3))
    by_score = np.array([3.0, 1.0, 0.0, 0.0]) / 4.0  # the negative score weighs nothing, the invalid entry neither
    staleness = np.array([3.0, 2.0, 1.0, 0.0]) / 6.0
    want = 0.8 * by_score + 0.2 * staleness
    np.testing.assert_allclose(B.replay_weights(state, cfg), want, rtol=1e-6)
    _, idxs, _ = B.sample_replay(state, cfg, jax.random.PRNGKey(0), 4000)
    np.testing.assert_allclose(np.bincount(np.asarray(idxs), minlength=4) / 4000, want, atol=0.03)
    allowed = ", ".join(B.REPLAY_RULES)
    assert allowed.endswith("proportional")
    with pytest.raises(Exception, match=f"prioritization: unknown value 'nope'; allowed: {allowed}$"):
        validate_buffer_config(BufferConfig(prioritization="nope"))
