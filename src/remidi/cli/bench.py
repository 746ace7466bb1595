"""``remidi bench``: throughput benchmarks (:mod:`remidi.bench`)."""

from __future__ import annotations

import sys

from remidi.errors import RemidiError


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
    from remidi.experiments.overrides import parse_set_items

    overrides = parse_set_items(args.sets)
    check_overrides(overrides)
    doc = run_benchmarks(names, args.repeats, log=sys.stderr, tiny=args.tiny, overrides=overrides, lanes=args.lanes,
                         seeds=args.seeds)
    print(json.dumps(doc, indent=2) if args.json else format_table(doc))
    return 0


def add_commands(sub) -> None:
    """The ``bench`` sub-parser."""
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
