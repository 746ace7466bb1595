"""Seconds per update of a multi-seed block from a fresh run (no buffer switch inside), with whatever
remidi is on PYTHONPATH, to compare commits (docs/performance.md, "Rare branches over several seeds"):

    PYTHONPATH=WORKTREE/src python docs/perf_seed_branches.py blindfold-noisy cpu 5 2 \
        remidi.tracker=simulated remidi.belief_reference=true remidi.belief_false_rate=0 remidi.belief_margin=5
"""
import sys, time
from functools import partial
import jax
from remidi.experiments import get_experiment
from remidi.experiments.base import resolve_config
from remidi.experiments.config import parse_set_items
from remidi.engine.run import driver, train as tr

name, preset, seeds, updates = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
exp = get_experiment(name)
cfg = resolve_config(exp, preset, parse_set_items(sys.argv[5:]))
setup = tr.make_setup(exp.make_task(cfg), cfg, "remidi")
runner = driver._init(setup, jax.vmap(jax.random.PRNGKey)(jax.numpy.arange(seeds, dtype=jax.numpy.uint32)))
block = jax.jit(lambda r: driver.run_steps(setup, r, updates))
t = time.time(); c = block.lower(runner).compile(); print(f"compile {time.time() - t:.0f} s", flush=True)
times = []
for _ in range(2):
    t = time.time(); runner, m = c(runner); jax.block_until_ready(runner); times.append(time.time() - t)
print(f"{name} {preset} seeds {seeds}: {min(times) / updates:.2f} s/update (calls {['%.1f' % x for x in times]})", flush=True)
