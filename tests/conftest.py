"""Test-suite set-up: JAX's persistent compilation cache.

Most of the suite's time is XLA compiling small training programs. With the persistent cache a
program compiled once (in an earlier run of the suite, or by another xdist worker) is loaded
instead of compiled again. The cache lives outside the checkout (``REMIDI_TEST_JAX_CACHE``,
default ``~/.cache/remidi/jax-test-cache``; set it to an empty string to disable), so a fresh
clone on the same machine reuses it; results do not depend on it. Every program goes into it,
however quickly it compiled (JAX's default keeps only those over a second): the thousands of
tiny programs that eager operations compile cost more to compile again than to load (measured:
test_continuous, test_maze_env and test_buffer warm, 93 s with a 0.1 s threshold, 69 s with
none).

Scheduling (``pyproject.toml``: ``--dist loadfile --no-loadscope-reorder``): each test file runs
on one pytest-xdist worker, so a file's tests share its compiled programs and module fixtures
instead of compiling them on both workers, and the files start heaviest first (:data:`HEAVY_FIRST`,
measured), so that both workers finish at about the same time.

XLA settings, chosen for a suite that mostly compiles (measured on the maze smoke run's block
program, 2-core CPU; tests/compile_report.py shows any program's):

* :data:`FAST_XLA_FLAGS`: XLA:CPU's older fusion emitters compile these programs about twice as
  fast as its newer (MLIR) ones, and LLVM level 1 instead of 2 halves the optimised compile again
  while the code runs nearly as fast (block: 3.8 s to compile and 1.4 s to run, instead of 8.5 s
  and 1.0 s). They go into ``XLA_FLAGS`` before any backend starts, so the xdist workers and the
  tests' subprocesses inherit them; a jaxlib that no longer knows one of them (XLA would abort)
  is found by a probe (run once per jaxlib version and flag string while the cache is on), and
  the suite then runs without them (the report header says which). On x86-64 they also cap
  XLA's instruction set at AVX2, so that machines with and without AVX-512 compute the engine
  reference's values alike.
  ``REMIDI_TEST_XLA_FLAGS=0`` leaves ``XLA_FLAGS`` alone.
* Most test files run their programs for milliseconds, so they compile without LLVM optimisation
  (JAX's ``jax_disable_most_optimizations``: 2.0 s instead of 3.8 s to compile the block, which
  then runs 12x slower), except the files of :data:`OPTIMIZED`, whose end-to-end runs execute long
  enough that optimised code pays for itself (unoptimised, the Brax smoke run takes minutes
  instead of seconds). ``REMIDI_TEST_OPTIMIZE=all`` optimises every file, ``none`` none;
  subprocesses started by tests inherit the setting through :func:`subprocess_env`.

The settings differ only in floating-point rounding: tests/test_engine_reference.py allows for
it, and tests/test_maze_env.py, which compares our maze with jaxued's bit for bit, compiles those
programs with XLA's own fusion emitters.
"""

import contextlib
import hashlib
import importlib.metadata
import os
import platform
import subprocess
import sys
from pathlib import Path

import jax
import pytest

FAST_XLA_FLAGS = "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=1"
# x86-64 CPUs with and without AVX-512 vectorise reductions differently, and the rounding that
# follows moves the engine reference's lever cases beyond their float32 tolerance within a few
# PPO updates (measured: the values written on an AVX-512 machine failed on an AVX2 one): the
# suite compiles for AVX2 on every x86-64 CPU, so it computes the same values on both
if platform.machine().lower() in ("x86_64", "amd64"):
    FAST_XLA_FLAGS += " --xla_cpu_max_isa=AVX2"
_CACHE = os.environ.get("REMIDI_TEST_JAX_CACHE", str(Path.home() / ".cache" / "remidi" / "jax-test-cache"))
_FLAGS_CHECKED = "REMIDI_TEST_XLA_FLAGS_CHECKED"  # set once the controlling process has decided


def _add_fast_xla_flags() -> None:
    if os.environ.get(_FLAGS_CHECKED) or os.environ.get("REMIDI_TEST_XLA_FLAGS", "1") == "0":
        return  # a worker or subprocess: the controlling process decided, and XLA_FLAGS says what
    os.environ[_FLAGS_CHECKED] = "1"
    flags = f"{os.environ.get('XLA_FLAGS', '')} {FAST_XLA_FLAGS}".strip()
    # a jaxlib that accepted these flags once accepts them again: remembered in the cache's folder
    # (a new jaxlib or new flags give a new marker and a new probe; no cache, always a probe)
    marker = None
    if _CACHE:
        try:
            tag = hashlib.sha1(f"{importlib.metadata.version('jaxlib')} {flags}".encode()).hexdigest()[:16]
        except importlib.metadata.PackageNotFoundError:  # a jaxlib without metadata: probe every time
            tag = None
        marker = None if tag is None else Path(_CACHE) / f"xla-flags-ok-{tag}"  # gone with the cache
        if marker is not None and marker.exists():
            os.environ["XLA_FLAGS"] = flags
            return
    try:
        probe = subprocess.run([sys.executable, "-c", "import jax.numpy as j; j.ones(2).sum().block_until_ready()"],
                               env=dict(os.environ, XLA_FLAGS=flags), capture_output=True, timeout=300).returncode
    except subprocess.TimeoutExpired:
        probe = None
    if probe == 0:
        os.environ["XLA_FLAGS"] = flags
        if marker is not None:
            with contextlib.suppress(OSError):  # an unwritable place: the next run probes again
                marker.parent.mkdir(parents=True, exist_ok=True)
                marker.touch()
    else:
        os.environ[_FLAGS_CHECKED] = "refused"  # for the report header


def pytest_report_header(config):
    if os.environ.get(_FLAGS_CHECKED) == "refused":
        return f"XLA_FLAGS: this jaxlib refused {FAST_XLA_FLAGS}; compiling with its defaults (slower)"
    return f"XLA_FLAGS: {os.environ.get('XLA_FLAGS', '')}"


_add_fast_xla_flags()

# the CLI's own default cache (remidi.compile_cache) stays off: the suite writes only its own, and
# its subprocesses get that one from subprocess_env
os.environ["REMIDI_JAX_CACHE"] = "off"
if _CACHE:
    jax.config.update("jax_compilation_cache_dir", _CACHE)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)

# the files whose end-to-end runs execute long enough that XLA's optimisations pay for themselves
# (measured: each takes longer unoptimised, the Brax run ~7x). tests/test_engine_reference.py
# compares with values written unoptimised and compiles unoptimised whatever the setting
OPTIMIZED = ("test_brax_smoke", "test_maze_smoke", "test_lever_smoke")
_OPTIMIZE = os.environ.get("REMIDI_TEST_OPTIMIZE", "some")
if _OPTIMIZE not in ("some", "all", "none"):
    raise pytest.UsageError(f"REMIDI_TEST_OPTIMIZE: unknown value {_OPTIMIZE!r}; allowed: some, all, none")


def optimized(module_name: str) -> bool:
    """Whether the tests of ``module_name`` compile with XLA's optimisations."""
    return _OPTIMIZE == "all" or (_OPTIMIZE == "some" and module_name in OPTIMIZED)


jax.config.update("jax_disable_most_optimizations", _OPTIMIZE != "all")  # collection-time programs


@pytest.fixture(autouse=True, scope="module")
def _xla_optimization(request):
    disable = not optimized(request.module.__name__)
    if jax.config.read("jax_disable_most_optimizations") != disable:
        # jit's in-memory cache does not key on the setting (the persistent cache does): without
        # this, a program compiled by an earlier file would run under the other setting
        jax.clear_caches()
        jax.config.update("jax_disable_most_optimizations", disable)
    yield


@contextlib.contextmanager
def optimizing():
    """Compile the programs first traced inside the block with XLA's optimisations, whatever the
    file's setting: for a test of an unoptimised file that runs one program long enough (a model
    fit of hundreds of full-batch steps) to pay for its optimised compile. Jit it inside the
    block (a fresh function), since jit's in-memory cache does not key on the setting."""
    before = jax.config.read("jax_disable_most_optimizations")
    jax.config.update("jax_disable_most_optimizations", _OPTIMIZE == "none")
    try:
        yield
    finally:
        jax.config.update("jax_disable_most_optimizations", before)


def subprocess_env(module_name: str, cache: bool = True, **extra: str) -> dict[str, str]:
    """The environment for a Python subprocess started by a test of ``module_name``: this
    process's, with the suite's XLA optimisation setting and (``cache``) compilation cache, which
    a subprocess does not get from this file, and ``extra``."""
    env = dict(os.environ, JAX_DISABLE_MOST_OPTIMIZATIONS="0" if optimized(module_name) else "1", **extra)
    if "XLA_FLAGS" in extra and os.environ.get("XLA_FLAGS"):  # the suite's flags too
        env["XLA_FLAGS"] = f"{os.environ['XLA_FLAGS']} {extra['XLA_FLAGS']}"
    if _CACHE and cache:
        env.update(JAX_COMPILATION_CACHE_DIR=_CACHE, JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0",
                   JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES="0")
    return env

@pytest.fixture
def no_png(monkeypatch):
    """For tests whose checks read no plot: a run's figures are built (their data and panel code
    runs) but not rendered (``tight_layout`` and ``savefig``, most of a figure's cost). The PNGs
    themselves are checked by tests/test_plots.py, the smoke tests and test_cli's output tests."""
    import matplotlib.pyplot as plt

    from remidi.experiments import plots

    monkeypatch.setattr(plots, "_save", lambda fig, path: plt.close(fig))


@pytest.fixture
def figures(monkeypatch):
    """``{file name: figure}`` of what the plot functions would save, kept instead of written
    (laid out as when saved), for tests that walk the figures; closed at the end."""
    import matplotlib.pyplot as plt

    from remidi.experiments import plots

    saved = {}

    def keep(fig, path):
        saved[path.name] = fig

    monkeypatch.setattr(plots, "_save", keep)
    yield saved
    for fig in saved.values():
        plt.close(fig)


# the files that take longest on a cold cache (worker-seconds, 2-core CPU, measured with the
# compile report below), heaviest first; the others follow in their usual order
HEAVY_FIRST = ("test_maze_smoke", "test_lever_smoke", "test_brax_env", "test_brax_smoke", "test_examples", "test_belief", "test_simulated",
               "test_cli", "test_engine_reference_maze", "test_engine_reference", "test_bench", "test_continuous", "test_sharding",
               "test_maze_env", "test_accel", "test_gymnax", "test_tracker_equivalence", "test_evaluate", "test_tabular_ued",
               "test_interrupt", "test_ued_engine", "test_render", "test_ppo", "test_buffer", "test_networks",
               "test_loggers", "test_scores", "test_resume_damaged")


# the files of the slow set (``pytest -m slow``) besides the tests marked slow where they stand:
# those whose tests train end to end, compile large programs (the belief and simulated models,
# Brax, the maze reference) or start subprocesses that do. The quick tier (``-m "not slow"``, the
# README's test command) must pass in under six minutes on a fresh 2-core machine with an empty
# compilation cache, install included; these files took 888 of its 1,420 worker-seconds there
# (REMIDI_TEST_COMPILE_REPORT, 2026-11-28). .ci/run runs both sets, so nothing goes unchecked.
SLOW_FILES = ("test_belief", "test_engine_reference_maze", "test_brax_env", "test_simulated", "test_sharding",
              "test_examples", "test_continuous", "test_rehearsal", "test_bench", "test_interrupt", "test_gymnax",
              "test_noisy", "test_paired", "test_tracker_equivalence", "test_accel")


@pytest.hookimpl(tryfirst=True)  # before -m selects by marks
def pytest_collection_modifyitems(session, config, items):
    for item in items:
        module = getattr(item, "module", None)
        if getattr(module, "__name__", "") in SLOW_FILES:
            item.add_marker(pytest.mark.slow)
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}

    def key(item):
        module = getattr(item, "module", None)
        return rank.get(getattr(module, "__name__", ""), len(rank))

    items.sort(key=key)  # stable: the order within a file, and of the other files, is kept


# ------------------------------------------------- where the suite's time goes (diagnostic, opt-in)
# REMIDI_TEST_COMPILE_REPORT=DIR: each worker appends one JSON line per test to DIR/<worker>.jsonl
# with its wall time and the XLA compile and tracing seconds (and compile count) spent during it
# (module fixtures count towards the first test that uses them), and one line per program that
# went through the persistent cache to DIR/<worker>.programs.jsonl (its name and cache key, hit or
# compiled, and how long compiling took). Read them with ``python tests/compile_report.py DIR``.
_REPORT = os.environ.get("REMIDI_TEST_COMPILE_REPORT")
if _REPORT:
    import json
    import time

    from jax import monitoring
    from jax._src import compiler

    _spent = {"compile_s": 0.0, "compiles": 0, "trace_s": 0.0}
    _programs: list[dict] = []  # this test's programs that went through the persistent cache
    _current = {"test": ""}

    def _looked_up(hit):
        def log(module_name, cache_key):
            _programs.append({"test": _current["test"], "name": module_name, "key": cache_key[-16:], "hit": hit,
                              "compile_s": 0.0})
        return log

    compiler.log_persistent_cache_hit = _looked_up(True)  # called by compile_or_get_cached
    compiler.log_persistent_cache_miss = _looked_up(False)

    def _listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            _spent["compile_s"] += duration
            _spent["compiles"] += 1
            if _programs and not _programs[-1]["hit"] and not _programs[-1]["compile_s"]:
                _programs[-1]["compile_s"] = duration
        elif event in ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration"):
            _spent["trace_s"] += duration

    monitoring.register_event_duration_secs_listener(_listen)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):
        before, start = dict(_spent), time.perf_counter()
        _current["test"] = item.nodeid
        yield
        row = {"test": item.nodeid, "wall_s": time.perf_counter() - start,
               **{k: _spent[k] - before[k] for k in _spent}}
        Path(_REPORT).mkdir(parents=True, exist_ok=True)
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        with open(Path(_REPORT) / f"{worker}.jsonl", "a") as f:
            f.write(json.dumps(row) + "\n")
        with open(Path(_REPORT) / f"{worker}.programs.jsonl", "a") as f:
            f.writelines(json.dumps(p) + "\n" for p in _programs)
        _programs.clear()


@pytest.fixture
def restore_registries():
    """Algorithms, scores and networks registered by a test (remidi.register_algorithm /
    register_score / register_network / register_replay_rule, an example loaded in-process) are removed again when it
    ends, so other tests see the library's."""
    from remidi.engine.algorithms import ALGORITHMS
    from remidi.engine.adversaries.scores import SCORES
    from remidi.engine.adversaries.level_buffer import REPLAY_RULES
    from remidi.engine.core.networks import NETWORK_HELP, NETWORKS

    registries = (ALGORITHMS, SCORES, NETWORKS, NETWORK_HELP, REPLAY_RULES)
    saved = [dict(registry) for registry in registries]
    yield
    for registry, before in zip(registries, saved):
        registry.clear()
        registry.update(before)


def pytest_sessionfinish(session, exitstatus):
    """JAX's garbage-collection hook (``_xla_gc_callback``) off once the tests are done: an xdist
    worker is interrupted as it shuts down, and an interrupt landing inside that hook was printed
    as a PytestUnraisableExceptionWarning traceback below a passing run."""
    import gc

    gc.callbacks[:] = [c for c in gc.callbacks if getattr(c, "__name__", "") != "_xla_gc_callback"]
