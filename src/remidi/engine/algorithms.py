"""UED algorithms as data: what each one does in the shared train step (:mod:`remidi.engine.train`).

The train step, the driver and the tools read an :class:`Algorithm`'s fields, never its name, so
an algorithm is added by describing it here (and, if it needs a new kind of stage, by adding that
stage to the train step once, for every algorithm and domain). ``docs/extending.md`` walks
through one.
"""

from __future__ import annotations

from dataclasses import dataclass

from remidi.errors import one_of


@dataclass(frozen=True)
class Algorithm:
    """One UED algorithm (hashable: part of the static set-up of a compiled train step).

    name: what ``--algo`` calls it.
    replays: keeps a level buffer and, with probability ``buffer.replay_prob`` once it holds
        enough levels, replays levels from it instead of generating fresh ones (the PLR family).
        False: every update plays fresh levels from the generator (DR).
    trains_on_fresh: PPO learns from rollouts on fresh levels too. Robust PLR⊥ and its relatives
        learn only from replays (a fresh level is only scored and offered to the buffer).
    score: the level score it always uses (``minimax-return``: ``neg_return``); None: the config's
        ``score``.
    buffer_sequence: ReMiDi's refinement: a sequence of ``remidi.num_buffers`` buffers, switched
        after ``remidi.steps_per_buffer``; earlier buffers are frozen, a fresh level whose rollout a
        frozen level explains at every step is rejected, and PPO's loss is masked on the steps a
        frozen level explains.
    edits: ACCEL's editing: the update after a replay edits the levels it replayed with the task's
        mutator (``UEDTask.mutate_level``, ``accel.num_edits`` edits each), rolls them out, scores
        them and offers them to the buffer like fresh levels, without training on them. Edited
        levels are new levels: with a buffer sequence, one a frozen level explains is rejected.
    description: one line for ``remidi list`` and the docs.
    """

    name: str
    replays: bool
    trains_on_fresh: bool
    score: str | None = None
    buffer_sequence: bool = False
    edits: bool = False
    description: str = ""

    def score_name(self, configured: str) -> str:
        """The score this algorithm ranks levels by, given the config's ``score``."""
        return self.score or configured


DR = Algorithm("dr", replays=False, trains_on_fresh=True,
               description="domain randomisation: fresh random levels every update")
PLR = Algorithm("plr", replays=True, trains_on_fresh=False,
                description="robust prioritized level replay (PLR⊥): replays high-score levels, trains only on replays")
MINIMAX_RETURN = Algorithm("minimax-return", replays=True, trains_on_fresh=False, score="neg_return",
                           description="PLR⊥ scored by negative return (a minimax adversary)")
REMIDI = Algorithm("remidi", replays=True, trains_on_fresh=False, buffer_sequence=True,
                   description="ReMiDi: PLR⊥ with a sequence of buffers; levels an earlier buffer explains are rejected")

ACCEL = Algorithm("accel", replays=True, trains_on_fresh=False, edits=True,
                  description="ACCEL: PLR⊥ whose replayed levels are edited, and the edits offered to the buffer")
REMIDI_ACCEL = Algorithm("remidi-accel", replays=True, trains_on_fresh=False, buffer_sequence=True, edits=True,
                         description="ReMiDi over ACCEL: ACCEL's edits are new levels for ReMiDi's buffer sequence")

#: every algorithm ``--algo`` accepts, by name, in the order the docs and plots list them
ALGORITHMS: dict[str, Algorithm] = {a.name: a for a in (DR, PLR, MINIMAX_RETURN, REMIDI, ACCEL, REMIDI_ACCEL)}
#: the algorithms of the paper's comparisons: what ``remidi run`` trains when ``--algo`` is not given
PAPER_ALGORITHMS = ("dr", "plr", "minimax-return", "remidi")


def get_algorithm(algo: str | Algorithm, key: str = "--algo") -> Algorithm:
    """The algorithm named ``algo`` (an :class:`Algorithm` is returned as it is); ConfigError
    naming ``key`` and the allowed names otherwise."""
    if isinstance(algo, Algorithm):
        return algo
    if algo not in ALGORITHMS:
        raise one_of(key, algo, ALGORITHMS)
    return ALGORITHMS[algo]
