"""Test-suite set-up: JAX's persistent compilation cache.

Most of the suite's time is XLA compiling small training programs. With the persistent cache a
program compiled once (in an earlier run of the suite, or by another xdist worker) is loaded
instead of compiled again. The cache lives outside the checkout (``REMIDI_TEST_JAX_CACHE``,
default ``~/.cache/remidi/jax-test-cache``; set it to an empty string to disable), so a fresh
clone on the same machine reuses it; results do not depend on it.
"""

import os
from pathlib import Path

import jax

_CACHE = os.environ.get("REMIDI_TEST_JAX_CACHE", str(Path.home() / ".cache" / "remidi" / "jax-test-cache"))
if _CACHE:
    jax.config.update("jax_compilation_cache_dir", _CACHE)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
