"""What every ``remidi`` command shares: one-line usage errors (:class:`_Parser`), and how a
command ends on Ctrl-C, SIGTERM or a failed write (the messages, the signal handlers, and the
folder of the run in progress that a resume hint names)."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from pathlib import Path

from remidi.errors import RemidiError


class _Parser(argparse.ArgumentParser):
    """argparse, but usage errors are one line and exit 2."""

    def error(self, message: str):  # noqa: D401
        command = self.prog.removeprefix("remidi").strip()  # "run" for `remidi run`; "" for `remidi` itself
        raise RemidiError(f"{command + ': ' if command else ''}{message} (see {self.prog} --help)")


_RUN_DIR: list[Path] = []  # the folder of the run in progress, for the resume hint


def _write_failed_message(err: OSError) -> str:
    """One line for a failed write: what failed, that earlier files are whole (writes are atomic),
    and how to continue a run."""
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
    """``remidi: interrupted`` (or ``what`` happened), with :func:`_resume_hint`."""
    return f"remidi: {what}" + _resume_hint()


def _terminated_message(checkpointed_at: int | None = None) -> str:
    """``remidi: terminated (SIGTERM)``, where the checkpoint stands, and how to resume."""
    written = f", checkpoint of update {checkpointed_at} written" if checkpointed_at is not None else ""
    return _interrupted_message(f"terminated (SIGTERM){written}")


def _open_bars() -> list:
    """The progress bars (tqdm) still open in this process: a run that stopped leaves its own."""
    tqdm = sys.modules.get("tqdm")
    return list(getattr(getattr(tqdm, "tqdm", None), "_instances", None) or [])


def _say(line: str) -> None:
    """Print ``line`` on stderr on a line of its own, closing an open progress bar first."""
    for bar in _open_bars():
        bar.close()
    print(line, file=sys.stderr)


def _exit_at_once(message: str, status: int) -> None:  # pragma: no cover - runs in a subprocess
    """Print ``message`` on its own line and end the process with ``status`` without unwinding
    (safe: :func:`_exit_on_sigint`)."""
    try:
        sys.stdout.flush()
    except Exception:  # a print the signal cut short
        pass
    os.write(2, (("\n" if sys.stderr.isatty() or _open_bars() else "") + message + "\n").encode())
    os._exit(status)


def _exit_on_sigint(signum, frame) -> None:  # pragma: no cover - runs in a subprocess (tests/test_interrupt.py)
    """Ctrl-C: print one line and exit with status 130 at once, wherever the interrupt lands.

    KeyboardInterrupt is not safe while JAX imports, traces, compiles or runs: it can land in a
    jaxlib callback ("Exception ignored", the run goes on) or unwind while XLA's threads run (an
    abort at exit, exit 134, or a segfault). Exiting at once is safe because every run file is
    written atomically: the last complete checkpoint stays and ``--resume`` continues from it."""
    _exit_at_once(_interrupted_message(), 130)


def _on_sigterm(signum, frame) -> None:  # pragma: no cover - runs in a subprocess (tests/test_interrupt.py)
    """SIGTERM (a scheduler's pre-emption, :mod:`remidi.preemption`): while a UED run trains, only
    recorded (the driver checkpoints the block and stops; :func:`main` exits 143); anywhere else one
    line and exit 143 at once, as :func:`_exit_on_sigint` does."""
    from remidi import preemption

    if not preemption.request():
        _exit_at_once(_terminated_message(), preemption.EXIT_STATUS)


def _install_sigint_handler():
    """Install :func:`_exit_on_sigint` and :func:`_on_sigterm` when this process runs the command
    line (not under a host with its own handling, or ignoring the signal); returns {signal: previous
    handler} to restore."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous = {}
    for signum, default, handler in ((signal.SIGINT, signal.default_int_handler, _exit_on_sigint),
                                     (signal.SIGTERM, signal.SIG_DFL, _on_sigterm)):
        if signal.getsignal(signum) is default:
            previous[signum] = default
            signal.signal(signum, handler)
    return previous
