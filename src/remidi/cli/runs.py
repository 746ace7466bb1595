"""The commands that read run folders: ``remidi render``, ``evaluate``, ``table``, ``status``
and ``compare`` (their work is done in :mod:`remidi.runs`)."""

from __future__ import annotations

import sys
from pathlib import Path

from remidi.cli.common import _Parser
from remidi.cli.experiments import _print_metrics
from remidi.errors import RemidiError
from remidi.runs import require_folder


def _cmd_render(args) -> int:
    from remidi.runs import render

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
    require_folder("RUN_DIR", args.run_dir)  # before the imports below, which take seconds
    from remidi.runs.evaluate import files_stem, run_from_args

    doc = run_from_args(args)
    for algo, entry in doc["algorithms"].items():
        n = len(entry["seeds"])
        print(f"\n{algo} ({n} seed{'s' if n != 1 else ''}, checkpoint of update {entry['update']})")
        _print_metrics(entry["metrics"])
    stem = files_stem(args.action)
    print(f"\nwrote {Path(args.run_dir) / stem}.json, {stem}.csv, {stem}.png")
    return 0


def _cmd_table(args) -> int:
    for folder in args.runs:
        require_folder("RUN", folder)
    from remidi.runs.table import markdown_table, summaries

    metrics = [m.strip() for m in args.metrics.split(",") if m.strip()] if args.metrics else None
    print(markdown_table(summaries(args.runs), metrics, args.last))
    _note_unfinished(args.runs)
    return 0


def _note_unfinished(runs) -> None:
    """A note per algorithm of a several-algorithm run left out for want of a summary.json."""
    from remidi.runs.table import unfinished

    for folder, resume in unfinished(runs):
        print(f"remidi: note: {folder} is left out: unfinished (no summary.json; remidi run --resume "
              f"{resume} finishes it)", file=sys.stderr)


def _cmd_status(args) -> int:
    for folder in args.runs:
        require_folder("RUN_DIR", folder)
    from remidi.runs.status import run_folders, run_status

    for folder in run_folders(args.runs):
        print("\n".join(run_status(folder)))
    return 0


def _cmd_compare(args) -> int:
    from remidi.runs.compare import compare_runs, format_comparison, plot_comparison
    from remidi.runs.table import summaries

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


def add_commands(sub) -> None:
    """The ``render``, ``evaluate``, ``table``, ``compare`` and ``status`` sub-parsers."""
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
                                          "evaluate it; writes RUN_DIR/evaluate.json, evaluate.csv, evaluate.png "
                                          "(evaluate-mode.* with --action mode).")
    from remidi.runs.evaluate import main_args

    main_args(evaluate)
    evaluate.set_defaults(func=_cmd_evaluate)

    table = sub.add_parser("table", help="a Markdown table of finished runs (mean ± sample std, IQM, 95%% CI "
                                         "over seeds)",
                           description="One row per experiment × algorithm of the given run folders (each "
                                       "with summary.json, or with one sub-folder per algorithm); per metric "
                                       "the mean ± sample standard deviation over seeds (ddof 1), the "
                                       "interquartile mean and the 95% percentile-bootstrap interval of the mean.")
    table.add_argument("runs", nargs="+", metavar="RUN", help="finished run folders")
    table.add_argument("--metrics", metavar="M1,M2", help="metrics to show (default: per experiment, every "
                                                         "evaluation set's solve rate, or return, unless its "
                                                         "first metric sums them up (solve_rate/mean), and level "
                                                         "shares replay_fraction/TAG, buffer_fraction/TAG; else its "
                                                         "first three)")
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
