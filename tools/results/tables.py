"""The results page's tables, as Markdown: the verdicts, each experiment's metrics and seeds, the
README's claims table, the runs' provenance, and the floors (policies that learn nothing) beside the
algorithms."""

from __future__ import annotations

import math
import re

import numpy as np

from remidi import stats
from remidi.envs.maze_names import HELD_OUT_NAMES
from remidi.errors import ConfigError
from remidi.experiments.plots import seeds_text
from remidi.runs.compare import describe
from remidi.runs.table import _cells as table_cells
from remidi.runs.table import _digits as table_digits

from tools.results.claims import BRAX, SCALE_PRESETS, SCALE_TASKS, SECTIONS, in_paper
from tools.results.data import EVAL_ATTEMPTS, lost_note, metric_values
from tools.results.verdicts import scale_gap, verdict_words


def _f(x: float, digits: int = 2) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{digits}f}"


def _digits(metric: str) -> int:
    """Decimals of ``"source:name"`` (as ``remidi table`` shows ``name``)."""
    return table_digits(metric.split(":", 1)[1])


def _p(p: float) -> str:
    return "n/a" if not math.isfinite(p) else f"{p:.2g}" if p >= 0.001 else "< 0.001"


def metric_source(metric: str) -> str:
    """Where a claim's metric (``evaluate:NAME`` or ``summary:NAME``) comes from, as the verdict
    table names it: the evaluation sets' metrics of ``remidi evaluate`` take :data:`~tools.results.data.EVAL_ATTEMPTS`
    attempts per level, its CVaR and generator metrics its default generated levels and attempts;
    ``summary.json`` holds each metric's last logged point, the replay shares summed over the last
    10% of training."""
    from remidi.runs.evaluate import DEFAULTS

    kind, name = metric.split(":", 1)
    if kind != "evaluate":
        return "last 10% of training" if name.startswith("replay_fraction/") else "last logged point"
    levels, attempts = DEFAULTS["cvar_levels"], DEFAULTS["cvar_attempts"]
    if name.startswith("generator/"):
        return f"final checkpoint, the tag's levels among {levels} generated, {attempts} attempts each"
    if name.startswith("cvar/"):
        return f"final checkpoint, {levels} generated levels, {attempts} attempts each"
    return f"final checkpoint, {EVAL_ATTEMPTS} attempts"


def verdict_table(results: list[dict]) -> str:
    lines = ["| claim | primary metric | test | A | B | P(A > B) [95% CI] | p (Holm) | seeds | verdict |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in results:
        claim = r["claim"]
        d = _digits(claim.metric)
        for i, t in enumerate(r["tests"]):
            head = (f"{claim.title}: {claim.statement}", f"`{claim.metric.split(':', 1)[1]}` ({metric_source(claim.metric)})"
                    ) if i == 0 else ("", "")
            where = f" on {t['experiment']}" if len(claim.experiments) > 1 else ""
            if t["kind"] == "greater":
                test = f"{t['algo']} > {t['baseline']}{where}"
                a = f"{_f(t['mean'][0], d)} [{_f(t['ci'][0][0], d)}, {_f(t['ci'][0][1], d)}]" if "mean" in t else "—"
                b = f"{_f(t['mean'][1], d)} [{_f(t['ci'][1][0], d)}, {_f(t['ci'][1][1], d)}]" if "mean" in t else "—"
                poi = f"{_f(t['poi'])} [{_f(t['poi_ci'][0])}, {_f(t['poi_ci'][1])}]" if "poi" in t else "—"
                p = f"{_p(t['p'])} ({_p(t['p_holm'])})" if "p" in t else "—"
                seeds = f"{t['n'][0]} / {t['n'][1]}"
            elif t["kind"] == "no_worse":
                test = f"{t['algo']} ≥ {t['baseline']} − {t['margin']:g}{where}"
                a = _f(t["mean"][0], d) if "mean" in t else "—"
                b = _f(t["mean"][1], d) if "mean" in t else "—"
                lo, hi = t.get("difference_ci", (math.nan, math.nan))
                poi = f"A − B {_f(t['difference'], d)} [{_f(lo, d)}, {_f(hi, d)}]" if "mean" in t else "—"
                p, seeds = "", f"{t['n'][0]} / {t['n'][1]}"
            else:
                lo, hi = t["bound"]
                test = f"{t['algo']} in [{lo:g}, {hi:g}]{where}"
                a = f"{_f(t['mean'][0], d)} [{_f(t['ci'][0][0], d)}, {_f(t['ci'][0][1], d)}]" if "mean" in t else "—"
                b, poi, p, seeds = "", "", "", f"{t['n'][0]}"
            verdict_cell = verdict_words(r) if i == 0 else ""
            lines.append(f"| {head[0]} | {head[1]} | {test} | {a} | {b} | {poi} | {p} | {seeds} | {verdict_cell} |")
    return "\n".join(lines)


def metrics_table(runs: dict, experiment: str, metrics: list[str], algos: list[str]) -> str:
    """Per algorithm of ``experiment``: each metric's mean ± sample std [95% CI] (IQM)."""
    head = "| algorithm | seeds | " + " | ".join(f"`{m.split(':', 1)[1]}`" for m in metrics) + " |"
    lines = [head, "| --- | --- |" + " --- |" * len(metrics)]
    for algo in algos:
        if (experiment, algo) not in runs:
            continue
        cells = []
        for m in metrics:
            x = list(metric_values(runs, experiment, algo, m).values())
            if not x or all(math.isnan(v) for v in x):  # not logged, or undefined (DR's replay share)
                cells.append("—")
                continue
            spread, iqm, ci = table_cells({"per_seed": x}, _digits(m))  # as remidi table shows them
            cells.append(f"{spread} {ci} ({iqm})")
        lines.append(f"| {algo} | {len(runs[experiment, algo].seeds)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def per_seed_table(runs: dict, experiment: str, metric: str, algos: list[str]) -> str:
    seeds = sorted({s for a in algos for s in metric_values(runs, experiment, a, metric)})
    lines = ["| algorithm | " + " | ".join(f"seed {s}" for s in seeds) + " |", "| --- |" + " --- |" * len(seeds)]
    d = _digits(metric)
    for algo in algos:
        v = metric_values(runs, experiment, algo, metric)
        if v:
            lines.append(f"| {algo} | " + " | ".join(_f(v[s], d) if s in v else "" for s in seeds) + " |")
    return "\n".join(lines)


def key_numbers(result: dict) -> str:
    """A claim's primary metric and each algorithm's mean of it, where there are data, with the
    smallest and largest seed count: ``"`solve_rate/mean`: remidi 0.25, plr 0.01 (10 seeds)"``
    ("" without data)."""
    claim = result["claim"]
    d = _digits(claim.metric)
    means = {}  # grouped by experiment, in the claim's order (Brax: by morphology)
    for t in sorted(result["tests"], key=lambda t: claim.experiments.index(t["experiment"])):
        if "mean" in t:
            names = (t["algo"], t["baseline"]) if "baseline" in t else (t["algo"],)
            where = f" ({t['experiment'].removeprefix('brax-')})" if len(claim.experiments) > 1 else ""
            for name, mean in zip(names, t["mean"]):
                means[f"{name}{where}"] = mean
    if not means:
        return ""
    counts = [n for t in result["tests"] if "mean" in t for n in t["n"]]  # of the settings with data
    seeds = f"{min(counts)}" + (f"–{max(counts)}" if max(counts) > min(counts) else "")
    numbers = ", ".join(f"{k} {_f(v, d)}" for k, v in means.items())
    return f"`{claim.metric.split(':', 1)[1]}`: {numbers} ({seeds} seeds)"


#: the order the README's table counts the other claims' verdicts in
VERDICT_ORDER = ("reproduced", "partly", "partly (no test passes)", "not reproduced", "pending", "stale")


def claims_table(results: list[dict]) -> str:
    """The README's results: one row per claim of the paper itself (:func:`~tools.results.claims.in_paper`)
    with its verdict and key numbers, and one row counting the verdicts of the page's other claims."""
    lines = ["| claim | verdict | key numbers |", "| --- | --- | --- |"]
    for r in results:
        if in_paper(r["claim"]):
            lines.append(f"| {r['claim'].title}: {r['claim'].statement} | {verdict_words(r)} | {key_numbers(r) or '—'} |")
    others = [r["verdict"].split(":", 1)[0] for r in results if not in_paper(r["claim"])]
    counts = ", ".join(f"{others.count(v)} {v}" for v in VERDICT_ORDER if v in others)
    lines.append(f"| {len(others)} claims beyond the paper (its methods on other tasks, ReMiDi over other "
                 f"algorithms, belief and tolerance trackers, a scale study, Kinetix) | {counts} | "
                 f"[docs/results.md](docs/results.md) |")
    return "\n".join(lines)


def provenance_table(runs: dict) -> str:
    """One row per experiment and algorithm: preset, seeds, commits and devices (of every part
    that trained it, where its summary records ``parts``; per run folder in the order its parts
    trained), the training wall time summed over its parts (marked † where some part's time is
    unknown: a run resumed before parts were recorded holds the time of its last part alone) and
    its data folders."""
    lines = ["| experiment | algorithm | preset | seeds | commit | device | training wall time (all parts) | data |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for (exp, algo), run in sorted(runs.items()):
        commits = ", ".join(sorted(str(c)[:7] for c in run.commits))
        # per run folder, its devices in the order its parts trained (folders alike shown once)
        devices = "; ".join(dict.fromkeys(" then ".join(group[2]) for group in run.groups))
        wall = f"{run.wall_s / 60:.1f} min" + (" †" if run.resumed else "")
        lines.append(f"| {exp} | {algo} | {run.preset} | {len(run.seeds)} | {commits} | {devices} | {wall} | "
                     + ", ".join(f"`{f}`" for f in run.folders) + " |")
    if any(run.resumed for run in runs.values()):
        lines.append("\n† a part of these runs was resumed from a checkpoint before runs recorded their parts; its "
                     "wall time counts the last part alone.")
    return "\n".join(lines)


def device_kinds(device: str) -> list[str]:
    """The machines a run's recorded device names, in its order: ``"gpu: NVIDIA H100 80GB HBM3
    (updates 1-300), then cpu"`` → ``["H100", "cpu"]``; a GPU without a model number keeps its
    name (``"gpu: NVIDIA GeForce RTX 4090"`` → ``["GeForce RTX 4090"]``); ``"not recorded"`` →
    ``["cpu (not recorded)"]``: the code recorded no device before it ran anywhere but the 2-core CPU."""
    if device == "not recorded":
        return ["cpu (not recorded)"]
    kinds = []
    for part in device.split(", then "):
        name = re.sub(r"\s*\(updates [^)]*\)$", "", part.strip())  # "gpu: NVIDIA H200 (updates 1-900)"
        if name.split(":")[0].strip() == "cpu":
            kinds.append("cpu")
            continue
        name = name.split(":", 1)[-1].strip().removeprefix("NVIDIA ")
        model = re.match(r"([A-Z]\d{2,4})\b", name)  # H100 80GB HBM3 → H100
        kinds.append(model.group(1) if model else name)
    return list(dict.fromkeys(kinds))


def claim_provenance_table(results: list[dict], runs: dict) -> str:
    """Per claim with data, per algorithm it reads: each run folder's seeds with the commits,
    machines and JAX versions their parts trained with, in the order they trained; the claim's
    first row says how many of each its seeds span (a claim over more than one can differ by
    more than its algorithms; a version "not recorded" is counted apart)."""
    lines = ["| claim | algorithm | seeds: commit · machine · JAX | the claim's seeds span |",
             "| --- | --- | --- | --- |"]
    for r in results:
        claim = r["claim"]
        rows, commits, machines, jaxes = [], set(), set(), set()
        for exp in claim.experiments:
            for algo in claim.algorithms:
                run = runs.get((exp, algo))
                if run is None:
                    continue
                cells = []
                for seeds, c, d, j in run.groups:
                    kinds = list(dict.fromkeys(k for dev in d for k in device_kinds(dev)))
                    cells.append(f"{seeds_text(seeds)}: {', '.join(str(x)[:7] for x in c)} · "
                                 f"{' + '.join(kinds)} · {', '.join(j)}")
                    commits |= {str(x)[:7] for x in c}
                    machines |= {k.removesuffix(" (not recorded)") for k in kinds}
                    jaxes |= set(j)
                where = f" ({exp})" if len(claim.experiments) > 1 else ""
                rows.append((f"{algo}{where}", "; ".join(cells)))
        if not rows:
            continue
        known = jaxes - {"not recorded"}
        span = ", ".join(f"{len(x)} {name}{'s' if len(x) > 1 else ''}" for x, name in
                         ((commits, "commit"), (machines, "machine"), (known, "JAX version")))
        span += " (and parts whose JAX version is not recorded)" if "not recorded" in jaxes else ""
        for i, (algo, cell) in enumerate(rows):
            head = f"{claim.title} (`{claim.key}`)" if i == 0 else ""
            lines.append(f"| {head} | {algo} | {cell} | {span if i == 0 else ''} |")
    return "\n".join(lines)


def _test_words(test: dict, result: dict) -> str:
    """A comparison of ``result``'s claim in words: passes, holds in the mean only, does not
    hold in the mean, pending (too few seeds for the claim) or stale (its runs predate a correction)."""
    if result["verdict"].startswith("stale"):
        return "stale"
    if "mean" not in test or result["rule_verdict"] == "pending":
        return "pending"
    return "passes" if test["passes"] else "holds in the mean only" if test["in_mean"] else "does not hold in the mean"


def scale_gap_table(results: list[dict], runs: dict) -> str:
    """The scale study per task and scale: ReMiDi's and PLR⊥'s held-out solve rates (each as soon
    as its runs are committed) and the difference of their means, the comparison ReMiDi > PLR⊥
    (at `cpu`: that test of the paper's held-out claim) with the seeds of each side, whether PLR⊥
    solves more than at `cpu` (the claim's verdict and its test), and the gap's reading
    (:func:`~tools.results.verdicts.scale_gap`)."""
    by_key = {r["claim"].key: r for r in results}
    lines = ["| task | scale | ReMiDi (mean [95% CI]) | PLR⊥ (mean [95% CI]) | ReMiDi − PLR⊥ (means) | "
             "ReMiDi > PLR⊥ | seeds (ReMiDi / PLR⊥) | PLR⊥ solves more than at `cpu` | the gap |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for exp, what in SCALE_TASKS:
        base = by_key[f"{exp}-heldout"]
        rows = [(base, next(t for t in base["tests"] if t["baseline"] == "plr"), "—", "(the first scale)")]
        for preset in SCALE_PRESETS:
            held, learns = by_key[f"{exp}-heldout-{preset}"], by_key[f"{exp}-plr-learns-{preset}"]
            learns_words = f"**{learns['verdict'].split(':', 1)[0]}** ({_test_words(learns['tests'][0], learns)})"
            rows.append((held, held["tests"][0], learns_words, f"**{scale_gap(held, learns)}**"))
        for r, t, learns_words, gap in rows:
            means = []
            for algo in (t["algo"], t["baseline"]):
                values = metric_values(runs, exp, algo, r["claim"].metric)
                means.append(describe(values) if values else None)
            cells = [f"{_f(d['mean'], 3)} [{_f(d['mean_ci'][0], 3)}, {_f(d['mean_ci'][1], 3)}]" if d else "—"
                     for d in means]
            diff = f"{means[0]['mean'] - means[1]['mean']:+.3f}" if all(means) else "—"
            lines.append(f"| {what} | {r['scale']} | {cells[0]} | {cells[1]} | {diff} | {_test_words(t, r)} | "
                         f"{t['n'][0]} / {t['n'][1]} | {learns_words} | {gap} |")
    return "\n".join(lines)


def unfinished_table(unfinished: dict) -> str:
    """One row per unfinished run (:func:`~tools.results.data.load_unfinished`): its preset,
    seeds, the updates and environment steps reached of the run's, devices and commit, and its
    held-out solve rate at its last training evaluation (mean over seeds with its 95% bootstrap
    interval, and the seeds above 0). A run whose folder was lost before it finished (``lost`` in its
    progress: the date) is marked so: a restarted run's collection replaces it."""
    if not unfinished:
        return "_No committed data yet._"
    lines = ["| experiment | algorithm | preset | seeds | updates reached | environment steps reached | device | commit | "
             "held-out solve rate, last evaluation (mean [95% CI]) | seeds above 0 | data |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for (exp, algo), (run, progress) in sorted(unfinished.items()):
        steps, values = run.curves["solve_rate/mean"]
        last = values[:, -1]
        lo, hi = stats.bootstrap_ci(last)
        per_update = run.config["num_envs"] * run.config["num_steps"]
        lost = f" ({note})" if (note := lost_note(progress)) else ""
        lines.append(f"| {exp} | {algo} | {progress['preset']} | {len(run.seeds)} | {progress['updates']:,} of "
                     f"{progress['num_updates']:,}{lost} | {progress['updates'] * per_update / 1e6:.1f}M of "
                     f"{progress['num_updates'] * per_update / 1e6:.1f}M | {' then '.join(progress['devices'])} | "
                     f"{str(progress['commit'])[:7]} | {_f(float(last.mean()), 3)} [{_f(lo, 3)}, {_f(hi, 3)}] | "
                     f"{int((last > 0).sum())} / {len(last)} | " + ", ".join(f"`{f}`" for f in run.folders) + " |")
    return "\n".join(lines)


#: the Brax algorithms whose undisturbed return the floors and mean-action tables show
BRAX_ALGOS = ("plr", "minimax-return", "remidi")


def floors_table(runs: dict, floors: dict) -> str:
    """Per Brax morphology: the undisturbed return of the zero-action and the N(0, 1)-action
    policy (``floors``: :mod:`tools.results.floors`' document) beside each algorithm's
    mean over seeds (the claim's metric), and the algorithms whose mean lies above zero action's
    ("—" without runs). ConfigError for a run on another Brax back end than the floors'."""
    algos = BRAX_ALGOS
    backend = floors.get("config", {}).get("backend")
    metric = "evaluate:return/undisturbed"
    lines = ["| morphology | zero action | N(0, 1) actions | " + " | ".join(algos) + " | above zero action |",
             "| --- |" + " --- |" * (len(algos) + 3)]
    for exp in BRAX:
        floor = floors.get(exp)
        if floor is None:
            continue
        means = {a: float(np.mean(list(v.values()))) for a in algos if (v := metric_values(runs, exp, a, metric))}
        for a in means:
            ran = runs[exp, a].config.get("brax", {}).get("backend")
            if backend is not None and ran != backend:
                raise ConfigError(f"data: {exp} {a} ran on the Brax back end {ran!r}, the floors on {backend!r}: "
                                  f"python -m tools.results.floors measures them again")
        above = ", ".join(a for a, m in means.items() if m > floor["zero_action"]) or ("none" if means else "—")
        lines.append(f"| {exp.removeprefix('brax-')} | {_f(floor['zero_action'], 1)} | {_f(floor['normal_actions'], 1)} | "
                     + " | ".join(_f(means[a], 1) if a in means else "—" for a in algos)
                     + f" | {above} |")
    return "\n".join(lines)


def mode_table(runs: dict, repeats: dict | None = None) -> str:
    """Per Brax morphology and algorithm, the undisturbed return of the same checkpoints acting two
    ways: actions sampled from the policy (``evaluate:``, as it trained) and its most likely
    action, the Gaussian's mean (``evaluate-mode:``, ``remidi evaluate --action mode``): means over
    the seeds evaluated both ways, and which seeds those are ("—" for an algorithm with none). The
    seeds of ``repeats`` (:data:`~tools.results.data.REPEATS`, runs trained again) get a row of
    their own, marked "trained again", under their algorithm's."""
    lines = ["| morphology | algorithm | seeds | sampled actions | mean action |", "| --- | --- | --- | --- | --- |"]
    for exp in BRAX:
        for algo in BRAX_ALGOS:
            rows = []
            for source, mark in ((runs, ""), (repeats or {}, ", trained again")):
                sampled = metric_values(source, exp, algo, "evaluate:return/undisturbed")
                mean = metric_values(source, exp, algo, "evaluate-mode:return/undisturbed")
                both = sorted(set(sampled) & set(mean))
                if both:
                    rows.append(f"| {exp.removeprefix('brax-')} | {algo} | {seeds_text(both)}{mark} | "
                                f"{_f(float(np.mean([sampled[s] for s in both])), 1)} | "
                                f"{_f(float(np.mean([mean[s] for s in both])), 1)} |")
            lines += rows or [f"| {exp.removeprefix('brax-')} | {algo} | — | — | — |"]
    return "\n".join(lines)


def repeat_table(runs: dict, repeats: dict) -> str:
    """Per experiment and algorithm of ``repeats`` (runs trained again with the same experiment,
    algorithm, preset, seeds and commit as committed ones), how far the trained-again seeds' value
    of the experiment's first :data:`~tools.results.claims.SECTIONS` metric (Brax: the final
    evaluation's undisturbed return) lies from the committed run's on the same seeds: both means, the largest difference of
    one seed, how many seeds give the same value to the last digit JSON keeps, and the commit and
    devices the repeat trained at (the committed run's are in the provenance table)."""
    lines = ["| experiment | algorithm | seeds | metric | committed run | trained again | largest difference of a seed "
             "| seeds identical | trained again at, on |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for (exp, algo) in sorted(repeats):
        metric = SECTIONS[exp][1][0]
        first, again = metric_values(runs, exp, algo, metric), metric_values(repeats, exp, algo, metric)
        both = sorted(set(first) & set(again))
        if not both:
            continue
        digits = _digits(metric)
        diffs = [abs(again[s] - first[s]) for s in both]
        lines.append(f"| {exp} | {algo} | {seeds_text(both)} | `{metric.split(':', 1)[1]}` | "
                     f"{_f(float(np.mean([first[s] for s in both])), digits)} | "
                     f"{_f(float(np.mean([again[s] for s in both])), digits)} | {_f(max(diffs), digits)} | "
                     f"{sum(again[s] == first[s] for s in both)} / {len(both)} | "
                     f"{', '.join(sorted(c[:7] for c in repeats[exp, algo].commits))}, on "
                     f"{', '.join(dict.fromkeys(d for g in repeats[exp, algo].groups for d in g[2]))} |")
    return "\n".join(lines) if len(lines) > 2 else "_No committed data yet._"


def maze_floors_table(runs: dict, floors: dict) -> str:
    """The held-out mazes' solve rate of uniform random actions (``floors["mazes"]``:
    :mod:`tools.results.floors`) beside the T-maze and blindfold algorithms' means over seeds
    (Fig. 6's metric), per maze and their mean."""
    metrics = [f"solve_rate/{name}" for name in HELD_OUT_NAMES] + ["solve_rate/mean"]
    rows = [("uniform random actions", floors["mazes"]["uniform_actions"])]
    for exp in ("tmaze", "blindfold"):
        for algo in ("plr", "remidi"):
            values = {m: metric_values(runs, exp, algo, f"evaluate:{m}") for m in metrics}
            if all(values.values()):
                rows.append((f"{algo} ({exp})", {m: float(np.mean(list(v.values()))) for m, v in values.items()}))
    lines = ["| policy | " + " | ".join(m.split("/", 1)[1] for m in metrics) + " |",
             "| --- |" + " --- |" * len(metrics)]
    cell = lambda v: "0" if v == 0 else f"{v:.4f}" if v < 0.01 else _f(v)  # noqa: E731 (the floor is near 0)
    lines += [f"| {name} | " + " | ".join(cell(means[m]) for m in metrics) + " |" for name, means in rows]
    return "\n".join(lines)

