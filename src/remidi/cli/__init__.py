"""The ``remidi`` command line, one module per group of commands: :mod:`~remidi.cli.experiments`
(``solve``, ``run``, ``list``), :mod:`~remidi.cli.runs` (the commands reading run folders) and
:mod:`~remidi.cli.bench`; :mod:`~remidi.cli.common`: usage errors, Ctrl-C and SIGTERM.

Bad input never reaches JAX: every argument is validated first, reported as one line
``remidi: error: ...`` with exit status 2, before anything is written."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys

from remidi.cli import bench, experiments, runs
from remidi.cli.common import (_RUN_DIR, _install_sigint_handler, _interrupted_message, _Parser, _say,
                               _terminated_message, _write_failed_message)
from remidi.errors import RemidiError, callback_failure, debugging


def build_parser() -> argparse.ArgumentParser:
    from remidi import __version__

    parser = _Parser(prog="remidi", description="ReMiDi and Bayesian level-perfect minimax regret for UED.")
    parser.add_argument("--version", action="version", version=f"remidi {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    experiments.add_commands(sub)
    runs.add_commands(sub)
    bench.add_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The command line. Run as a program (``argv`` None), Ctrl-C exits at once with 130
    (:func:`remidi.cli.common._exit_on_sigint`) and SIGTERM with 143 after checkpointing a training
    run; with an ``argv`` list, KeyboardInterrupt is caught and 130 returned.

    Exit status: 0 done, 1 a failed write, 2 bad input, 130 Ctrl-C, 143 SIGTERM."""
    from remidi import preemption

    previous = _install_sigint_handler() if argv is None else {}
    if not debugging():  # JAX logs a failing callback's traceback itself; the error's one line says it
        logging.getLogger("jax._src.debugging").setLevel(logging.CRITICAL)
    parser = build_parser()
    _RUN_DIR.clear()
    preemption.reset()
    try:
        args = parser.parse_args(argv)
        if args.command in ("run", "evaluate", "render"):  # the commands that compile a run's programs
            from remidi import compile_cache

            compile_cache.enable()  # JAX's persistent cache, unless set otherwise (remidi.compile_cache)
        if args.command in ("run", "list", "evaluate", "render", "bench"):  # what may name a registered entry
            from remidi.plugins import load_plugins

            load_plugins()  # REMIDI_PLUGINS and the remidi.plugins entry points: docs/extending.md
        if args.command is None:
            parser.print_help()
            return 2
        return args.func(args)
    except RemidiError as err:
        _say(f"remidi: error: {err}")
        return 2
    except KeyboardInterrupt:
        _say(_interrupted_message())
        return 130
    except preemption.Preempted as stopped:  # SIGTERM while training: checkpointed at the end of a block
        _say(_terminated_message(stopped.done))
        return preemption.EXIT_STATUS
    except BrokenPipeError:  # `remidi list | head`: the reader has gone, which is no error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return 0
    except OSError as err:  # a full disk, a folder made read-only meanwhile: writes are atomic, nothing is lost
        _say(_write_failed_message(err))
        return 1
    except Exception as err:  # the user's code raised inside a compiled program (a JAX callback)
        failure = callback_failure(err)
        if failure is None or debugging():
            raise
        _say(f"remidi: error: {failure}")
        return 2
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
