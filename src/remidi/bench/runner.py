"""Timing the benchmarks: each in a fresh process (:func:`run_one`, ``python -m remidi.bench NAME
REPEATS``), optionally in pinned single-threaded lanes at once (:func:`run_lanes`), the ratios
between them and the table ``remidi bench`` prints."""

from __future__ import annotations

import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time

from remidi.bench import tracker_cost
from remidi.bench.registry import (BARRIER_ENV, BENCHMARKS, CORE_ENV, SEEDS_ENV, SET_ENV, SINGLE_THREAD_XLA,
                                   TINY_ENV)


def run_one(name: str, repeats: int) -> dict:
    """Compile, warm up and time benchmark ``name`` in this process."""
    import jax

    work = BENCHMARKS[name].build()
    args = work.args
    start = time.perf_counter()
    compiled = work.fn.lower(*args).compile() if work.jit else work.fn
    compile_s = time.perf_counter() - start

    def call(args):
        out = compiled(*args)
        if work.jit:
            jax.block_until_ready(out)
        return out

    out = call(args)  # warm-up
    _wait_for_the_other_lanes()
    times = []
    for _ in range(repeats):
        if work.chain:
            args = (out[0],) + args[1:]
        start = time.perf_counter()
        out = call(args)
        times.append(time.perf_counter() - start)
    seconds = statistics.median(times)
    steps = work.env_steps_per_call
    flops = work.flops_per_call
    return {"env_steps_per_s": steps / seconds if steps else None, "seconds_per_call": seconds,
            "env_steps_per_call": steps, "gflops_per_s": flops / seconds / 1e9 if flops else None,
            "compile_s": compile_s, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "repeats": repeats, "times_s": times, "cores": sorted(os.sched_getaffinity(0)), **work.extras(out)}


def _wait_for_the_other_lanes() -> None:
    """In a lane of ``--lanes``: say this process is warmed up, then wait until every lane is, so
    that the lanes' timed calls overlap."""
    folder = os.environ.get(BARRIER_ENV)
    if not folder:
        return
    open(os.path.join(folder, f"ready-{os.getpid()}"), "w").close()
    while not os.path.exists(os.path.join(folder, "go")):
        time.sleep(0.01)


def run_lanes(name: str, repeats: int, lanes: int, env: dict) -> dict:
    """Benchmark ``name`` in ``lanes`` processes at once, each pinned to a core of its own with
    XLA's CPU runtime on one thread, all timed together: how a CPU runs independent jobs (seeds,
    algorithms) side by side. ``env_steps_per_s`` is the lanes' total."""
    import glob
    import tempfile

    cores = sorted(os.sched_getaffinity(0))
    with tempfile.TemporaryDirectory() as folder:
        lane_env = {**env, BARRIER_ENV: folder,
                    "XLA_FLAGS": f"{env.get('XLA_FLAGS', '')} {SINGLE_THREAD_XLA}".strip()}
        procs = [subprocess.Popen([sys.executable, "-m", "remidi.bench", name, str(repeats)], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True, env={**lane_env, CORE_ENV: str(core)})
                 for core in cores[:lanes]]
        while len(glob.glob(os.path.join(folder, "ready-*"))) < lanes and all(p.poll() is None for p in procs):
            time.sleep(0.05)
        open(os.path.join(folder, "go"), "w").close()  # also when a lane died: the others must not wait forever
        outs = [p.communicate() for p in procs]
    for p, (_, err) in zip(procs, outs):
        if p.returncode != 0:
            raise RuntimeError(f"benchmark {name} (a lane of {lanes}) failed:\n{err[-3000:]}")
    each = [json.loads(out.strip().splitlines()[-1]) for out, _ in outs]
    rates = [r["env_steps_per_s"] for r in each]
    return {"lanes": lanes, "env_steps_per_s": sum(rates) if None not in rates else None,
            "lane_env_steps_per_s": rates, "lane_seconds_per_call": [r["seconds_per_call"] for r in each],
            "lane_cores": [r["cores"] for r in each],
            "xla_flags": SINGLE_THREAD_XLA}


def device_description() -> str:
    import jax

    d = jax.devices()[0]
    kind = getattr(d, "device_kind", d.platform)
    cores = len(os.sched_getaffinity(0))
    return f"{d.platform}: {kind} ({jax.device_count()} device{'s' if jax.device_count() != 1 else ''}), " \
           f"{cores} CPU cores, {platform.machine()}, jax {jax.__version__}"


# (workload, baseline, key): the workload's time per env step over the baseline's, in one invocation
STEP_RATIOS = (
    ("maze-remidi", "maze-plr", "remidi_step_over_plr_step"),
    ("nomatch-remidi", "nomatch-plr", "nomatch_remidi_step_over_plr_step"),
    ("maze-remidi-combine", "maze-remidi", "remidi_combine_step_over_remidi_step"),
    ("maze-remidi-rehearsal", "maze-remidi", "remidi_rehearsal_step_over_remidi_step"),
    ("maze-remidi-belief", "maze-remidi", "remidi_belief_step_over_remidi_step"),
    ("maze-remidi-simulated", "maze-remidi", "remidi_simulated_step_over_remidi_step"),
    ("maze-paired", "maze-plr", "paired_step_over_plr_step"),
    ("maze-paired-reference", "maze-plr", "paired_reference_step_over_plr_step"),
    ("maze-accel", "maze-plr", "accel_step_over_plr_step"),
    ("maze-remidi-reference", "maze-plr", "remidi_reference_step_over_plr_step"),
    ("lever-sfl", "lever-plr", "sfl_update_over_plr_update"),
) + tracker_cost.RATIOS  # the exact tracker's multiple of a rollout, per remidi.tracker_budget


def ratios(results: dict[str, dict]) -> dict[str, float]:
    out = {}

    def per_call(name):
        return results[name]["seconds_per_call"] / results[name]["env_steps_per_call"]

    for numerator, denominator, key in STEP_RATIOS:
        if numerator in results and denominator in results:
            out[key] = per_call(numerator) / per_call(denominator)
    if "maze-plr" in results and "maze-env" in results:
        out["maze_plr_over_env"] = results["maze-plr"]["env_steps_per_s"] / results["maze-env"]["env_steps_per_s"]
    if results.get("maze-plr", {}).get("gflops_per_s") and "lstm-matmul" in results:
        out["maze_plr_flops_over_matmul"] = results["maze-plr"]["gflops_per_s"] / results["lstm-matmul"]["gflops_per_s"]
    return out


def run_benchmarks(names: list[str], repeats: int, log=sys.stderr, tiny: bool = False,
                   overrides: dict | None = None, lanes: int = 1, seeds: int = 1) -> dict:
    """Run each benchmark in its own process; return the JSON document ``remidi bench --json``
    prints. ``tiny``: toy sizes (checks the tool; the figures mean nothing). ``overrides``: UED
    config keys set in every train workload (``num_envs`` and ``num_steps`` also in ``maze-env``).
    ``lanes`` > 1: each benchmark also runs in that many pinned single-threaded processes at once
    (:func:`run_lanes`), reported under ``"lanes"`` with their total against the one process on
    every core (``over_one_process``). ``seeds``: the train workloads train that many seeds
    together (vmapped, as a run of that many seeds does; their env-steps count every seed's)."""
    overrides = overrides or {}
    env = {**os.environ, TINY_ENV: "1" if tiny else "", SET_ENV: json.dumps(overrides), SEEDS_ENV: str(seeds)}
    results = {}
    for name in names:
        print(f"bench {name}: {BENCHMARKS[name].description} ...", file=log, flush=True)
        proc = subprocess.run([sys.executable, "-m", "remidi.bench", name, str(repeats)],
                              capture_output=True, text=True, env=env)
        if proc.returncode != 0:
            raise RuntimeError(f"benchmark {name} failed:\n{proc.stderr[-3000:]}")
        results[name] = json.loads(proc.stdout.strip().splitlines()[-1])
        r = results[name]
        print(f"  {_num(r['env_steps_per_s'])} env-steps/s, {_num(r['gflops_per_s'], 1)} GFLOP/s, "
              f"{r['seconds_per_call']:.3f} s per call, compile {r['compile_s']:.1f} s, peak RSS {r['peak_rss_mb']:.0f} MB", file=log, flush=True)
    doc = {"benchmarks": results, "ratios": ratios(results), "device": device_description(), "tiny": tiny,
           "set": overrides, "seeds": seeds}
    if lanes > 1:
        doc["lanes"] = {}
        for name in names:
            print(f"bench {name} in {lanes} lanes (one process per core, XLA on one thread) ...", file=log, flush=True)
            lane = run_lanes(name, repeats, lanes, env)
            total, one = lane["env_steps_per_s"], results[name]["env_steps_per_s"]
            lane["over_one_process"] = total / one if total and one else None
            doc["lanes"][name] = lane
            print(f"  {_num(total)} env-steps/s in total ({_num(lane['over_one_process'] or None, 2)}× one process)",
                  file=log, flush=True)
    return doc


def _num(value, digits: int = 0) -> str:
    """``1,234`` (or ``12.3`` with ``digits``), ``-`` where a benchmark has no such figure."""
    return "-" if value is None else f"{value:,.{digits}f}"


def format_table(doc: dict) -> str:
    lines = [f"device: {doc['device']}", "",
             f"{'benchmark':24s} {'env-steps/s':>12s} {'GFLOP/s':>8s} {'s/call':>8s} {'compile s':>9s} {'peak MB':>8s}"]
    for name, r in doc["benchmarks"].items():
        lines.append(f"{name:24s} {_num(r['env_steps_per_s']):>12s} {_num(r.get('gflops_per_s'), 1):>8s} "
                     f"{r['seconds_per_call']:8.3f} "
                     f"{r['compile_s']:9.1f} {r['peak_rss_mb']:8.0f}")
    if doc["ratios"]:
        lines.append("")
        lines += [f"{k}: {v:.3f}" for k, v in doc["ratios"].items()]
    if doc.get("lanes"):
        lines += ["", "one process per core (pinned, XLA on one thread), timed together:",
                  f"{'benchmark':24s} {'lanes':>5s} {'env-steps/s':>12s} {'× one process':>14s}"]
        for name, lane in doc["lanes"].items():
            lines.append(f"{name:24s} {lane['lanes']:5d} {_num(lane['env_steps_per_s']):>12s} "
                         f"{_num(lane['over_one_process'], 2):>14s}")
    return "\n".join(lines)
