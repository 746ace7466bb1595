"""``remidi bench``: the JSON document's shape, the ratios, and bad names."""

import json
import subprocess
import sys

from remidi.bench import BENCHMARKS, DEFAULT, format_table, ratios

FIELDS = {"env_steps_per_s", "seconds_per_call", "env_steps_per_call", "compile_s", "peak_rss_mb", "repeats", "times_s"}


def test_bench_json_has_only_the_document_on_stdout():
    proc = subprocess.run([sys.executable, "-m", "remidi", "bench", "maze-env", "--tiny", "--repeats", "2", "--json"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)  # nothing but the document
    assert set(doc) == {"benchmarks", "ratios", "device", "tiny", "set"} and doc["tiny"] is True
    result = doc["benchmarks"]["maze-env"]
    assert FIELDS <= set(result) and result["repeats"] == 2 and len(result["times_s"]) == 2
    assert result["env_steps_per_s"] > 0 and result["compile_s"] > 0 and result["peak_rss_mb"] > 100
    assert result["env_steps_per_s"] == result["env_steps_per_call"] / result["seconds_per_call"]
    assert "cpu" in doc["device"]
    assert "bench maze-env" in proc.stderr  # progress goes to stderr


def test_ratios_compare_time_per_env_step():
    results = {"maze-plr": {"seconds_per_call": 2.0, "env_steps_per_call": 16384, "env_steps_per_s": 8192.0},
               "maze-remidi": {"seconds_per_call": 2.4, "env_steps_per_call": 16384, "env_steps_per_s": 6826.7},
               "maze-env": {"seconds_per_call": 0.01, "env_steps_per_call": 8192, "env_steps_per_s": 819200.0}}
    r = ratios(results)
    assert abs(r["remidi_step_over_plr_step"] - 1.2) < 1e-12
    assert abs(r["maze_plr_over_env"] - 0.01) < 1e-12
    assert ratios({"maze-env": results["maze-env"]}) == {}
    table = format_table({"benchmarks": {k: {**v, "compile_s": 1.0, "peak_rss_mb": 500.0} for k, v in results.items()},
                          "ratios": r, "device": "cpu"})
    assert "remidi_step_over_plr_step: 1.200" in table


def test_default_benchmarks_are_registered_and_unknown_names_are_one_line_errors():
    assert set(DEFAULT) <= set(BENCHMARKS) and "maze-remidi-reference" in BENCHMARKS
    proc = subprocess.run([sys.executable, "-m", "remidi", "bench", "maze-fast"], capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "maze-fast" in proc.stderr and "maze-plr" in proc.stderr
