"""The ``remidi`` command line: ``solve``, ``run``, ``list``.

Bad input never reaches JAX: every argument is validated first and reported as one line
``remidi: error: ...`` with exit status 2, before anything is written.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from remidi.errors import RemidiError


class _Parser(argparse.ArgumentParser):
    """argparse, but usage errors are one line and exit 2."""

    def error(self, message: str):  # noqa: D401
        raise RemidiError(f"{self.prog}: {message} (see {self.prog} --help)")


def _cmd_solve(args) -> int:
    from remidi.solvers.report import solve_command

    print(solve_command(args.game, as_json=args.json))
    return 0


def _cmd_list(args) -> int:
    from remidi.experiments import all_experiments
    from remidi.experiments.config import field_names

    for exp in all_experiments().values():
        print(f"{exp.name}: {exp.description}")
        print(f"  algorithms: {', '.join(exp.algorithms)}")
        presets = ", ".join(f"{p} ({exp.preset_seeds[p]} seeds)" for p in exp.presets)
        print(f"  presets:    {presets}")
        print(f"  --set keys: {', '.join(field_names(exp.config_factory()))}")
    return 0


def _print_summaries(summaries: dict[str, dict], out: Path) -> None:
    for algo, summary in summaries.items():
        print(f"\n{summary['experiment']} / {algo} ({summary['preset']}, {len(summary['seeds'])} seeds): final metrics")
        for name, m in summary["metrics"].items():
            if m["mean"] is None or m["mean"] != m["mean"]:  # undefined (null in JSON, NaN in memory)
                print(f"  {name:32s} {'n/a':>10s}")
            else:
                print(f"  {name:32s} {m['mean']:10.4f} ± {m['std']:.4f}")
    print(f"\nwrote {out}")


def _cmd_run(args) -> int:
    from remidi.experiments import get_experiment
    from remidi.experiments.base import parse_algos, resume_experiment, run_experiment
    from remidi.experiments.config import parse_set_items

    if args.resume is not None:
        if args.experiment is not None or args.algo or args.out or args.sets or args.seeds is not None:
            raise RemidiError("--resume: takes only the run folder; its config.json says the rest")
        summaries = resume_experiment(get_experiment, Path(args.resume), progress=not args.quiet)
        _print_summaries(summaries, Path(args.resume))
        return 0
    if args.experiment is None:
        raise RemidiError("remidi run: name an experiment (see remidi list) or pass --resume DIR")
    exp = get_experiment(args.experiment)
    algos = parse_algos(exp, args.algo)
    if args.preset not in exp.presets:
        from remidi.errors import one_of

        raise one_of("--preset", args.preset, exp.presets)
    num_seeds = args.seeds if args.seeds is not None else exp.preset_seeds[args.preset]
    if num_seeds < 1:
        raise RemidiError(f"--seeds: must be an integer ≥ 1, got {num_seeds}")
    if args.seed < 0:
        raise RemidiError(f"--seed: must be an integer ≥ 0, got {args.seed}")
    seeds = list(range(args.seed, args.seed + num_seeds))
    out = Path(args.out) if args.out else Path("runs") / exp.name / time.strftime("%Y%m%d-%H%M%S")
    summaries = run_experiment(exp, algos=algos, preset=args.preset, seeds=seeds,
                               overrides=parse_set_items(args.sets), out=out, progress=not args.quiet,
                               argv=sys.argv[1:])
    _print_summaries(summaries, out)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="remidi", description="ReMiDi and Bayesian level-perfect minimax regret for UED.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    solve = sub.add_parser("solve", help="exact MMR and BLP of a finite game file (JSON)",
                           description="Solve a finite game exactly: minimax-regret value, equilibrium "
                                       "adversary, and the BLP policy by iterated refinement.")
    solve.add_argument("game", help="game file (JSON; see examples/README.md for the formats)")
    solve.add_argument("--json", action="store_true", help="print machine-readable JSON")
    solve.set_defaults(func=_cmd_solve)

    run = sub.add_parser("run", help="run an experiment (see `remidi list`)",
                         description="Train one or more algorithms on an experiment for several seeds and "
                                     "write config.json, metrics.csv, summary.json and plots.")
    run.add_argument("experiment", nargs="?", help="experiment name (see `remidi list`)")
    run.add_argument("--algo", help="algorithm, comma-separated list, or 'all' (default: all)")
    run.add_argument("--preset", default="smoke", help="smoke (minutes on a CPU) or paper (default: smoke)")
    run.add_argument("--seeds", type=int, help="number of seeds (default: the preset's)")
    run.add_argument("--seed", type=int, default=0, help="first seed (default 0): seeds are SEED … SEED+N−1")
    run.add_argument("--out", help="output folder (default: runs/EXPERIMENT/TIMESTAMP); must not hold a run")
    run.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                     help="override a configuration value (repeatable; keys: `remidi list`)")
    run.add_argument("--resume", metavar="DIR", help="continue the interrupted run in DIR")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.set_defaults(func=_cmd_run)

    lst = sub.add_parser("list", help="list experiments, algorithms, presets and config keys",
                         description="List experiments with their algorithms, presets and --set keys.")
    lst.set_defaults(func=_cmd_list)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 2
        return args.func(args)
    except RemidiError as err:
        print(f"remidi: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("remidi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
