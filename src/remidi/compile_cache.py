"""JAX's persistent compilation cache, on by default for the commands that compile a run's
programs (``remidi run``, ``remidi evaluate``, ``remidi render``).

A run's programs take minutes to compile on a CPU (the maze's block, a physics simulator's step),
and every process compiles them again: a resume, ``remidi evaluate``, a second run of the same
configuration. With the cache a program compiled once on this machine is loaded instead
(docs/performance.md, "Start-up", has the measurements). Results are the same bit for bit: the
cache holds the very executable XLA compiled, keyed by the program, the compiler options, the
backend and the JAX version.

* ``JAX_COMPILATION_CACHE_DIR`` set, or a cache configured in Python before the command ran:
  left as it is (the results lanes and the test suite choose their own).
* ``REMIDI_JAX_CACHE=off`` (or ``0``): no cache, every process compiles afresh.
* ``REMIDI_JAX_CACHE=DIR``: the cache in DIR.
* otherwise: ``~/.cache/remidi/jax/<machine>`` (``$XDG_CACHE_HOME`` if set), one folder per
  processor kind: a home folder shared by the nodes of a cluster never hands one CPU's compiled
  code to another kind of CPU. A folder that cannot be made leaves the cache off.

JAX keeps programs that took at least a second to compile and never removes any; the folder can
be deleted at any time (``rm -rf ~/.cache/remidi/jax``).

``remidi bench`` leaves the cache off: it measures compile time.
"""

from __future__ import annotations

import hashlib
import os
import platform
import sys
from pathlib import Path

ENV = "REMIDI_JAX_CACHE"
OFF = ("0", "off", "false", "no")


def machine_kind() -> str:
    """``x86_64-1a2b3c4d``: the architecture and a hash of the processor's model and instruction-set
    flags (``/proc/cpuinfo``; ``platform.processor()`` where there is none)."""
    described = platform.processor()
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
        wanted = ("model name", "flags", "Features", "CPU part")
        described = "\n".join(dict.fromkeys(line for line in lines if line.split(":")[0].strip() in wanted))
    except OSError:
        pass
    return f"{platform.machine() or 'cpu'}-{hashlib.sha256(described.encode()).hexdigest()[:8]}"


def default_folder(environ=os.environ) -> Path:
    """``$XDG_CACHE_HOME/remidi/jax/<machine kind>`` (default ``~/.cache``)."""
    base = Path(environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "remidi" / "jax" / machine_kind()


def enable(environ=os.environ) -> Path | None:
    """Turn the persistent cache on as the module's docstring says; returns its folder, or None
    where it is left as it was (the user's own setting) or off. JAX is not imported here (that
    takes seconds, and a command may yet stop at a bad argument): before JAX is imported the
    folder goes into ``JAX_COMPILATION_CACHE_DIR``, which JAX reads when it is."""
    jax = sys.modules.get("jax")
    if environ.get("JAX_COMPILATION_CACHE_DIR") or (jax is not None and jax.config.jax_compilation_cache_dir):
        return None
    value = environ.get(ENV, "").strip()
    if value.lower() in OFF:
        return None
    folder = Path(value).expanduser() if value else default_folder(environ)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:  # a read-only home: compile as without the cache
        return None
    if jax is None:
        environ["JAX_COMPILATION_CACHE_DIR"] = str(folder)
    else:
        jax.config.update("jax_compilation_cache_dir", str(folder))
    return folder
