"""The ``remidi`` command line: ``solve``, ``run``, ``list``, ``render``.

Bad input never reaches JAX: every argument is validated first and reported as one line
``remidi: error: ...`` with exit status 2, before anything is written.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from pathlib import Path

from remidi.errors import RemidiError


class _Parser(argparse.ArgumentParser):
    """argparse, but usage errors are one line and exit 2."""

    def error(self, message: str):  # noqa: D401
        command = self.prog.removeprefix("remidi").strip()  # "run" for `remidi run`; "" for `remidi` itself
        raise RemidiError(f"{command + ': ' if command else ''}{message} (see {self.prog} --help)")


def _algo_help() -> str:
    """``remidi run --algo``'s help, read from the registry when the help is printed (importing the
    experiments takes seconds, too long for every command): each experiment's default algorithms
    and what ``all`` adds."""
    from remidi.experiments import all_experiments
    from remidi.engine.algorithms import ALGORITHMS, PAPER_ALGORITHMS

    groups: dict[tuple, list[str]] = {}  # (default algorithms, every algorithm, qualifier) → experiments
    for exp in all_experiments().values():
        groups.setdefault((tuple(exp.default_algorithms or exp.algorithms), tuple(exp.algorithms), ""),
                          []).append(exp.name)
    # a user's task: what its level mutator and builder allow (custom.task_experiment's refusal)
    groups.setdefault((tuple(PAPER_ALGORITHMS), tuple(ALGORITHMS), " that the task can run"), []).append("module:function")
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


_RUN_DIR: list[Path] = []  # the folder of the run in progress, for the resume hint


def _write_failed_message(err: OSError) -> str:
    """One line for a failed write (``No space left on device``, ...): what failed, that the files
    written before are whole (every write is atomic), and how to continue a run."""
    what = f"{err.filename}: " if err.filename else ""
    return f"remidi: error: {what}{err.strerror or type(err).__name__}; files written before are intact" + _resume_hint()


def _resume_hint() -> str:
    """``; continue with: remidi run --resume DIR`` once the run folder in progress holds a
    resumable run (its config.json, or a sub-folder's), else nothing."""
    if not _RUN_DIR:
        return ""
    folder = Path(_RUN_DIR[-1])
    try:
        resumable = (folder / "config.json").exists() or any(folder.glob("*/config.json"))
    except OSError:
        resumable = False
    return f"; continue with: remidi run --resume {folder}" if resumable else ""


def _interrupted_message(what: str = "interrupted") -> str:
    """``remidi: interrupted`` (or ``what`` happened) and, once the run folder holds a resumable
    run, how to resume it."""
    return f"remidi: {what}" + _resume_hint()


def _terminated_message(checkpointed_at: int | None = None) -> str:
    """``remidi: terminated (SIGTERM)``, where the checkpoint stands, and how to resume."""
    written = f", checkpoint of update {checkpointed_at} written" if checkpointed_at is not None else ""
    return _interrupted_message(f"terminated (SIGTERM){written}")


def _exit_at_once(message: str, status: int) -> None:  # pragma: no cover - runs in a subprocess
    """Print ``message`` (on a line of its own after a progress bar) and end the process with
    ``status`` without unwinding: see :func:`_exit_on_sigint` for why that is safe."""
    try:
        sys.stdout.flush()
    except Exception:  # a print the signal cut short
        pass
    os.write(2, (("\n" if sys.stderr.isatty() else "") + message + "\n").encode())
    os._exit(status)


def _exit_on_sigint(signum, frame) -> None:  # pragma: no cover - runs in a subprocess (tests/test_interrupt.py)
    """Ctrl-C: print one line and exit with status 130 at once, wherever the interrupt lands.

    Raising KeyboardInterrupt (Python's default) is not safe while JAX imports, traces, compiles or
    runs: the exception can land in a callback that jaxlib calls (garbage-collection hooks: it is
    printed as "Exception ignored" and the run goes on) or unwind while XLA's threads still run
    (the interpreter then aborts at exit with "pure virtual method called", exit 134, or a
    segfault). Exiting at once is safe because every file a run writes is written atomically
    (temporary file, then rename): an interrupted run keeps its last complete checkpoint and
    ``remidi run --resume DIR`` continues from it.
    """
    _exit_at_once(_interrupted_message(), 130)


def _on_sigterm(signum, frame) -> None:  # pragma: no cover - runs in a subprocess (tests/test_interrupt.py)
    """SIGTERM (a scheduler's pre-emption notice, :mod:`remidi.preemption`): while a UED run
    trains, only recorded: the driver checkpoints the block under way and stops, and :func:`main`
    exits with status 143. Anywhere else, one line and exit 143 at once, as Ctrl-C does with 130
    (:func:`_exit_on_sigint`: the last checkpoint is whole, nothing newer exists)."""
    from remidi import preemption

    if not preemption.request():
        _exit_at_once(_terminated_message(), preemption.EXIT_STATUS)


def _install_sigint_handler():
    """Install :func:`_exit_on_sigint` (SIGINT) and :func:`_on_sigterm` (SIGTERM) when this process
    runs the command line (not when a host such as pytest or a notebook has its own handling, or
    ignores the signal); returns the handlers to restore, {signal: previous handler}."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous = {}
    for signum, default, handler in ((signal.SIGINT, signal.default_int_handler, _exit_on_sigint),
                                     (signal.SIGTERM, signal.SIG_DFL, _on_sigterm)):
        if signal.getsignal(signum) is default:
            previous[signum] = default
            signal.signal(signum, handler)
    return previous


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


def _cmd_list(args) -> int:
    from remidi.experiments import all_experiments, get_experiment
    from remidi.experiments.base import default_preset, resolve_config
    from remidi.experiments.config import field_names, get_value, key_help

    if not args.experiment:  # an overview, one line per experiment; the details of one: remidi list NAME
        experiments = list(all_experiments().values())
        width = max(len(exp.name) for exp in experiments)
        for exp in experiments:
            print(f"{exp.name:<{width}}  {exp.description} (presets: {', '.join(exp.presets)})")
        print("remidi list NAME: its algorithms, presets and --set keys", file=sys.stderr)
        return 0
    exp = get_experiment(args.experiment)
    print(f"{exp.name}: {exp.description}")
    print(f"  algorithms: {', '.join(exp.algorithms)}"
          + (f" (default: {', '.join(exp.default_algorithms)}; --algo all: every one)" if exp.default_algorithms else ""))
    if exp.make_task is not None:  # a UED experiment: the level scores of the PLR family
        from remidi.engine.adversaries.scores import SCORES

        print(f"  scores:     {', '.join(SCORES)} (--set score=NAME)")
    presets = ", ".join(f"{p} ({exp.preset_seeds[p]} seed{'s' if exp.preset_seeds[p] != 1 else ''})"
                        for p in exp.presets)
    print(f"  presets:    {presets}")
    for name, reasons in exp.preset_reasons.items():
        print(f"  {name}: deviates from paper in")
        width = max(len(key) for key in reasons)
        cfg = resolve_config(exp, name, {})
        for key, why in reasons.items():
            print(f"    {key:<{width}}  {_format_value(get_value(cfg, key))}: {why}")
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


def _cmd_run(args) -> int:
    from remidi.experiments import get_experiment, saved_experiment
    from remidi.experiments.base import default_preset, parse_algos, resume_experiment, run_experiment
    from remidi.experiments.config import parse_set_items
    from remidi.experiments.tracking import parse_log

    for flag, value in (("--out", args.out), ("--resume", args.resume)):
        if value is not None and not value.strip():  # Path("") is the current folder: never what was meant
            raise RemidiError(f"{flag}: must name a folder, got {value!r}")
    if args.resume is not None:
        if (args.experiment is not None or args.algo or args.out is not None or args.sets or args.seeds is not None
                or args.seed is not None or args.preset is not None or args.devices is not None or args.log):
            raise RemidiError("--resume: takes only the run folder; its config.json says the rest")
        _RUN_DIR.append(Path(args.resume))
        from remidi.experiments.base import finished_run

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
    exp = get_experiment(args.experiment)
    algos = parse_algos(exp, args.algo)
    if args.preset is None:
        args.preset = default_preset(exp)
    if args.preset not in exp.presets:
        from remidi.errors import one_of

        raise one_of("--preset", args.preset, exp.presets)
    num_seeds = args.seeds if args.seeds is not None else exp.preset_seeds[args.preset]
    if num_seeds < 1:
        raise RemidiError(f"--seeds: must be an integer ≥ 1, got {num_seeds}")
    first = 0 if args.seed is None else args.seed
    if first < 0:
        raise RemidiError(f"--seed: must be an integer ≥ 0, got {first}")
    seeds = list(range(first, first + num_seeds))
    out = Path(args.out) if args.out is not None else Path("runs") / exp.name / time.strftime("%Y%m%d-%H%M%S")
    _RUN_DIR.append(out)
    log = parse_log(args.log)  # a missing package: one line naming the extra, before anything is written
    summaries = run_experiment(exp, algos=algos, preset=args.preset, seeds=seeds,
                               overrides=parse_set_items(args.sets), out=out, progress=not args.quiet,
                               argv=sys.argv[1:], devices=1 if args.devices is None else args.devices, log=log)
    _print_summaries(summaries, out)
    return 0


def _cmd_render(args) -> int:
    from remidi import render

    if args.what == "maze":
        print(f"wrote {render.render_maze(args.name, out=args.out, tile=args.tile)}")
    elif args.what == "buffers":
        path = render.render_buffers(args.run_dir, top=args.top, seed=args.seed, out=args.out, tile=args.tile)
        print(f"wrote {path}")
    elif args.what == "episode":
        episode = render.render_episode(args.run_dir, args.maze, seed=args.seed, attempt_seed=args.attempt_seed,
                                        goal_index=args.goal_index, out=args.out, tile=args.tile)
        print(episode.line())
    else:
        raise RemidiError("remidi render: say what to draw: maze, buffers or episode (see remidi render --help)")
    return 0


def _cmd_evaluate(args) -> int:
    from remidi.evaluate import run_from_args

    doc = run_from_args(args)
    for algo, entry in doc["algorithms"].items():
        n = len(entry["seeds"])
        print(f"\n{algo} ({n} seed{'s' if n != 1 else ''}, checkpoint of update {entry['update']})")
        _print_metrics(entry["metrics"])
    print(f"\nwrote {Path(args.run_dir) / 'evaluate.json'}, evaluate.csv, evaluate.png")
    return 0


def _cmd_table(args) -> int:
    from remidi.experiments.table import markdown_table, summaries

    metrics = [m.strip() for m in args.metrics.split(",") if m.strip()] if args.metrics else None
    print(markdown_table(summaries(args.runs), metrics, args.last))
    _note_unfinished(args.runs)
    return 0


def _note_unfinished(runs) -> None:
    """A note per algorithm of a several-algorithm run left out for want of a summary.json."""
    from remidi.experiments.table import unfinished

    for folder, resume in unfinished(runs):
        print(f"remidi: note: {folder} is left out: unfinished (no summary.json; remidi run --resume "
              f"{resume} finishes it)", file=sys.stderr)


def _cmd_status(args) -> int:
    from remidi.experiments.status import run_folders, run_status

    for folder in run_folders(args.runs):
        print("\n".join(run_status(folder)))
    return 0


def _cmd_compare(args) -> int:
    from remidi.experiments.compare import compare_runs, format_comparison, plot_comparison
    from remidi.experiments.table import summaries

    if args.out is not None and Path(args.out).suffix.lower() != ".png":
        raise RemidiError(f"--out: must be a .png file, got {args.out!r}")
    result = compare_runs(summaries(args.runs), args.metric, args.algo, args.baseline, paired=args.paired,
                          last=args.last)
    print(format_comparison(result))
    _note_unfinished(args.runs)
    if args.out is not None:
        plot_comparison(result, Path(args.out))
        print(f"\nwrote {args.out}")
    return 0


def _cmd_bench(args) -> int:
    import json

    from remidi.bench import BENCHMARKS, DEFAULT, format_table, run_benchmarks

    names = args.names or list(DEFAULT)
    for name in names:
        if name not in BENCHMARKS:
            from remidi.errors import one_of

            raise one_of("remidi bench: NAME", name, list(BENCHMARKS))
    if args.repeats < 1:
        raise RemidiError(f"--repeats: must be an integer ≥ 1, got {args.repeats}")
    import os

    cores = len(os.sched_getaffinity(0))
    if not 1 <= args.lanes <= cores:
        raise RemidiError(f"--lanes: must be an integer in [1, {cores}] (this machine's cores), got {args.lanes}")
    if args.seeds < 1:
        raise RemidiError(f"--seeds: must be an integer ≥ 1, got {args.seeds}")
    from remidi.bench import check_overrides
    from remidi.experiments.config import parse_set_items

    overrides = parse_set_items(args.sets)
    check_overrides(overrides)
    doc = run_benchmarks(names, args.repeats, log=sys.stderr, tiny=args.tiny, overrides=overrides, lanes=args.lanes,
                         seeds=args.seeds)
    print(json.dumps(doc, indent=2) if args.json else format_table(doc))
    return 0


def build_parser() -> argparse.ArgumentParser:
    from remidi import __version__

    parser = _Parser(prog="remidi", description="ReMiDi and Bayesian level-perfect minimax regret for UED.")
    parser.add_argument("--version", action="version", version=f"remidi {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

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
    lst.set_defaults(func=_cmd_list)

    render = sub.add_parser("render", help="draw held-out mazes, a run's level buffers, or an episode",
                            description="Draw a held-out maze (PNG), the top-scored levels of each level buffer "
                                        "of a maze run's checkpoint (PNG), or the checkpoint's agent playing one "
                                        "episode on a held-out maze (animated GIF).")
    what = render.add_subparsers(dest="what", metavar="WHAT", parser_class=_Parser)
    tile = dict(type=int, default=16, help="pixels per maze cell (default 16)")
    maze = what.add_parser("maze", help="a held-out maze (every goal placement of a corridor maze)",
                           description="Draw a held-out maze as a PNG; the corridor mazes get one tile per "
                                       "goal placement.")
    maze.add_argument("name", metavar="NAME", help="held-out maze name (e.g. SixteenRooms, SmallCorridor)")
    maze.add_argument("--out", metavar="FILE.png", help="output file (default: NAME.png in the current folder)")
    maze.add_argument("--tile", **tile)
    buffers = what.add_parser("buffers", help="the top-scored levels of each level buffer of a maze run",
                              description="Draw the top-K scored levels of every level buffer in RUN_DIR's "
                                          "checkpoint, one row per buffer (the active one marked), each titled "
                                          "with its score and tags.")
    run_dir = "a tmaze or blindfold run folder (config.json, checkpoint.npz)"
    buffers.add_argument("run_dir", metavar="RUN_DIR", help=run_dir)
    buffers.add_argument("--top", type=int, default=8, help="levels per buffer (default 8)")
    buffers.add_argument("--seed", type=int, help="which of the run's seeds (default: its first)")
    buffers.add_argument("--out", metavar="FILE.png", help="output file (default: RUN_DIR/buffers_seed<S>.png)")
    buffers.add_argument("--tile", **tile)
    episode = what.add_parser("episode", help="the trained agent playing one episode on a held-out maze (GIF)",
                              description="Play one episode (at most 250 steps) of RUN_DIR's checkpointed agent "
                                          "on a held-out maze and save it as an animated GIF showing the agent "
                                          "and its 5x5 view.")
    episode.add_argument("run_dir", metavar="RUN_DIR", help=run_dir)
    episode.add_argument("--maze", required=True, metavar="NAME", help="held-out maze name")
    episode.add_argument("--seed", type=int, help="which of the run's seeds (default: its first)")
    episode.add_argument("--attempt-seed", type=int, default=0, help="seed of the sampled actions (default 0)")
    episode.add_argument("--goal-index", type=int, help="goal placement of a corridor maze (default 0)")
    episode.add_argument("--out", metavar="FILE.gif", help="output file (default: RUN_DIR/episode_<NAME>_seed<S>.gif)")
    episode.add_argument("--tile", **tile)
    render.set_defaults(func=_cmd_render)

    evaluate = sub.add_parser("evaluate", help="a UED run's agents on more levels: held-out sets, CVaR over the "
                                               "generator, larger perfect mazes",
                              description="Reload every seed and algorithm of a UED run from its checkpoint and "
                                          "evaluate it; writes RUN_DIR/evaluate.json, evaluate.csv, evaluate.png.")
    from remidi.evaluate import main_args

    main_args(evaluate)
    evaluate.set_defaults(func=_cmd_evaluate)

    table = sub.add_parser("table", help="a Markdown table of finished runs (mean ± sample std, IQM, 95%% CI "
                                         "over seeds)",
                           description="One row per experiment × algorithm of the given run folders (each "
                                       "with summary.json, or with one sub-folder per algorithm); per metric "
                                       "the mean ± sample standard deviation over seeds (ddof 1), the "
                                       "interquartile mean and the 95% percentile-bootstrap interval of the mean.")
    table.add_argument("runs", nargs="+", metavar="RUN", help="finished run folders")
    table.add_argument("--metrics", metavar="M1,M2", help="metrics to show (default: per experiment, its first "
                                                         "metric and level shares replay_fraction/TAG, "
                                                         "buffer_fraction/TAG; else its first three)")
    table.add_argument("--last", type=int, metavar="K", help="per seed, the mean of each metric's last K logged "
                                                            "points (metrics.csv) instead of its final value")
    table.set_defaults(func=_cmd_table)

    compare = sub.add_parser("compare", help="an algorithm against a baseline on one metric: probability of "
                                             "improvement, permutation p-value, interval plot",
                             description="For each experiment in the given run folders: both algorithms' "
                                         "per-seed mean ± sample std, IQM and 95% bootstrap intervals, the "
                                         "probability of improvement P(ALGO > BASELINE) with its 95% bootstrap "
                                         "interval, and the exact one-sided permutation p-value of ALGO's mean "
                                         "being higher (Holm-adjusted over several experiments).")
    compare.add_argument("runs", nargs="+", metavar="RUN", help="finished run folders")
    compare.add_argument("--metric", required=True, metavar="M", help="the metric compared (a summary.json key)")
    compare.add_argument("--algo", required=True, metavar="A", help="the algorithm claimed better")
    compare.add_argument("--baseline", required=True, metavar="B", help="the algorithm it is compared with")
    compare.add_argument("--paired", action="store_true", help="pair the two algorithms' runs by seed (both "
                                                               "must have the same seeds)")
    compare.add_argument("--last", type=int, metavar="K", help="per seed, the mean of the metric's last K logged "
                                                              "points (metrics.csv) instead of its final value")
    compare.add_argument("--out", metavar="FIG.png", help="also draw the interval plot into FIG.png")
    compare.set_defaults(func=_cmd_compare)

    status = sub.add_parser("status", help="where runs stand: finished, or the update of their last checkpoint, "
                                           "the time left, stalled seeds",
                            description="Read run folders without loading a model: finished (summary.json; "
                                        "evaluated or not) or the update of the last checkpoint and when it was "
                                        "written, each part's updates, device and seconds per update, the time "
                                        "left at the last part's rate, and the updates in which a seed trained "
                                        "on nothing while a frozen adversary rejected levels.")
    status.add_argument("runs", nargs="+", type=Path, metavar="RUN_DIR",
                        help="run folders, or a several-algorithm run's folder")
    status.set_defaults(func=_cmd_status)

    from remidi.bench import BENCHMARKS, DEFAULT

    others = [name for name in BENCHMARKS if name not in DEFAULT]
    bench = sub.add_parser("bench", help="throughput benchmarks (env-steps/s, compile time, memory)",
                           description="Time named workloads, each in a fresh process after compiling and "
                                       "warming up (median of --repeats calls), and the ratios between them. "
                                       f"Benchmarks: {', '.join(DEFAULT)} (the default set), {', '.join(others)}.")
    bench.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: the default set)")
    bench.add_argument("--json", action="store_true", help="print only the JSON document (progress on stderr)")
    bench.add_argument("--repeats", type=int, default=3, help="timed calls per benchmark (default 3)")
    bench.add_argument("--tiny", action="store_true", help="toy sizes: checks the tool in seconds, figures meaningless")
    bench.add_argument("--lanes", type=int, default=1, metavar="N",
                       help="also run each benchmark as N processes at once, each pinned to one core with XLA on "
                            "one thread, and report their total against one process on every core (default 1: off)")
    bench.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                       help="override a UED config key in every training workload (e.g. num_envs=64, "
                            "remidi.buffer_capacity=64; num_envs and num_steps also apply to maze-env)")
    bench.add_argument("--seeds", type=int, default=1, metavar="N",
                       help="train N seeds together in every training workload (vmapped, as a run of N seeds "
                            "does; default 1: the one-seed program)")
    bench.set_defaults(func=_cmd_bench)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The command line. Run as a program (``argv`` None: the ``remidi`` script, ``python -m
    remidi``), Ctrl-C exits at once with status 130 (:func:`_exit_on_sigint`) and SIGTERM with
    143 after checkpointing a run in training (:func:`_on_sigterm`); called with an ``argv`` list,
    KeyboardInterrupt is caught and 130 returned.

    Exit status: 0 done, 1 a failed write, 2 bad input, 130 Ctrl-C, 143 SIGTERM (resume the run
    with ``remidi run --resume DIR``)."""
    from remidi import preemption

    previous = _install_sigint_handler() if argv is None else {}
    parser = build_parser()
    _RUN_DIR.clear()
    preemption.reset()
    try:
        args = parser.parse_args(argv)
        if args.command in ("run", "list", "evaluate", "render", "bench"):  # what may name a registered entry
            from remidi.plugins import load_plugins

            load_plugins()  # REMIDI_PLUGINS and the remidi.plugins entry points: docs/extending.md
        if args.command is None:
            parser.print_help()
            return 2
        return args.func(args)
    except RemidiError as err:
        print(f"remidi: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(_interrupted_message(), file=sys.stderr)
        return 130
    except preemption.Preempted as stopped:  # SIGTERM while training: checkpointed at the end of a block
        print(_terminated_message(stopped.done), file=sys.stderr)
        return preemption.EXIT_STATUS
    except BrokenPipeError:  # `remidi list | head`: the reader has gone, which is no error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    except OSError as err:  # a full disk, a folder made read-only meanwhile: writes are atomic, nothing is lost
        print(_write_failed_message(err), file=sys.stderr)
        return 1
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


if __name__ == "__main__":
    sys.exit(main())
