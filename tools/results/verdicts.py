"""The verdict rule applied to the committed runs: each claim's tests (:func:`evaluate_claim`),
its verdict (:func:`verdict`), and the scale its runs trained at (:func:`claim_scale`)."""

from __future__ import annotations

import math
import re
from functools import lru_cache

import numpy as np

from remidi import stats
from remidi.errors import ConfigError
from remidi.runs.compare import compare

from tools.results.claims import Claim, stale_fix
from tools.results.data import metric_values

ALPHA = 0.05


STEP_KEYS = ("num_updates", "num_envs", "num_steps")  # a run's environment steps: their product


@lru_cache(maxsize=None)
def preset_steps(experiment: str, preset: str) -> tuple[int, ...] | None:
    """``(num_updates, num_envs, num_steps)`` of an experiment's preset (None where the experiment
    is not registered, has no such preset, or counts its training otherwise, as the tabular games)."""
    from remidi.experiments import get_experiment
    from remidi.experiments.base import resolve_config

    try:
        cfg = resolve_config(get_experiment(experiment), preset, {})
    except ConfigError:
        return None
    sizes = tuple(getattr(cfg, k, None) for k in STEP_KEYS)
    return sizes if all(isinstance(v, int) for v in sizes) else None


#: experiments whose `paper` preset follows another paper than ReMiDi's: whose sizes it takes
PAPER_OF = {"kinetix": "Kinetix's"}


def paper_of(experiment: str) -> str:
    """Whose configuration the experiment's `paper` preset takes: ``"the paper's"`` (ReMiDi's), or
    e.g. ``"Kinetix's"`` for the Kinetix experiments."""
    return next((v for k, v in PAPER_OF.items() if experiment.startswith(k)), "the paper's")


def run_scale(experiment: str, preset: str, config: dict | None = None) -> str:
    """At which scale a run trained: ``"`paper` preset: the paper's stated settings"`` (what the paper
    leaves unstated, such as the lever's steps per rollout, is ours: the deviations table), or its
    preset and its environment steps (num_updates × num_envs × num_steps: as the run's ``config``
    records them, else as the preset sets them) as a share of the paper preset's, e.g. ``"`cpu` preset: 5% of the paper's
    environment steps"`` (Kinetix: ``"… of Kinetix's environment steps"``)."""
    if preset == "paper":
        return "`paper` preset: the paper's stated settings"
    recorded = tuple((config or {}).get(k) for k in STEP_KEYS)
    ours = recorded if all(isinstance(v, int) for v in recorded) else preset_steps(experiment, preset)
    paper = preset_steps(experiment, "paper")
    if ours is None or paper is None:
        return f"`{preset}` preset"
    share = 100 * math.prod(ours) / math.prod(paper)
    return f"`{preset}` preset: {share:.3g}% of {paper_of(experiment)} environment steps"


def claim_scale(claim: Claim, runs: dict) -> str:
    """The scales (:func:`run_scale`) of the runs ``claim`` reads, each once, in the claim's order
    ("" if none is known); a second scale's share is written short (``"`cpu` preset: 5%"``). An
    algorithm without runs yet counts where its name says its preset (``plr @cpu4x``)."""
    scales = []
    for exp, algo in [(exp, a) for a in claim.algorithms for exp in claim.experiments]:
        if (exp, algo) in runs:
            scales.append(run_scale(exp, runs[exp, algo].preset, runs[exp, algo].config))
        elif " @" in algo:
            scales.append(run_scale(exp, algo.rsplit(" @", 1)[1]))
    scales = list(dict.fromkeys(scales))
    return "; ".join([*scales[:1], *(re.sub(r" of .*'s? environment steps$", "", s) for s in scales[1:])])


def _holds(value: float, low: float) -> bool:
    return math.isfinite(value) and value > low


def evaluate_claim(claim: Claim, runs: dict) -> dict:
    """Every test of ``claim`` on ``runs``, and its :func:`verdict`."""
    tests = []
    for a, b in claim.greater:
        for exp in claim.experiments:
            x, y = metric_values(runs, exp, a, claim.metric), metric_values(runs, exp, b, claim.metric)
            row = {"kind": "greater", "experiment": exp, "algo": a, "baseline": b, "n": (len(x), len(y))}
            if x and y:
                c = compare({exp: x}, {exp: y})["experiments"][exp]
                row.update(mean=(c["algo"]["mean"], c["baseline"]["mean"]), ci=(c["algo"]["mean_ci"],
                           c["baseline"]["mean_ci"]), poi=c["probability_of_improvement"], poi_ci=c["poi_ci"],
                           p=c["p_value"])
            tests.append(row)
    ps = [t.get("p", math.nan) for t in tests]
    for t, p in zip(tests, stats.holm(ps) if tests else []):
        t["p_holm"] = float(p)
        t["in_mean"] = "mean" in t and t["mean"][0] > t["mean"][1]
        t["passes"] = t["in_mean"] and (_holds(t["poi_ci"][0], 0.5) or (math.isfinite(p) and p < ALPHA))
    for a, b, margin in claim.no_worse:
        for exp in claim.experiments:
            tests.append(no_worse_test(exp, a, b, margin, metric_values(runs, exp, a, claim.metric),
                                       metric_values(runs, exp, b, claim.metric)))
    for a, lo, hi in claim.bounds:
        for exp in claim.experiments:
            x = metric_values(runs, exp, a, claim.metric)
            row = {"kind": "bound", "experiment": exp, "algo": a, "bound": (lo, hi), "n": (len(x),)}
            if x:
                mean, _ = stats.mean_and_sample_std(list(x.values()))
                ci = stats.bootstrap_ci(list(x.values()), np.mean)
                row.update(mean=(mean,), ci=(ci,), in_mean=lo <= mean <= hi,
                           passes=math.isfinite(ci[0]) and lo <= ci[0] and ci[1] <= hi)
            tests.append(row)
    ruled = verdict(tests, claim.min_seeds)
    fix = stale_fix(claim, runs) if ruled != "pending" else None
    shown = f"stale: its runs predate {fix.commit} ({fix.change}); {fix.rerun}" if fix else ruled
    return {"claim": claim, "tests": tests, "verdict": shown, "rule_verdict": ruled,
            "scale": claim_scale(claim, runs)}


def no_worse_test(experiment: str, a: str, b: str, margin: float, x: dict, y: dict) -> dict:
    """The test "A's mean ≥ B's mean − ``margin``" over the seeds' values ``x`` (A's) and ``y``
    (B's), ``{seed: value}``: it holds in the mean when mean(A) − mean(B) > −margin, and passes when
    the 95% bootstrap interval of that difference (the two groups resampled independently) lies
    above −margin (a non-inferiority test)."""
    row = {"kind": "no_worse", "experiment": experiment, "algo": a, "baseline": b, "margin": margin,
           "n": (len(x), len(y))}
    if x and y:
        xs, ys = np.array(list(x.values()), float), np.array(list(y.values()), float)
        diff = float(np.mean(xs) - np.mean(ys))
        ci = stats.difference_ci(xs, ys)
        row.update(mean=(float(np.mean(xs)), float(np.mean(ys))), difference=diff, difference_ci=ci,
                   in_mean=math.isfinite(diff) and diff > -margin, passes=math.isfinite(ci[0]) and ci[0] > -margin)
    return row


def verdict(tests: list[dict], min_seeds: int) -> str:
    """The verdict rule (:mod:`tools.results.page`) over a claim's tests. "partly" where no test passes
    (every comparison holds in the mean only) reads "partly (no test passes)", so that it is not
    taken for a claim that holds in some settings."""
    if not tests or any(min(t["n"]) < min_seeds for t in tests):
        return "pending"
    if all(t["passes"] for t in tests):
        return "reproduced"
    if any(t["passes"] for t in tests):
        return "partly"
    if all(t["in_mean"] for t in tests):
        return "partly (no test passes)"
    return "not reproduced"


def verdict_words(result: dict) -> str:
    """A claim's verdict as the page prints it: bold, then the scale its runs trained at."""
    return f"**{result['verdict']}**" + (f" ({result['scale']})" if result.get("scale") else "")


def scale_gap(held: dict, learns: dict) -> str:
    """The scale study's reading of ReMiDi's lead over PLR⊥ at a second scale, by the rule its
    section states before the runs. ``held``: the claim "ReMiDi > PLR⊥ on held-out mazes" at that
    scale (one comparison); ``learns``: "PLR⊥ at that scale > PLR⊥ at `cpu`". The gap
    **persists** where ``held`` is reproduced ("persists where the baseline learns" where
    ``learns`` is too), **closes** where PLR⊥'s mean is at least ReMiDi's, and **narrows,
    undecided** otherwise (ReMiDi ahead in the mean, its test not passing: "narrows" does not
    compare the gap with the first scale's, the table's difference column shows both); "pending"
    or "stale" while ``held`` has no verdict by the rule."""
    if held["verdict"] == "pending" or held["verdict"].startswith("stale"):
        return held["verdict"].split(":", 1)[0]
    if held["verdict"] == "reproduced":
        return "persists where the baseline learns" if learns["verdict"] == "reproduced" else "persists"
    (test,) = held["tests"]
    remidi, plr = test["mean"]
    if not (math.isfinite(remidi) and math.isfinite(plr)):
        return "undefined (a mean is not finite)"
    return "closes" if plr >= remidi else "narrows, undecided"
