"""The static set-up of a run (:class:`Setup`: the task, the config, the algorithm, and the
components derived from them: the network, the tracker, the policy's distribution and the
environments the agent's rollout steps) and what is read off it before a runner exists (the
network of a config, an example observation)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import partial

import jax

from typing import TYPE_CHECKING, Any

from remidi.engine.adversaries.scores import SCORES
from remidi.engine.config import BufferConfig, UEDConfig, buffer_config, score_name
from remidi.engine.core.distributions import for_task
from remidi.engine.core.networks import NETWORKS, make_network
from remidi.envs.interface import UEDTask
from remidi.errors import ConfigError

if TYPE_CHECKING:
    from remidi.engine.trackers.base import Tracker


@dataclass(frozen=True)
class Setup:
    """Static pieces of a run: the task, the config, the algorithm (its adversary and score,
    :mod:`remidi.engine.algorithms`), and the components derived from those three, left out of
    equality: the agent's network and the distinguishability tracker
    (:mod:`remidi.engine.trackers`; None for an algorithm that freezes nothing). Hashable: a static
    argument under jit. Built by :func:`remidi.engine.train.make_setup`. Derived here, once:
    ``dist``, the policy's action distribution
    (:func:`~remidi.engine.core.distributions.for_task`), ``envs``, the environments the agent's
    rollout steps (:class:`~remidi.engine.learner.Stepping`), ``score``, the score levels are
    ranked by (:data:`~remidi.engine.adversaries.scores.SCORES`' entry; None for a name the
    config's validation refuses), and ``buffer``, the level buffers' settings
    (:func:`~remidi.engine.config.buffer_config`)."""

    task: UEDTask
    cfg: UEDConfig
    algo: Any  # the Algorithm (engine/algorithms.py, which imports the adversaries that take a Setup)
    net: object = field(compare=False)
    tracker: Tracker | None = field(compare=False, default=None)
    envs: Any = field(compare=False, default=None)  # the learner's Stepping, built by make_setup
    dist: object = field(init=False, compare=False, repr=False)
    score: object = field(init=False, compare=False, repr=False)
    buffer: BufferConfig = field(init=False, compare=False, repr=False)

    def __post_init__(self):
        task = self.task
        object.__setattr__(self, "dist", for_task(task))
        object.__setattr__(self, "score", SCORES.get(score_name(self.cfg, self.algo)))
        object.__setattr__(self, "buffer", buffer_config(self.cfg, self.algo))


def network_for(cfg: UEDConfig, task: UEDTask):
    """The network ``cfg.network`` for the task's actions (its policy output sized for the task's
    distribution, :func:`~remidi.engine.core.distributions.for_task`), with
    ``hidden_size``/``lstm_size`` where set (ConfigError if that network has no such layer):
    ``hidden_size`` sets every layer of a ``hidden`` option that is a tuple of widths (its length
    kept), or ``hidden`` itself if it is one width; ``lstm_size`` sets ``lstm_size``."""
    options = {}
    cls = NETWORKS.get(cfg.network)
    fields = {f.name: f.default for f in dataclasses.fields(cls)} if cls is not None else {}
    for key, option, value in (("hidden_size", "hidden", cfg.hidden_size), ("lstm_size", "lstm_size", cfg.lstm_size)):
        if value == 0:
            continue
        if option not in fields:
            raise ConfigError(f"{key}: the network {cfg.network} has no such layer; leave it 0 or pick a network "
                              f"that has one")
        default = fields[option]
        options[option] = (value,) * len(default) if isinstance(default, (tuple, list)) else value
    dist = for_task(task)
    return make_network(cfg.network, dist.network_actions, dist.continuous, **options)


def example_observation(task: UEDTask, key=None):
    """One observation (unbatched leaves): the first of a level the task samples with ``key``
    (``PRNGKey(0)`` if None), reset with the same key. Returns ``(obs, level)``.

    One compiled program: called outside a trace, the generator's and the reset's operations
    would each compile a program of their own (about a hundred for the maze, seconds per process)."""
    return _first_observation(task, jax.random.PRNGKey(0) if key is None else key)


@partial(jax.jit, static_argnums=0)
def _first_observation(task: UEDTask, key):
    level = task.sample_level(key)
    return task.env.reset_to_level(key, level, task.params)[0], level
