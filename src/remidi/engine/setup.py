"""The static set-up of a run (:class:`Setup`) and what is read off a config and a task before a
runner exists (the network, an example observation)."""

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
    """Static pieces of a run: the task, the config, the algorithm, and what is derived from them,
    left out of equality: the agent's network, the tracker (None for an algorithm that freezes
    nothing), ``envs`` (the :class:`~remidi.engine.learner.Stepping` the agent's rollout steps),
    ``dist`` (the policy's action distribution), ``score`` (the levels' score, a
    :data:`~remidi.engine.adversaries.scores.SCORES` entry; None for a name the config's validation
    refuses) and ``buffer`` (the level buffers' settings). Hashable: a static argument under jit."""

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
    """The network ``cfg.network`` sized for the task's action distribution, with ``hidden_size`` /
    ``lstm_size`` where set (ConfigError if the network has no such layer): ``hidden_size`` sets
    every width of ``hidden`` (a tuple keeps its length), ``lstm_size`` sets ``lstm_size``."""
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
    """``(obs, level)``: the first observation (unbatched leaves) of a level sampled with ``key``
    (``PRNGKey(0)`` if None), reset with the same key. One compiled program: outside a trace, the
    generator's and the reset's operations would each compile their own (about a hundred for the
    maze, seconds per process)."""
    return _first_observation(task, jax.random.PRNGKey(0) if key is None else key)


@partial(jax.jit, static_argnums=0)
def _first_observation(task: UEDTask, key):
    level = task.sample_level(key)
    return task.env.reset_to_level(key, level, task.params)[0], level
