"""Test-suite set-up: JAX's persistent compilation cache.

Most of the suite's time is XLA compiling small training programs. With the persistent cache a
program compiled once (in an earlier run of the suite, or by another xdist worker) is loaded
instead of compiled again. The cache lives outside the checkout (``REMIDI_TEST_JAX_CACHE``,
default ``~/.cache/remidi/jax-test-cache``; set it to an empty string to disable), so a fresh
clone on the same machine reuses it; results do not depend on it.

Scheduling (``pyproject.toml``: ``--dist loadfile --no-loadscope-reorder``): each test file runs
on one pytest-xdist worker, so a file's tests share its compiled programs and module fixtures
instead of compiling them on both workers, and the files start heaviest first (:data:`HEAVY_FIRST`,
measured), so that both workers finish at about the same time.
"""

import os
from pathlib import Path

import jax

_CACHE = os.environ.get("REMIDI_TEST_JAX_CACHE", str(Path.home() / ".cache" / "remidi" / "jax-test-cache"))
if _CACHE:
    jax.config.update("jax_compilation_cache_dir", _CACHE)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.1)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)

# the files that take longest on a cold cache (worker-seconds, 2-core CPU), heaviest first; the
# others follow in their usual order
HEAVY_FIRST = ("test_brax_env", "test_maze_smoke", "test_brax_smoke", "test_lever_smoke", "test_cli",
               "test_continuous", "test_maze_env", "test_sharding", "test_examples", "test_tracker_equivalence",
               "test_tabular_ued", "test_ued_engine", "test_combine", "test_bench", "test_ppo", "test_buffer",
               "test_render", "test_interrupt", "test_seed_init", "test_tracker")


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}

    def key(item):
        module = getattr(item, "module", None)
        return rank.get(getattr(module, "__name__", ""), len(rank))

    items.sort(key=key)  # stable: the order within a file, and of the other files, is kept


# ------------------------------------------------- where the suite's time goes (diagnostic, opt-in)
# REMIDI_TEST_COMPILE_REPORT=DIR: each worker appends one JSON line per test to DIR/<worker>.jsonl
# with its wall time and the XLA compile and tracing seconds (and compile count) spent during it
# (module fixtures count towards the first test that uses them). Read it with
# ``python tests/compile_report.py DIR``.
_REPORT = os.environ.get("REMIDI_TEST_COMPILE_REPORT")
if _REPORT:
    import json
    import time

    import pytest
    from jax import monitoring

    _spent = {"compile_s": 0.0, "compiles": 0, "trace_s": 0.0}

    def _listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            _spent["compile_s"] += duration
            _spent["compiles"] += 1
        elif event in ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration"):
            _spent["trace_s"] += duration

    monitoring.register_event_duration_secs_listener(_listen)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        before, start = dict(_spent), time.perf_counter()
        yield
        row = {"test": item.nodeid, "wall_s": time.perf_counter() - start,
               **{k: _spent[k] - before[k] for k in _spent}}
        Path(_REPORT).mkdir(parents=True, exist_ok=True)
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        with open(Path(_REPORT) / f"{worker}.jsonl", "a") as f:
            f.write(json.dumps(row) + "\n")
