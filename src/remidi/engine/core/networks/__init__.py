"""Actor-critic networks sharing one interface for feed-forward and recurrent agents.

Every network is a :class:`flax.linen.Module` applied to a whole rollout at once::

    carry, (logits, value) = net.apply(variables, carry, obs, reset)

- ``obs``: an observation pytree whose leaves are shaped ``[T, N, ...]`` (time, envs).
- ``reset``: ``bool[T, N]``, True where a new episode starts at that step; a recurrent net
  re-initialises its carry *before* processing such a step.
- ``logits``: the policy output (:mod:`remidi.engine.core.distributions`), ``f32[T, N, num_actions]``
  logits, or with ``continuous=True`` ``f32[T, N, 2·num_actions]``, the mean and log standard
  deviation of a diagonal Gaussian (the log-std is a state-independent parameter, zeros
  initially); ``value``: ``f32[T, N]``.
- ``carry``: the recurrent state for the ``N`` envs after the last step. Every carry leaf has the
  env axis first, so a PPO minibatch of envs is ``jax.tree.map(lambda x: x[ids], carry)``.

``net.initialize_carry(n)`` returns the initial carry for ``n`` envs and needs no parameters.
Feed-forward nets return a dummy carry (``f32[n]`` zeros) unchanged. Every network states the
observation it reads: a class attribute ``reads`` (one line) and ``check_observation(obs)``, why
it cannot read one observation of a task, or None (:mod:`.registry`).

Modules: :mod:`.base` (initialisers, heads, the LSTM over a rollout, the patch convolution),
:mod:`.paper` (the paper's agents: ``mlp``, ``maze_lstm``, ``mlp_lstm``, PAIRED's generator),
:mod:`.entity` (``entity``: Kinetix-style entity encoder), :mod:`.cnn` (``cnn``: pixels),
:mod:`.registry` (``NETWORKS``, :func:`register_network`, :func:`make_network`).
"""

from remidi.engine.core.networks.base import (ACTIVATIONS, ActorCriticHeads, PatchConv, ResetLSTM, flatten_obs,
                                              obs_field, zero_lstm_carry)
from remidi.engine.core.networks.cnn import CNNActorCritic
from remidi.engine.core.networks.entity import EntityActorCritic
from remidi.engine.core.networks.paper import (FeedForwardActorCritic, GeneratorLSTMActorCritic, MazeLSTMActorCritic,
                                               MLPLSTMActorCritic)
from remidi.engine.core.networks.registry import (BUILTIN_NETWORKS, NETWORK_HELP, NETWORKS, describe_observation,
                                                  make_network, network_options, observation_problem, reads,
                                                  register_network)

__all__ = ["ACTIVATIONS", "ActorCriticHeads", "BUILTIN_NETWORKS", "CNNActorCritic", "EntityActorCritic",
           "FeedForwardActorCritic", "GeneratorLSTMActorCritic", "MLPLSTMActorCritic", "MazeLSTMActorCritic",
           "NETWORKS", "NETWORK_HELP", "PatchConv", "ResetLSTM", "describe_observation", "flatten_obs",
           "make_network", "network_options", "obs_field", "observation_problem", "reads", "register_network",
           "zero_lstm_carry"]
