"""Time remidi's start-up phases in one process: python prof.py <remidi argv...>.
Prints, at exit, wall and process CPU time (user+sys) per phase."""
import os, sys, time, atexit, functools
T0w, T0c = time.perf_counter(), time.process_time()
rows = []
def timed(name):
    def deco(fn):
        @functools.wraps(fn)
        def inner(*a, **k):
            w, c = time.perf_counter(), time.process_time()
            try:
                return fn(*a, **k)
            finally:
                rows.append((name, time.perf_counter() - w, time.process_time() - c))
        return inner
    return deco
import remidi.engine.run.validation as val
import remidi.engine.run.driver as drv
import remidi.experiments.ued as ued
import remidi.experiments.running as running
import jax
COMP = {"backend_compile": [0, 0.0], "trace": [0, 0.0], "lower": [0, 0.0], "cache_hit": [0, 0.0]}
NAMES = {"/jax/core/compile/backend_compile_duration": "backend_compile", "/jax/core/compile/jaxpr_trace_duration": "trace",
         "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower", "/jax/compilation_cache/cache_retrieval_time_sec": "cache_hit"}
def _listen(event, duration, **kw):
    if event in NAMES:
        COMP[NAMES[event]][0] += 1; COMP[NAMES[event]][1] += duration
jax.monitoring.register_event_duration_secs_listener(_listen)
rows.append(("imports", time.perf_counter() - T0w, time.process_time() - T0c))
val.validate_ued_config = timed("validate_ued_config")(val.validate_ued_config)
drv.validate_ued_config = val.validate_ued_config
ued.validate_ued_config = val.validate_ued_config
ued.run_warnings = timed("run_warnings")(ued.run_warnings)
orig_progs = drv.ued_programs
def ued_programs(setup, devices=1):
    p = orig_progs(setup, devices)
    first = {"rb": True, "ev": True}
    def rb(runner, length):
        w, c = time.perf_counter(), time.process_time()
        out = p.run_block(runner, length); jax.block_until_ready(out)
        rows.append(("run_block", time.perf_counter() - w, time.process_time() - c)); return out
    def ev(runner, keys):
        w, c = time.perf_counter(), time.process_time()
        out = p.evaluate(runner, keys); jax.block_until_ready(out)
        rows.append(("evaluate", time.perf_counter() - w, time.process_time() - c)); return out
    def init(keys):
        w, c = time.perf_counter(), time.process_time()
        out = p.init(keys); jax.block_until_ready(out)
        rows.append(("init", time.perf_counter() - w, time.process_time() - c)); return out
    return drv.Programs(init=init, run_block=rb, evaluate=ev, mesh=p.mesh)
drv.ued_programs = ued_programs
import remidi.engine.train as tr
tr.make_setup = timed("make_setup")(tr.make_setup)
import remidi.runs.evaluate as rev
rev._load = timed("evaluate:_load")(rev._load)
rev._solvable_levels = timed("evaluate:_solvable_levels")(rev._solvable_levels)
def report():
    tw, tc = time.perf_counter() - T0w, time.process_time() - T0c
    print("\n== phases (wall s / cpu s) ==", file=sys.stderr)
    for n, w, c in rows:
        print(f"  {n:22s} {w:7.1f} {c:7.1f}", file=sys.stderr)
    print(f"  {'TOTAL':22s} {tw:7.1f} {tc:7.1f}", file=sys.stderr)
    print("  jax (count, wall s): " + ", ".join(f"{k} {n} {t:.1f}" for k, (n, t) in COMP.items()), file=sys.stderr)
    print(f"  cache dir: {jax.config.jax_compilation_cache_dir}", file=sys.stderr)
atexit.register(report)
import signal
def _term(*_):
    print("== SIGTERM", file=sys.stderr); report(); sys.stderr.flush(); os._exit(143)
signal.signal(signal.SIGTERM, _term)
from remidi.cli import main
sys.exit(main(sys.argv[1:]))
