"""SIGTERM, the notice a cluster scheduler (SLURM, Kubernetes, most batch systems) sends before it
pre-empts or time-limits a job: ``remidi run`` checkpoints and exits with :data:`EXIT_STATUS`.

The command line's SIGTERM handler (``remidi.cli``) asks :func:`request`. While a UED run is
training (:func:`checkpointing`, entered by the driver once its first block is compiled and
dispatched), the request is only recorded: the driver finishes the block under way,
writes a checkpoint of it (whatever ``checkpoint_every`` says) and raises :class:`Preempted`, which
the command line reports as one line with the resume hint and exit status 143. Anywhere else
(start-up, compiling, writing the results of a finished algorithm) nothing newer than the last
checkpoint exists, and the handler exits at once with 143, as Ctrl-C does with 130.

143 = 128 + 15 (SIGTERM), the status a shell reports for a process killed by SIGTERM, so a
requeue script can tell a pre-emption (143: ``remidi run --resume DIR``) from a failure (1, 2)
or a finished run (0). docs/devices.md has a SLURM array script.
"""

from __future__ import annotations

from contextlib import contextmanager

EXIT_STATUS = 143  # 128 + SIGTERM

_state = {"requested": False, "training": 0}


class Preempted(Exception):
    """The run stopped after a SIGTERM, its checkpoint written at update ``done`` (None: it
    stopped before training, e.g. the next algorithm of a run after the one that was training
    when the signal came finished)."""

    def __init__(self, done: int | None):
        super().__init__("stopped by SIGTERM" + (f" after update {done}, checkpoint written" if done is not None else ""))
        self.done = done


def request() -> bool:
    """Record a SIGTERM. True if a run in training will checkpoint and stop at the end of its
    block (:func:`checkpointing`); False if nothing can be checkpointed now (exit at once)."""
    _state["requested"] = True
    return _state["training"] > 0


def requested() -> bool:
    return _state["requested"]


def reset() -> None:
    _state["requested"] = False
    _state["training"] = 0


@contextmanager
def checkpointing():
    """Within: a SIGTERM is answered by the caller's checkpoint at the end of its block
    (it checks :func:`requested` after each block and raises :class:`Preempted`)."""
    _state["training"] += 1
    try:
        yield
    finally:
        _state["training"] -= 1
