"""UED algorithms as data: an adversary (:mod:`remidi.engine.adversaries.base`) and a score.

The train step calls the adversary, never the algorithm's name or a flag, so a new kind of
adversary is a new implementation of that protocol, once for every domain (``docs/extending.md``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from remidi.engine.adversaries.accel import EditingBuffers
from remidi.engine.adversaries.base import Adversary, RandomLevels
from remidi.engine.adversaries.paired import GeneratorSequence, LevelGenerator
from remidi.engine.adversaries.plr import LevelBuffers
from remidi.engine.adversaries.scores import SCORES
from remidi.engine.adversaries.sfl import LearnabilityBuffers
from remidi.errors import ConfigError, check_name, one_of


@dataclass(frozen=True)
class Algorithm:
    """One UED algorithm (hashable: part of the compiled train step's static set-up).

    name: what ``--algo`` calls it.
    adversary: where its levels come from and what becomes of them (an
        :class:`~remidi.engine.adversaries.base.Adversary`; ``buffer_sequence=True``: ReMiDi's
        sequence); its ``trains_on_fresh``: PPO learns from fresh levels too (PLR⊥ does not).
    score: the score it always uses (``minimax-return``: ``neg_return``); None: the config's ``score``.
    description: one line for ``remidi list`` and the docs."""

    name: str
    adversary: Adversary
    score: str | None = None
    description: str = ""

    def __post_init__(self):
        if not isinstance(self.adversary, Adversary):
            raise ConfigError(f"algorithm {self.name}: adversary must be a remidi.engine.adversaries.base adversary "
                              f"(an Adversary: RandomLevels, LevelBuffers, EditingBuffers, LevelGenerator, GeneratorSequence or "
                              f"LearnabilityBuffers), "
                              f"got {type(self.adversary).__name__}")

    def score_name(self, configured: str) -> str:
        """The score this algorithm ranks levels by, given the config's ``score``."""
        return self.score or configured

    # what the tools ask of an algorithm, read off its adversary
    @property
    def replays(self) -> bool:
        """It keeps level buffers and replays from them (the PLR family)."""
        return isinstance(self.adversary, LevelBuffers)

    @property
    def buffer_sequence(self) -> bool:
        """ReMiDi's sequence of buffers."""
        return getattr(self.adversary, "buffer_sequence", False)

    @property
    def edits(self) -> bool:
        """ACCEL's editing of replayed levels."""
        return isinstance(self.adversary, EditingBuffers)

    @property
    def trains_on_fresh(self) -> bool:
        return self.adversary.trains_on_fresh


DR = Algorithm("dr", RandomLevels(), description="domain randomisation: fresh random levels every update")
PLR = Algorithm("plr", LevelBuffers(),
                description="robust prioritized level replay (PLR⊥): replays high-score levels, trains only on replays")
MINIMAX_RETURN = Algorithm("minimax-return", LevelBuffers(), score="neg_return",
                           description="PLR⊥ scored by negative return (a minimax adversary)")
REMIDI = Algorithm("remidi", LevelBuffers(buffer_sequence=True),
                   description="ReMiDi: PLR⊥ with a sequence of buffers; levels an earlier buffer explains are rejected")

ACCEL = Algorithm("accel", EditingBuffers(),
                  description="ACCEL: PLR⊥ whose replayed levels are edited, and the edits offered to the buffer")
REMIDI_ACCEL = Algorithm("remidi-accel", EditingBuffers(buffer_sequence=True),
                         description="ReMiDi over ACCEL: ACCEL's edits are new levels for ReMiDi's buffer sequence")

PAIRED = Algorithm("paired", LevelGenerator(),
                   description="PAIRED: a learned generator builds the levels, paid the regret an antagonist estimates")

REMIDI_PAIRED = Algorithm("remidi-paired", GeneratorSequence(),
                          description="ReMiDi over PAIRED: a sequence of generators, one antagonist; levels an earlier "
                                      "generator's support explains pay the generator little and train nothing")

SFL = Algorithm("sfl", LearnabilityBuffers(), score="learnability",
                description="SFL (sampling for learnability): every sfl.refresh_every updates the current policy "
                            "plays fresh levels and keeps the most learnable, p(1 − p); each update mixes them with "
                            "fresh levels")
REMIDI_SFL = Algorithm("remidi-sfl", LearnabilityBuffers(buffer_sequence=True), score="learnability",
                       description="ReMiDi over SFL: a sequence of SFL buffers; levels an earlier buffer explains are "
                                   "never kept, and the loss is masked where they explain")

#: every algorithm ``--algo`` accepts, by name, in the order the docs and plots list them
ALGORITHMS: dict[str, Algorithm] = {a.name: a for a in (DR, PLR, MINIMAX_RETURN, REMIDI, ACCEL, REMIDI_ACCEL, PAIRED,
                                                        REMIDI_PAIRED, SFL, REMIDI_SFL)}
BUILTIN_ALGORITHMS = tuple(ALGORITHMS)  # the library's own, in order


class RegisteredNames(Sequence):
    """The names in :data:`ALGORITHMS` now, in order: an experiment's ``algorithms``.

    Live, so algorithms registered later are accepted by ``--algo``. ``where(Algorithm) -> bool``
    keeps those the task supports; ``why``: a sentence (or a function of the algorithm giving one)
    saying why one is left out."""

    def __init__(self, where=None, why=None):  # why: str, or Algorithm -> str | None
        self.where, self.why = where, why

    def refusal(self, name: str) -> str | None:
        """Why registered algorithm ``name`` is left out here; None if it is not (or is not registered)."""
        if name in ALGORITHMS and self.where is not None and not self.where(ALGORITHMS[name]):
            why = self.why(ALGORITHMS[name]) if callable(self.why) else self.why
            return why or "this experiment's task does not support it"
        return None

    def _names(self) -> tuple[str, ...]:
        return tuple(name for name, algo in ALGORITHMS.items() if self.where is None or self.where(algo))

    def __getitem__(self, i):
        return self._names()[i]

    def __len__(self):
        return len(self._names())

    def __add__(self, other):
        return tuple(self) + tuple(other)

    def __radd__(self, other):
        return tuple(other) + tuple(self)

    def __eq__(self, other):
        return isinstance(other, Sequence) and tuple(self) == tuple(other)

    def __hash__(self):
        return hash(tuple(self))

    def __repr__(self):
        return repr(tuple(self))


def register_algorithm(name: str, adversary: Adversary, *, score: str | None = None,
                       description: str = "") -> Algorithm:
    """Add an algorithm of existing components to :data:`ALGORITHMS`, accepted by every UED experiment's
    ``--algo`` and by :func:`remidi.run_ued`.

    ``adversary``: an instance, e.g. ``LevelBuffers(trains_on_fresh=True)``; ``score``: a registered
    score it always uses, or None for the config's. Raises ConfigError for a taken name or a
    malformed entry."""
    check_name("algorithm", name)
    if name in ALGORITHMS:
        raise ConfigError(f"register_algorithm: an algorithm named {name!r} is already registered; "
                          f"taken: {', '.join(ALGORITHMS)}")
    if isinstance(adversary, type):
        raise ConfigError(f"register_algorithm: {name}: adversary must be an instance, e.g. "
                          f"{adversary.__name__}(), got the class {adversary.__name__}")
    if score is not None and score not in SCORES:
        raise ConfigError(f"register_algorithm: {name}: score must be a registered score or None, got {score!r}; "
                          f"allowed: {', '.join(SCORES)}")
    if not isinstance(description, str):
        raise ConfigError(f"register_algorithm: {name}: description must be a string, "
                          f"got {type(description).__name__}")
    algo = Algorithm(name, adversary, score=score, description=description)  # checks the adversary
    ALGORITHMS[name] = algo
    return algo


#: the algorithms of the paper's comparisons: what ``remidi run`` trains when ``--algo`` is not given
PAPER_ALGORITHMS = ("dr", "plr", "minimax-return", "remidi")


def get_algorithm(algo: str | Algorithm, key: str = "--algo") -> Algorithm:
    """The algorithm named ``algo`` (an :class:`Algorithm` as is); ConfigError naming ``key`` otherwise."""
    if isinstance(algo, Algorithm):
        return algo
    if algo not in ALGORITHMS:
        raise one_of(key, algo, ALGORITHMS)
    return ALGORITHMS[algo]
