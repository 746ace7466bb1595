"""The results page (``docs/results.md``): every table and figure generated from committed data.

Run from the repository root (a development tool, not installed with the package):
``python -m tools.results.page`` reads the runs under ``docs/results/data`` and rewrites, in
``docs/results.md`` and ``README.md`` (its claims table), every block between
``<!-- generated:NAME -->`` and ``<!-- /generated:NAME -->``, and the figures under
``docs/results/``; ``--check`` only says which blocks differ from what the data give (exit 1), as
``tests/test_results_page.py`` does.

**Data.** ``DATA/<experiment>/<run>/`` is one ``remidi run`` of one algorithm (a part of its
seeds): ``config.json``, ``summary.json``, ``evaluate.json`` (``remidi evaluate --attempts 30``)
and ``metrics.csv.gz``. Parts of one experiment × algorithm are merged by seed (a seed twice is
an error), so seeds can be run in parts. ``REPEATS`` (``docs/results/repeats``, ``--collect-repeat``)
is laid out alike and holds committed runs trained again, to measure what their folders did not
keep; only the tables that set them beside their originals read it.

**Claims and the verdict rule** (:data:`~tools.results.claims.CLAIMS`,
:func:`~tools.results.verdicts.verdict`), stated before the runs: each
claim of the paper has one primary metric, read from the final checkpoint (``evaluate.json``)
or the final logged point (``summary.json``), and its comparisons "A's mean > B's" or bounds
"A's mean lies in [lo, hi]". A comparison *passes* when the ordering holds in the mean and the
probability of improvement's 95% interval lies above 0.5 or the one-sided permutation p-value
(exact up to :data:`remidi.stats.MAX_EXACT` arrangements, every design of at most 10 seeds per
group; beyond, a Monte Carlo estimate), Holm-adjusted over the claim's comparisons, is below 0.05 (independent groups: the
seeds of two algorithms share their initial network but not their curricula, so they are not
paired). A bound passes when the 95% bootstrap interval of the mean lies inside it; a no-worse
test "A's mean ≥ B's − δ" when the 95% bootstrap interval of the difference lies above −δ. A claim is
**reproduced** when all of its tests pass, **partly** when some pass and others do not (and
**partly (no test passes)** when all hold in the mean but none passes), **not reproduced**
otherwise, and **pending** while an algorithm has fewer seeds than the claim requires. Everything
else on the page is secondary and exploratory.

Each verdict names the scale its runs trained at (:func:`~tools.results.verdicts.run_scale`:
the preset, and its
environment steps as a share of the paper preset's). A claim that reads runs made before a
correction they need (:data:`~tools.results.claims.FIXES`) shows "stale: ..." instead of its verdict until they are
made again.

The page's parts, one module each in :mod:`tools.results`: ``claims`` (what the page states,
and its sections), ``data`` (the committed runs, ``--collect``), ``verdicts`` (the rule applied),
``tables``, ``figures``, and ``floors`` (policies that learn nothing, measured once).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from remidi.errors import ConfigError, RemidiError
from remidi.experiments import outputs

from tools.results.claims import CLAIMS, EXTRA_TABLES, SECTIONS
from tools.results.data import DATA, REPEATS, ROOT, collect, collect_unfinished, load_runs, load_unfinished
from tools.results.figures import draw_figures
from tools.results.floors import OUT as FLOORS  # python -m tools.results.floors writes it
from tools.results.tables import (claim_provenance_table, claims_table, floors_table, maze_floors_table, metrics_table,
                                  mode_table, per_seed_table, provenance_table, repeat_table, scale_gap_table,
                                  unfinished_table, verdict_table)
from tools.results.verdicts import evaluate_claim

PAGE = ROOT / "docs" / "results.md"
README = ROOT / "README.md"


def blocks(runs: dict, unfinished: dict | None = None, repeats: dict | None = None) -> tuple[dict[str, str], list[dict]]:
    """``{block name: Markdown}`` of every generated block, and the claims' results (``unfinished``:
    :func:`~tools.results.data.load_unfinished`, drawn beside the scale study, in no claim;
    ``repeats``: :func:`~tools.results.data.load_runs` of :data:`~tools.results.data.REPEATS`,
    set beside their originals, in no claim)."""
    results = [evaluate_claim(c, runs) for c in CLAIMS]
    out = {"verdicts": verdict_table(results), "provenance": provenance_table(runs), "claims": claims_table(results),
           "claim-provenance": claim_provenance_table(results, runs),
           "claim-figures": "\n".join(f"![{r['claim'].title}: {r['claim'].statement}](results/claim-{r['claim'].key}.png)"
                                       for r in results if r["verdict"] != "pending") or "_No verdict yet._"}
    for exp, (algos, metrics, _) in SECTIONS.items():
        present = any((exp, a) in runs for a in algos)
        out[f"table:{exp}"] = metrics_table(runs, exp, metrics, algos) if present else "_No committed data yet._"
        out[f"seeds:{exp}"] = per_seed_table(runs, exp, metrics[0], algos) if present else "_No committed data yet._"
    for name, (exp, algos, metrics) in EXTRA_TABLES.items():
        present = [a for a in algos if (exp, a) in runs
                   and any(m.split(":", 1)[1] in runs[exp, a].values.get(m.split(":", 1)[0], {}) for m in metrics)]
        out[f"table:{name}"] = metrics_table(runs, exp, metrics, present) if present else "_No committed data yet._"
    floors = outputs.read_json(FLOORS) if FLOORS.is_file() else None
    out["brax-floors"] = floors_table(runs, floors) if floors else "_No committed data yet._"
    out["brax-mode"] = mode_table(runs, repeats)
    out["repeats"] = repeat_table(runs, repeats or {})
    out["scale-gap"] = scale_gap_table(results, runs)
    out["scale-unfinished"] = unfinished_table(unfinished or {})
    out["maze-floors"] = maze_floors_table(runs, floors) if floors and "mazes" in floors else "_No committed data yet._"
    return out, results


#: a block: its opening line, its body (whole lines, possibly none), its closing marker
_BLOCK = re.compile(r"(<!-- generated:(?P<name>[^ ]+) -->\n)(?P<body>.*?)(<!-- /generated:(?P=name) -->)", re.S)


def render(page: str, generated: dict[str, str]) -> str:
    """``page`` with every generated block's body replaced (unknown block names: ConfigError)."""
    def sub(m):
        name = m.group("name")
        if name not in generated:
            raise ConfigError(f"page: unknown generated block {name!r}; known: {', '.join(generated)}")
        return m.group(1) + generated[name] + "\n" + m.group(4)

    return _BLOCK.sub(sub, page)


def stale_blocks(page: str, generated: dict[str, str]) -> list[str]:
    """Names of the page's generated blocks whose body differs from the data's."""
    return [m.group("name") for m in _BLOCK.finditer(page) if generated.get(m.group("name"), "") + "\n" != m.group("body")]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tools.results.page", description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--page", type=Path, default=PAGE)
    parser.add_argument("--check", action="store_true", help="only report blocks that differ from the data (exit 1)")
    parser.add_argument("--no-figures", action="store_true")
    parser.add_argument("--collect", nargs="+", type=Path, metavar="RUN",
                        help="first copy these finished runs' small outputs into --data")
    parser.add_argument("--collect-repeat", nargs="+", type=Path, metavar="RUN",
                        help="first copy these finished runs, trained again to measure what a committed run did "
                             "not keep, into --repeats (set beside their originals, read by no claim)")
    parser.add_argument("--repeats", type=Path, default=REPEATS)
    parser.add_argument("--collect-unfinished", nargs="+", type=Path, metavar="RUN",
                        help="first copy these unfinished runs' training evaluations so far into --data (drawn "
                             "beside the scale study, read by no claim)")
    args = parser.parse_args(argv)
    try:
        return _run(args)
    except RemidiError as err:  # bad input (a run to collect, the data): one line, nothing written
        print(f"{parser.prog}: error: {err}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    for run in args.collect or []:
        for target in collect(run, args.data):
            print(f"collected {target}", file=sys.stderr)
    for run in args.collect_repeat or []:
        for target in collect(run, args.repeats):
            print(f"collected {target} (trained again)", file=sys.stderr)
    for run in args.collect_unfinished or []:
        print(f"collected {collect_unfinished(run, args.data)} (unfinished)", file=sys.stderr)
    runs, unfinished = load_runs(args.data), load_unfinished(args.data)
    generated, results = blocks(runs, unfinished, load_runs(args.repeats))
    pages = [args.page] + ([README] if args.page == PAGE else [])  # the README quotes the page's claims table
    if args.check:
        stale = [f"{p.name}:{name}" for p in pages for name in stale_blocks(p.read_text(), generated)]
        print("the page matches the data" if not stale else "stale blocks: " + ", ".join(stale))
        return 1 if stale else 0
    for page in pages:
        page.write_text(render(page.read_text(), generated))
    figures = [] if args.no_figures else draw_figures(runs, results, args.page.parent / "results", unfinished)
    for r in results:
        print(f"{r['claim'].key:28s} {r['verdict']}")
    print(f"wrote {args.page}" + (f" and {len(figures)} figures" if figures else ""), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
