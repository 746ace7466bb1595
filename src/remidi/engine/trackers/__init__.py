"""ReMiDi's distinguishability trackers (protocol: :mod:`~remidi.engine.trackers.base`) and the choice of one.

``remidi.tracker``: ``prefix`` (default, :mod:`~remidi.engine.trackers.exact`: one frozen level
produced the whole prefix), ``per_step`` (the authors' looser rule), ``tolerance`` (prefix rule,
floats compared up to a tolerance, :mod:`~remidi.engine.trackers.tolerance`), ``belief`` and
``simulated`` (learned models). Only this package reads the ``remidi.tracker*`` and
``remidi.belief_*`` keys."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from remidi.engine.setup import example_observation
from remidi.engine.trackers.base import Frozen, Tracker
from remidi.engine.trackers.belief import BeliefTracker
from remidi.engine.trackers.belief_model import BeliefModel, LearnedSettings, coding_for, coding_problem
from remidi.engine.trackers.exact import MODES, exact_budget, make_tracker
from remidi.engine.trackers.simulated import Simulated
from remidi.engine.trackers.tolerance import ToleranceCandidates, ToleranceTracker, make_tolerance_tracker
from remidi.envs.actions import Box, MultiDiscrete
from remidi.errors import COMMAND_LINE, ConfigError, Naming, positive_int, require

#: every value of ``remidi.tracker``
TRACKERS = MODES + ("tolerance", "belief", "simulated")
#: the trackers that replay the frozen levels and compare observations (no learned model)
REPLAYING = MODES + ("tolerance",)


@functools.lru_cache(maxsize=None)
def model_for(task, hidden: int) -> BeliefModel:
    """The belief model of ``task`` (its observations' coding, its actions) with ``hidden`` GRU units."""
    obs = jax.eval_shape(lambda: example_observation(task)[0])
    actions = task.actions  # Discrete or MultiDiscrete (validate_tracker refuses a Box)
    counts = actions.nvec if isinstance(actions, MultiDiscrete) else actions.n
    return BeliefModel(coding_for(obs), num_actions=counts, hidden=hidden)


def tracker_for(task, cfg, algo) -> Tracker | None:
    """The run's tracker (``remidi.tracker``); None for an algorithm that is no sequence of adversaries.

    With a single adversary nothing is ever frozen, and the exact tracker (``prefix`` unless
    ``per_step``) stands in for the choice."""
    if not algo.buffer_sequence:
        return None
    r = cfg.remidi
    sequence = r.num_buffers >= 2
    if sequence and r.tracker == "tolerance":
        return make_tolerance_tracker(exact_budget(task, r, "prefix"), r.tracker_tolerance, r.tracker_rtol)
    if not sequence or r.tracker in MODES:
        mode = r.tracker if r.tracker in MODES else "prefix"
        return make_tracker(mode, exact_budget(task, r, mode))
    settings = LearnedSettings(lr=r.belief_lr, epochs=r.belief_epochs, false_rate=r.belief_false_rate,
                               margin=r.belief_margin, spread=r.belief_spread, calibration=r.belief_calibration,
                               reference=r.belief_reference)
    model = model_for(task, r.belief_hidden)
    if r.tracker == "simulated":
        return Simulated(model, budget=r.tracker_budget, capacity=r.buffer_capacity, reseed=task.reseed_level,
                         settings=settings)
    return BeliefTracker(model, settings=settings)


def validate_tracker(cfg, algo, task) -> None:
    """ConfigError (one line, naming the key) for tracker keys the run cannot take."""
    r = cfg.remidi
    require(isinstance(r.tracker_budget, int) and not isinstance(r.tracker_budget, bool) and r.tracker_budget >= 0,
            "remidi.tracker_budget", "an integer ≥ 0 (0: the reference tracker)", r.tracker_budget)
    if r.tracker not in TRACKERS:  # the exact tracker is "prefix" (the definition); name it so
        raise ConfigError(f"remidi.tracker: unknown value {r.tracker!r}; allowed: prefix (the exact tracker, the "
                          f"default), per_step (the authors' looser exact rule), tolerance (prefix, with float "
                          f"observations compared up to remidi.tracker_tolerance), belief (the learned belief model), "
                          f"simulated (the frozen levels simulated under fresh randomness, with a learnt noise model)")
    for key in ("tracker_tolerance", "tracker_rtol"):
        value = getattr(r, key)
        require(isinstance(value, (int, float)) and not isinstance(value, bool) and 0 <= value < float("inf"),
                f"remidi.{key}", "a finite number ≥ 0", value)
    if r.tracker == "tolerance":
        require(r.tracker_tolerance > 0 or r.tracker_rtol > 0, "remidi.tracker_tolerance", "> 0 with "
                "remidi.tracker=tolerance (the largest |difference| of a float observation entry that is still the "
                "same observation: wider than the noise, narrower than what tells levels apart; docs/tolerance.md)",
                r.tracker_tolerance)
    # the belief model's keys are checked whichever tracker runs: a bad value is a mistake either way
    require(0.0 <= r.belief_false_rate < 1.0, "remidi.belief_false_rate", "a number in [0, 1)", r.belief_false_rate)
    positive_int("remidi.belief_hidden", r.belief_hidden)
    positive_int("remidi.belief_calibration", r.belief_calibration)
    positive_int("remidi.belief_epochs", r.belief_epochs)
    require(r.belief_margin >= 0, "remidi.belief_margin", "≥ 0", r.belief_margin)
    require(r.belief_spread >= 0, "remidi.belief_spread", "≥ 0", r.belief_spread)
    require(r.belief_lr > 0, "remidi.belief_lr", "> 0", r.belief_lr)
    require(isinstance(r.belief_reference, bool), "remidi.belief_reference", "true or false", r.belief_reference)
    if r.tracker == "simulated":
        require(algo.replays or not algo.buffer_sequence, "remidi.tracker", "prefix, per_step, tolerance or belief "
                "with a "
                "learned generator (the simulated model needs the adversary's levels: a buffer's)", r.tracker)
        require(task.deterministic_reset, "remidi.tracker", "prefix, per_step, tolerance or belief for a task whose "
                "reset draws "
                "randomness (the simulated model follows the frozen levels from their fixed starts)", r.tracker)
    if r.tracker in ("belief", "simulated"):
        require(not r.belief_reference or algo.replays, "remidi.belief_reference", "false with a learned generator "
                "(the reference learns from the task generator's fresh levels, which a generator never plays)",
                r.belief_reference)
        require(not isinstance(task.actions, Box), "remidi.tracker", "prefix, per_step or tolerance for a task with "
                "continuous "
                "actions (the belief model reads discrete actions: Discrete or MultiDiscrete)", r.tracker)
        obs = example_observation(task)[0]
        problem = coding_problem(coding_for(obs), obs)
        if problem is not None:
            raise ConfigError(f"remidi.tracker: {r.tracker} cannot read this task: {problem}; allowed here: prefix, "
                              f"per_step, tolerance (float observations compared up to remidi.tracker_tolerance)")
    if r.policy == "combine":
        require(r.tracker in ("prefix", "tolerance", "belief"), "remidi.tracker", "prefix, tolerance or belief with "
                "remidi.policy=combine (a "
                "policy per buffer acts where that buffer's levels produced, or its model explains, the whole prefix)",
                r.tracker)


def readable_trackers(task) -> tuple[str, ...]:
    """The trackers beyond exact equality that can read ``task``'s observations (for start-up advice).

    ``tolerance`` where observations hold non-categorical floats; else ``belief`` for discrete
    actions (and ``simulated`` where the reset ignores its key). Tolerance is not recommended for
    categorical observations: below a category's step it is exact equality."""
    obs = example_observation(task)[0]
    floats = any(jnp.issubdtype(jnp.result_type(leaf), jnp.inexact) for leaf in jax.tree.leaves(obs))
    if floats and coding_problem(coding_for(obs), obs) is not None:
        return ("tolerance",)
    if isinstance(task.actions, Box):
        return ()
    return ("belief", "simulated") if task.deterministic_reset else ("belief",)


def tracker_advice(task, naming: Naming = COMMAND_LINE) -> str | None:
    """Words recommending :func:`readable_trackers` (in ``naming``'s words); None where there is none."""
    names = readable_trackers(task)
    if names == ("tolerance",):
        return (f"judge with {naming.setting('remidi.tracker', 'tolerance')} and "
                f"{naming.setting('remidi.tracker_tolerance', '<wider than the observation noise>')} (float "
                f"observations compared up to a tolerance; docs/tolerance.md)")
    if not names:
        return None
    return "judge with " + " or ".join(naming.setting("remidi.tracker", name) for name in names)


# env steps per rollout env step (env + frozen levels) from which a run on a costly env is told:
# the slots multiply the env's work (docs/performance.md, "The tracker's cost")
COSTLY_STEPS = 9
LOWER_BUDGET = 8  # the budget a note suggests (9 environment steps per env step)


def tracker_cost_note(task, cfg, algo, naming: Naming = COMMAND_LINE) -> str | None:
    """One line for a run whose exact tracker steps the env at least :data:`COSTLY_STEPS` times per
    env step once an adversary is frozen, naming the option that lowers it and its cost; else None.

    The caller says it only where the env's step is not cheap (``UEDSpec.cheap_step``)."""
    r = cfg.remidi
    if not (algo.buffer_sequence and r.num_buffers >= 2) or r.tracker not in REPLAYING:
        return None
    slots = exact_budget(task, r, "prefix" if r.tracker == "tolerance" else r.tracker)
    frozen = (r.num_buffers - 1) * r.buffer_capacity
    followed = slots or frozen
    if followed + 1 < COSTLY_STEPS:
        return None
    what = (f"steps up to {followed} frozen levels (remidi.tracker_budget={r.tracker_budget}) beside each rollout env"
            if slots else f"steps every frozen level ({frozen}: the reference tracker) beside each rollout env")
    lower = naming.setting("remidi.tracker_budget", LOWER_BUDGET)  # in the caller's words: --set or config[...]
    if slots and slots > LOWER_BUDGET:
        fix = (f"{lower} makes it {LOWER_BUDGET + 1}×, at a cost where more than "
               f"{LOWER_BUDGET} frozen levels share an env's first observation: those beyond the slots are not "
               f"followed (counted by the tracker_overflow metric), so a prefix only they explain counts as "
               f"distinguishable")
    elif slots:
        fix = "a smaller remidi.buffer_capacity or remidi.num_buffers freezes fewer levels"
    else:
        if r.tracker != "per_step" and task.deterministic_reset:  # remidi.tracker_budget=0 chose the reference
            fix = (f"{lower} follows at most {LOWER_BUDGET} per env (the tracker_overflow metric counts those it "
                   f"could not)")
        elif "belief" in readable_trackers(task):
            fix = "remidi.tracker=belief judges with a learned model instead (docs/belief.md)"
        else:
            fix = "a smaller remidi.buffer_capacity or remidi.num_buffers freezes fewer levels"
    when = (" while that many frozen levels keep matching its observations (a slot no frozen level matches is "
            "not stepped: where nothing matches, ReMiDi steps as PLR⊥)") if slots else ""
    return (f"ReMiDi's exact tracker {what} once an adversary is frozen: a rollout steps this environment up to "
            f"{followed + 1}× as often as PLR⊥'s{when} (docs/performance.md, \"The tracker's cost\"); {fix}")


__all__ = ["Frozen", "Tracker", "TRACKERS", "REPLAYING", "tracker_for", "validate_tracker", "exact_budget",
           "model_for", "tracker_cost_note", "readable_trackers", "tracker_advice", "ToleranceTracker",
           "ToleranceCandidates"]
