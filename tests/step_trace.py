"""Every package function one update runs, in the order it is first called: what JAX traces in
one ``train_step`` (tracing runs both sides of every ``lax.cond``/``switch``), measured as
``../shared/tools/read_cost.py`` measures it (a profile hook while ``jax.make_jaxpr`` traces the
step; comprehensions and lambdas left out). docs/engine.md lists the same for ReMiDi and PLR⊥
(tests/test_engine_guide.py)."""

from __future__ import annotations

import os
import sys

import jax

import remidi

ROOT = os.path.dirname(remidi.__file__)
SKIPPED = ("<genexpr>", "<listcomp>", "<dictcomp>", "<setcomp>", "<lambda>")


def step_trace(algo: str, experiment: str = "lever") -> list[tuple[str, str]]:
    """``[(module relative to src/remidi, qualified name)]`` of the functions one update of
    ``algo`` on ``experiment``'s smoke preset runs, first call first (``Class.method``; a nested
    function as ``outer.inner``)."""
    from remidi.engine import train as tr
    from remidi.experiments import get_experiment
    from remidi.experiments.base import resolve_config

    exp = get_experiment(experiment)
    cfg = resolve_config(exp, "smoke", {})
    setup = tr.make_setup(exp.make_task(cfg), cfg, algo)
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    seen: dict[tuple[str, int], tuple[str, str]] = {}

    def profile(frame, event, arg):
        code = frame.f_code
        if event == "call" and code.co_filename.startswith(ROOT) and code.co_name not in SKIPPED:
            key = (code.co_filename, code.co_firstlineno)
            if key not in seen:
                seen[key] = (os.path.relpath(code.co_filename, ROOT), code.co_qualname.replace(".<locals>", ""))

    jax.clear_caches()  # a jitted function traced before (same shapes) would not run its Python again
    sys.setprofile(profile)
    try:
        jax.make_jaxpr(lambda r: tr.train_step(setup, r))(runner)
    finally:
        sys.setprofile(None)
    return list(seen.values())
