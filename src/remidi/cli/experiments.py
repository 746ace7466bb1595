"""``remidi solve``, ``remidi run`` and ``remidi list``: the exact solvers, training an
experiment (or resuming one), and the registry of experiments, algorithms, presets and keys."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from remidi.cli.common import _RUN_DIR
from remidi.errors import RemidiError, one_of


def _algorithms(entry: dict) -> tuple[list[str], list[str]]:
    """A built-in experiment's (default, every) algorithms: from its catalog entry, unless the
    algorithm registry is imported (:func:`remidi.register_algorithm` may have added some)."""
    if "remidi.engine.algorithms" not in sys.modules:
        return entry["default_algorithms"], entry["algorithms"]
    from remidi.experiments import get_experiment

    exp = get_experiment(entry["name"])
    return list(exp.default_algorithms or exp.algorithms), list(exp.algorithms)


def _algo_help() -> str:
    """``remidi run --algo``'s help, read from the catalog when the help is printed: each
    experiment's default algorithms and what ``all`` adds."""
    from remidi.experiments import catalog

    groups: dict[tuple, list[str]] = {}  # (default algorithms, every algorithm, qualifier) → experiments
    for name, entry in catalog().items():
        default, every = _algorithms({**entry, "name": name})
        groups.setdefault((tuple(default), tuple(every), ""), []).append(name)
    # a user's task: what its level mutator, builder and solve criterion allow (custom.task_experiment's refusal)
    lever = catalog()["lever"]  # every algorithm of the library, as a task with a level builder has
    default, every = _algorithms({**lever, "name": "lever"})
    groups.setdefault((tuple(default), tuple(every), " that the task can run"), []).append("module:function")
    parts = []
    for (default, every, can), names in groups.items():
        extra = [a for a in every if a not in default]
        parts.append(f"{', '.join(names)}: {', '.join(default)}" + (f" (all adds {', '.join(extra)}{can})" if extra else ""))
    return ("algorithm, comma-separated list, or 'all' (every algorithm of the experiment); default: the "
            "experiment's default set — " + "; ".join(parts))


class _RunHelpFormatter(argparse.HelpFormatter):
    """``remidi run --help``: ``--algo``'s help from the registry (:func:`_algo_help`)."""

    def _get_help_string(self, action):
        return _algo_help() if action.dest == "algo" else super()._get_help_string(action)

def _cmd_solve(args) -> int:
    from remidi.solvers.report import solve_command

    print(solve_command(args.game, as_json=args.json,
                        log=lambda line: print(f"remidi: {line}", file=sys.stderr, flush=True)))
    return 0


def _format_value(value) -> str:
    """A configuration value as it would be written after ``--set key=``."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _print_networks() -> None:
    """The registered networks (``--set network=NAME``), one line each: what it reads and is."""
    from remidi.engine.core.networks import NETWORK_HELP, NETWORKS, reads

    print("  networks (--set network=NAME; what each reads, then what it is):")
    width = max(len(name) for name in NETWORKS)
    for name, cls in NETWORKS.items():
        print(f"    {name:<{width}}  reads {reads(cls)}" + (f"; {NETWORK_HELP[name]}" if NETWORK_HELP.get(name) else ""))


def _cmd_list(args) -> int:
    from remidi.experiments import catalog

    if not args.experiment:  # an overview, one line per experiment; the details of one: remidi list NAME
        width = max(len(name) for name in catalog())
        for name, entry in catalog().items():
            print(f"{name:<{width}}  {entry['description']} (presets: {', '.join(entry['presets'])})")
        print("remidi list NAME: its algorithms, scores, networks (what each reads), presets and --set keys", file=sys.stderr)
        return 0
    exp = _experiment(args.experiment, getattr(args, "task_args", []))
    from remidi.experiments.base import default_preset, resolve_config
    from remidi.experiments.overrides import field_names, get_value, key_help

    print(f"{exp.name}: {exp.description}")
    print(f"  algorithms: {', '.join(exp.algorithms)}"
          + (f" (default: {', '.join(exp.default_algorithms)}; --algo all: every one)" if exp.default_algorithms else ""))
    if exp.scores is not None:  # a UED experiment: the level scores of the PLR family its task can use
        print(f"  scores:     {', '.join(exp.scores(resolve_config(exp, default_preset(exp), {})))} (--set score=NAME)")
    if exp.make_task is not None:
        _print_networks()
    presets = ", ".join(f"{p} ({exp.preset_seeds[p]} seed{'s' if exp.preset_seeds[p] != 1 else ''})"
                        for p in exp.presets)
    print(f"  presets:    {presets}")
    for name, reasons in exp.preset_reasons.items():
        print(f"  {name}: deviates from paper in")
        width = max(len(key) for key in reasons)
        cfg = resolve_config(exp, name, {})
        for key, why in reasons.items():
            print(f"    {key:<{width}}  {_format_value(get_value(cfg, key))}: {why}")
    for note in exp.notes:
        print(f"  note: {note}")
    default = default_preset(exp)
    configs = {name: resolve_config(exp, name, {}) for name in exp.presets}
    print(f"  --set keys, each with its default (the {default} preset's; [another preset's] where it "
          f"differs) and meaning:")
    rows = []
    for key in field_names(exp.config_factory()):
        value = get_value(configs[default], key)
        others = [f"{name}: {_format_value(get_value(cfg, key))}" for name, cfg in configs.items()
                  if name != default and get_value(cfg, key) != value]
        rows.append((key, _format_value(value) + (f" [{', '.join(others)}]" if others else ""),
                     key_help(configs[default], key)))
    widths = [max(len(row[c]) for row in rows) for c in (0, 1)]
    for key, shown, meaning in rows:
        print(f"    {key:<{widths[0]}}  {shown:<{widths[1]}}  {meaning}".rstrip())
    return 0


def _undefined(x) -> bool:
    return x is None or x != x  # null in JSON, NaN in memory


def _mean_and_spread(m: dict) -> str:
    """``mean ± sample std`` of a summary entry; ``n/a`` for an undefined mean, the mean alone for
    one seed (no spread)."""
    if _undefined(m["mean"]):
        return f"{'n/a':>10s}"
    return f"{m['mean']:10.4f}" + ("" if _undefined(m["std"]) else f" ± {m['std']:.4f}")


def _print_metrics(metrics: dict[str, dict]) -> None:
    """One line per metric, ``name  mean ± std``, the values in one column however long the names."""
    width = max((len(name) for name in metrics), default=0)
    for name, m in metrics.items():
        print(f"  {name:<{width}} {_mean_and_spread(m)}")


def _print_summaries(summaries: dict[str, dict], out: Path) -> None:
    for algo, summary in summaries.items():
        n = len(summary["seeds"])
        print(f"\n{summary['experiment']} / {algo} ({summary['preset']}, {n} seed{'s' if n != 1 else ''}): final metrics")
        _print_metrics(summary["metrics"])
    print(f"\nwrote {out}")


def _reject_unknown_algos(name: str, text: str | None) -> None:
    """Refuse, from the catalog and before JAX is imported, ``--algo`` names no built-in
    experiment has, as :func:`~remidi.experiments.base.parse_algos` would; the rest it decides. Only
    while no algorithm can have been registered."""
    from remidi.experiments import catalog

    if text is None or "remidi.engine.algorithms" in sys.modules:
        return
    known = {algo for entry in catalog().values() for algo in entry["algorithms"]}
    for algo in (part.strip() for part in text.split(",")):
        if algo and algo != "all" and algo not in known:
            raise one_of("--algo", algo, catalog()[name]["algorithms"] + ["all"])


def _experiment(name: str, task_args: list[str]):
    """The experiment ``name`` names; a ``module:function`` task is called with the ``--task-arg``
    values (refused for a built-in experiment)."""
    from remidi.experiments import get_experiment

    if not task_args:
        return get_experiment(name)
    if ":" not in name:
        raise RemidiError(f"--task-arg: gives keyword arguments to a task's function (remidi run "
                          f"mypkg.tasks:make_task --task-arg size=9); {name} is a built-in experiment: use --set")
    from remidi.experiments.custom import import_experiment
    from remidi.experiments.task_args import parse_task_args

    return import_experiment(name, args=parse_task_args(task_args))


def _cmd_run(args) -> int:
    from remidi.experiments import saved_experiment
    from remidi.experiments.base import RunSpec, default_preset, parse_algos
    from remidi.experiments.resuming import resume_experiment
    from remidi.experiments.running import run_experiment
    from remidi.experiments.overrides import parse_set_items
    from remidi.loggers import parse_log

    for flag, value in (("--out", args.out), ("--resume", args.resume)):
        if value is not None and not value.strip():  # Path("") is the current folder: never what was meant
            raise RemidiError(f"{flag}: must name a folder, got {value!r}")
    if args.resume is not None:
        if (args.experiment is not None or args.algo or args.out is not None or args.sets or args.seeds is not None
                or args.seed is not None or args.preset is not None or args.devices is not None or args.log
                or args.task_args):
            raise RemidiError("--resume: takes only the run folder; its config.json says the rest")
        _RUN_DIR.append(Path(args.resume))
        from remidi.experiments.resuming import finished_run

        finished = finished_run(Path(args.resume))
        summaries = resume_experiment(saved_experiment, Path(args.resume), progress=not args.quiet)  # checks it
        if finished:  # resume_experiment trained nothing
            print(f"{args.resume}: the run is finished (summary.json written); nothing to resume "
                  f"(its results: remidi table {args.resume})")
            return 0
        _print_summaries(summaries, Path(args.resume))
        return 0
    if args.experiment is None:
        raise RemidiError("remidi run: name an experiment (see remidi list) or pass --resume DIR")
    if ":" not in args.experiment:  # a built-in experiment: its name and preset checked before JAX is imported
        from remidi.experiments import entry

        presets = entry(args.experiment)["presets"]
        if args.preset is not None and args.preset not in presets:
            raise one_of("--preset", args.preset, presets)
        _reject_unknown_algos(args.experiment, args.algo)
    for flag, value, least in (("--seeds", args.seeds, 1), ("--seed", args.seed, 0)):
        if value is not None and value < least:
            raise RemidiError(f"{flag}: must be an integer ≥ {least}, got {value}")
    exp = _experiment(args.experiment, args.task_args)
    algos = parse_algos(exp, args.algo)
    if args.preset is None:
        args.preset = default_preset(exp)
    if args.preset not in exp.presets:
        raise one_of("--preset", args.preset, exp.presets)
    num_seeds = args.seeds if args.seeds is not None else exp.preset_seeds[args.preset]
    first = 0 if args.seed is None else args.seed
    seeds = list(range(first, first + num_seeds))
    out = Path(args.out) if args.out is not None else Path("runs") / exp.name / time.strftime("%Y%m%d-%H%M%S")
    _RUN_DIR.append(out)
    log = parse_log(args.log)  # a missing package: one line naming the extra, before anything is written
    spec = RunSpec(exp, algos, args.preset, seeds, overrides=parse_set_items(args.sets),
                   devices=1 if args.devices is None else args.devices, log=log, argv=sys.argv[1:])
    summaries = run_experiment(spec, out, progress=not args.quiet)
    _print_summaries(summaries, out)
    return 0


def add_commands(sub) -> None:
    """The ``solve``, ``run`` and ``list`` sub-parsers."""
    solve = sub.add_parser("solve", help="exact MMR and BLP of a finite game file (JSON)",
                           description="Solve a finite game exactly: minimax-regret value, equilibrium "
                                       "adversary, and the BLP policy by iterated refinement.")
    solve.add_argument("game", help="game file (JSON; see examples/README.md for the formats)")
    solve.add_argument("--json", action="store_true", help="print machine-readable JSON")
    solve.set_defaults(func=_cmd_solve)

    run = sub.add_parser("run", help="run an experiment (see `remidi list`)", formatter_class=_RunHelpFormatter,
                         description="Train one or more algorithms on an experiment for several seeds and "
                                     "write config.json, metrics.csv, summary.json and plots.")
    run.add_argument("experiment", nargs="?", help="experiment name (see `remidi list`), or module:function returning your UEDTask "
                          "(imported as Python does: from the current folder first)")
    run.add_argument("--task-arg", dest="task_args", action="append", default=[], metavar="NAME=VALUE",
                     help="a keyword argument of the task's function, for a task given as module:function "
                          "(repeatable; the value read as JSON: 9, 0.5, true, null, else a string; recorded in "
                          "config.json, so --resume, evaluate and render rebuild the same task)")
    run.add_argument("--algo", help="algorithm, comma-separated list, or 'all' (default: the experiment's default set)")
    run.add_argument("--preset", help="smoke (minutes on a CPU), paper, or another of the experiment's presets "
                                      "(cpu, reference: remidi list EXPERIMENT); default: smoke (a task given "
                                      "as module:function: default, the engine's UEDConfig)")
    run.add_argument("--seeds", type=int, help="number of seeds (default: the preset's)")
    run.add_argument("--seed", type=int, help="first seed (default 0): seeds are SEED … SEED+N−1")
    run.add_argument("--out", help="output folder (default: runs/EXPERIMENT/TIMESTAMP); must not hold a run")
    run.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                     help="override a configuration value (repeatable; keys: `remidi list`)")
    run.add_argument("--devices", type=int, metavar="N",
                     help="shard the seeds over N devices (default 1; N must divide the number of seeds; "
                          "see docs/devices.md)")
    run.add_argument("--resume", metavar="DIR", help="continue the interrupted run in DIR (a user's task is "
                                                     "imported again from the folder config.json records)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--log", metavar="wandb,tensorboard", help="experiment tracking: Weights & Biases and/or "
                     "TensorBoard (pip install \"remidi[wandb]\" / \"remidi[tensorboard]\"); files under the run "
                     "folder, WANDB_MODE=offline works; --resume continues the same tracked runs")
    run.set_defaults(func=_cmd_run)

    lst = sub.add_parser("list", help="list experiments, algorithms, presets and config keys",
                         description="List the experiments, one line each; with EXPERIMENT, its algorithms, "
                                     "presets and --set keys (each with its default and what it means).")
    lst.add_argument("experiment", nargs="?", help="this experiment's details")
    lst.add_argument("--task-arg", dest="task_args", action="append", default=[], metavar="NAME=VALUE",
                     help="a keyword argument of the task's function (module:function; as remidi run's)")
    lst.set_defaults(func=_cmd_list)
