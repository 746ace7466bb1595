"""``remidi bench``: the JSON document's shape, the ratios, and bad names."""

import json
import subprocess
import sys

import pytest
from conftest import subprocess_env

from remidi.bench import BENCHMARKS, DEFAULT, format_table
from remidi.bench.runner import ratios

FIELDS = {"env_steps_per_s", "seconds_per_call", "env_steps_per_call", "gflops_per_s", "compile_s", "peak_rss_mb",
          "repeats", "times_s"}


def test_bench_json_has_only_the_document_on_stdout():
    proc = subprocess.run([sys.executable, "-m", "remidi", "bench", "maze-env", "--tiny", "--repeats", "2", "--json"],
                          capture_output=True, text=True, timeout=300, env=subprocess_env(__name__))
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)  # nothing but the document
    assert set(doc) == {"benchmarks", "ratios", "device", "tiny", "set", "seeds"} and doc["tiny"] is True
    assert doc["seeds"] == 1
    result = doc["benchmarks"]["maze-env"]
    assert FIELDS <= set(result) and result["repeats"] == 2 and len(result["times_s"]) == 2
    assert result["env_steps_per_s"] > 0 and result["compile_s"] > 0 and result["peak_rss_mb"] > 100
    assert result["env_steps_per_s"] == result["env_steps_per_call"] / result["seconds_per_call"]
    assert result["gflops_per_s"] is None  # the environment alone: no network
    assert "cpu" in doc["device"]
    assert "bench maze-env" in proc.stderr  # progress goes to stderr


def test_a_flop_rate_without_env_steps_and_plain_python_without_compiling(monkeypatch):
    # what each benchmark's own process measures (`run_one`, here in the test's process, at --tiny sizes)
    from remidi.bench.registry import TINY_ENV
    from remidi.bench.runner import run_one

    monkeypatch.setenv(TINY_ENV, "1")
    matmul = run_one("lstm-matmul", 1)  # a FLOP rate, no environment steps
    assert matmul["env_steps_per_s"] is None and matmul["gflops_per_s"] > 0
    assert abs(matmul["gflops_per_s"] * 1e9 * matmul["seconds_per_call"] - 2 * 4 * 406 * 1024 * 64) < 1e3
    solve = run_one("solve-onestep", 1)  # plain Python: nothing compiled, no steps
    assert solve["compile_s"] < 0.01 and solve["env_steps_per_s"] is None and solve["rounds"] > 10


def test_seeds_train_together_and_count_every_seeds_steps(monkeypatch):
    """``--seeds 2``: the train workload's runner carries two seeds (as a run of two seeds does)
    and a call's environment steps are both seeds'."""
    from remidi.bench.registry import SEEDS_ENV, TINY_ENV, _shrink
    from remidi.experiments.lever import paper_config

    monkeypatch.setenv(TINY_ENV, "1")
    monkeypatch.setenv(SEEDS_ENV, "2")
    two = BENCHMARKS["lever-plr"].build()
    cfg = _shrink(paper_config())
    assert two.env_steps_per_call == 2 * 20 * cfg.num_envs * cfg.num_steps  # lever-plr: 20 updates per call
    assert two.args[0].updates_done.shape == (2,)


def test_ratios_compare_time_per_env_step():
    results = {"maze-plr": {"seconds_per_call": 2.0, "env_steps_per_call": 16384, "env_steps_per_s": 8192.0},
               "maze-remidi": {"seconds_per_call": 2.4, "env_steps_per_call": 16384, "env_steps_per_s": 6826.7},
               "maze-env": {"seconds_per_call": 0.01, "env_steps_per_call": 8192, "env_steps_per_s": 819200.0}}
    r = ratios(results)
    assert abs(r["remidi_step_over_plr_step"] - 1.2) < 1e-12
    assert abs(r["maze_plr_over_env"] - 0.01) < 1e-12
    assert ratios({"maze-env": results["maze-env"]}) == {}
    flops = ratios({"maze-plr": {**results["maze-plr"], "gflops_per_s": 60.0}, "lstm-matmul": {"gflops_per_s": 150.0}})
    assert flops == {"maze_plr_flops_over_matmul": 0.4}
    table = format_table({"benchmarks": {k: {**v, "compile_s": 1.0, "peak_rss_mb": 500.0} for k, v in results.items()},
                          "ratios": r, "device": "cpu"})
    assert "remidi_step_over_plr_step: 1.200" in table


def test_default_benchmarks_are_registered_and_unknown_names_are_one_line_errors(capsys):
    from remidi.cli import main

    assert set(DEFAULT) <= set(BENCHMARKS) and "maze-remidi-reference" in BENCHMARKS
    assert main(["bench", "maze-fast"]) == 2  # refused before any benchmark starts
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "maze-fast" in err and "maze-plr" in err


def test_every_ratio_names_registered_workloads_and_each_remidi_variant_has_its_ratio():
    from remidi.bench.runner import STEP_RATIOS

    for workload, baseline, _ in STEP_RATIOS:
        assert workload in BENCHMARKS and baseline in BENCHMARKS
    one = {"seconds_per_call": 1.0, "env_steps_per_call": 100}
    names = ["maze-remidi-combine", "maze-remidi-rehearsal", "maze-remidi-belief", "maze-remidi-simulated"]
    r = ratios({"maze-remidi": one, **{n: {**one, "seconds_per_call": 1.0 + i} for i, n in enumerate(names)}})
    assert [r[f"remidi_{n.removeprefix('maze-remidi-')}_step_over_remidi_step"] for n in names] == [1.0, 2.0, 3.0, 4.0]


@pytest.mark.parametrize("setting, needle", [
    ("num_envs=-1", "num_envs: must be an integer ≥ 1, got -1"),
    ("ppo.minibatches=3", "ppo.minibatches"),
    ("buffer.replay_prob=2", "buffer.replay_prob"),
])
def test_bench_settings_no_workload_can_run_are_one_line_errors(setting, needle):
    from remidi.bench import check_overrides
    from remidi.errors import ConfigError

    with pytest.raises(ConfigError, match=needle.replace("(", r"\(").replace(")", r"\)")) as err:
        check_overrides(dict([setting.split("=")]))
    assert "\n" not in str(err.value)


def test_network_flops_match_a_count_by_hand():
    """XLA's count of the maze agent's forward pass (conv + LSTM 256 + heads) against the
    layers' products, 2·(multiply-adds); a PPO epoch's forward and backward pass = 3 forwards."""
    import dataclasses

    import jax
    import jax.numpy as jnp

    from remidi.bench.workloads import network_flops_per_step
    from remidi.engine import train as tr
    from remidi.engine.setup import example_observation
    from remidi.envs.maze import maze_task
    from remidi.experiments.maze import paper_config

    cfg = paper_config()
    cfg = dataclasses.replace(cfg, num_envs=4, ppo=dataclasses.replace(cfg.ppo, epochs=2))
    task = maze_task("tmaze")
    setup = tr.make_setup(task, cfg, "plr")
    obs = jax.tree.map(lambda x: x[None, None], example_observation(task)[0])
    shapes = jax.eval_shape(setup.net.init, jax.random.PRNGKey(0), setup.net.initialize_carry(1), obs,
                            jnp.zeros((1, 1), bool))
    params = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), shapes["params"])
    lstm_in, hidden = 3 * 3 * 16 + 5, 256
    multiply_adds = (lstm_in + hidden) * 4 * hidden + 3 * 3 * 27 * 16 + 4 * 5 + 2 * hidden * 32 + 32 * 3 + 32
    by_hand = (1 + 3 * cfg.ppo.epochs) * 2 * multiply_adds
    assert abs(network_flops_per_step(setup, params) / by_hand - 1) < 0.03


@pytest.mark.skipif(len(__import__("os").sched_getaffinity(0)) < 2, reason="needs two cores")
def test_lanes_run_one_pinned_process_per_core_and_add_their_rates():
    """``--lanes 2``: two processes at once, each on a core of its own, their rates summed."""
    from remidi.bench.registry import SINGLE_THREAD_XLA, TINY_ENV
    from remidi.bench.runner import run_lanes

    lane = run_lanes("maze-env", 1, 2, {**subprocess_env(__name__), TINY_ENV: "1"})
    assert lane["lanes"] == 2 and len(lane["lane_cores"]) == 2
    assert all(len(cores) == 1 for cores in lane["lane_cores"])  # pinned
    assert lane["lane_cores"][0] != lane["lane_cores"][1]  # to different cores
    assert lane["env_steps_per_s"] == sum(lane["lane_env_steps_per_s"]) and lane["xla_flags"] == SINGLE_THREAD_XLA


def test_lanes_beyond_the_cores_are_a_one_line_error(capsys):
    from remidi.cli import main

    assert main(["bench", "maze-env", "--lanes", "999"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "--lanes" in err and "999" in err
    assert main(["bench", "maze-env", "--seeds", "0"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "--seeds" in err


def test_the_tracker_cost_workloads_have_a_ratio_per_budget():
    """bench/tracker_cost.py: ReMiDi's fresh-level update per remidi.tracker_budget against PLR⊥'s,
    on the maze and on Brax, each with its ratio (the time per env step over PLR⊥'s)."""
    from remidi.bench.tracker_cost import RATIOS

    names = {key for _, _, key in RATIOS}
    assert names == {"tracker_maze_remidi_0_over_plr", "tracker_maze_remidi_8_over_plr",
                     "tracker_maze_remidi_64_over_plr", "tracker_brax_remidi_8_over_plr",
                     "tracker_brax_remidi_64_over_plr"}
    one = {"seconds_per_call": 1.0, "env_steps_per_call": 100}
    r = ratios({"tracker-brax-plr": one, "tracker-brax-remidi-64": {**one, "seconds_per_call": 30.0}})
    assert r == {"tracker_brax_remidi_64_over_plr": 30.0}
    assert not set(DEFAULT) & {w for w, _, _ in RATIOS}  # not run by default: Brax with 64 slots is slow
