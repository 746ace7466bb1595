"""The registry of networks (``network=NAME``): the built-in ones, :func:`register_network` for
your own, :func:`make_network`, and how a network's statement of what it reads is checked against
a task's observation.

A network states what it reads with a class attribute ``reads`` (one line, shown by ``remidi
list``) and, optionally, an ``nn.nowrap`` method ``check_observation(obs) -> str | None``: why it
cannot read ``obs``, one observation of the task (unbatched leaves with ``.shape`` and ``.dtype``),
or None. Validation (:func:`remidi.engine.run.task_checks.check_network_reads_observations`) asks
it first, then traces the network on the observation.
"""

from __future__ import annotations

import dataclasses

import flax.linen as nn
import jax

from remidi.engine.core.networks.base import activation_fn, shape_text
from remidi.engine.core.networks.cnn import CNNActorCritic
from remidi.engine.core.networks.entity import EntityActorCritic
from remidi.engine.core.networks.paper import FeedForwardActorCritic, MazeLSTMActorCritic, MLPLSTMActorCritic
from remidi.errors import ConfigError, check_name, one_of

#: name → network class (``network=NAME``)
NETWORKS: dict[str, type] = {"mlp": FeedForwardActorCritic, "maze_lstm": MazeLSTMActorCritic,
                             "mlp_lstm": MLPLSTMActorCritic, "entity": EntityActorCritic, "cnn": CNNActorCritic}

#: name → one line of what the network is (``remidi list``)
NETWORK_HELP: dict[str, str] = {
    "mlp": "MLP trunk (hidden: 2 × 256 tanh), 32-unit heads: the lever agent",
    "maze_lstm": "3×3 conv of the view, embedded direction, LSTM (256), 32-unit heads: the paper's maze agent",
    "mlp_lstm": "MLP trunk (2 × 256 tanh), LSTM (256), 64-unit heads: the paper's Brax agent",
    "entity": "permutation-invariant entity encoder (masked self-attention or pooling), optional LSTM: "
              "Kinetix's entity agent",
    "cnn": "strided CNN over an image (Kinetix's pixel agent), other fields beside it, optional LSTM",
}

BUILTIN_NETWORKS = tuple(NETWORKS)  # the library's own, in order

#: fields every network has that are not options (set by the engine or by flax)
_NOT_OPTIONS = ("num_actions", "continuous", "parent", "name")


def network_options(cls: type) -> list[str]:
    """The options of a network class: its dataclass fields but ``num_actions`` and ``continuous``."""
    return [f.name for f in dataclasses.fields(cls) if f.init and f.name not in _NOT_OPTIONS]


def register_network(name: str, cls: type, *, description: str = "") -> type:
    """Add a network class to :data:`NETWORKS`, so that ``network=NAME`` (``--set network=NAME``)
    trains it in every UED experiment and ``remidi list EXPERIMENT`` lists it with what it reads.

    ``cls``: a :class:`flax.linen.Module` class with the engine's interface (the docstring of
    :mod:`remidi.engine.core.networks`): ``__call__(carry, obs, reset)`` over ``[T, N, ...]``
    leaves returning ``(carry, (logits, value))``, an ``nn.nowrap`` ``initialize_carry(n)``, the
    fields ``num_actions`` and ``continuous`` and every other field with a default (its options:
    ``make_network(NAME, ..., option=value)``; ``hidden`` and ``lstm_size`` are what the config's
    ``hidden_size`` and ``lstm_size`` set), a class attribute ``reads`` (one line: the observation
    it reads) and optionally ``check_observation(obs) -> str | None``. ``description``: one line
    for ``remidi list``. Raises ConfigError (one line) for a name taken or a malformed class.
    Returns ``cls``.
    """
    check_name("network", name)
    where = f"register_network: {name}"
    if name in NETWORKS:
        raise ConfigError(f"register_network: a network named {name!r} is already registered; "
                          f"taken: {', '.join(NETWORKS)}")
    if isinstance(cls, nn.Module):
        raise ConfigError(f"{where}: cls must be the class, not an instance ({type(cls).__name__})")
    if not (isinstance(cls, type) and issubclass(cls, nn.Module)):
        raise ConfigError(f"{where}: cls must be a flax.linen.Module class, got {cls!r}")
    fields = {f.name for f in dataclasses.fields(cls)}
    for field in ("num_actions", "continuous"):
        if field not in fields:
            raise ConfigError(f"{where}: {cls.__name__} must have a field {field} (set by the engine: "
                              f"the policy's outputs and whether actions are continuous)")
    for attribute, what in (("initialize_carry", "an nn.nowrap method initialize_carry(n): the initial carry"),
                            ("__call__", "a method __call__(carry, obs, reset)")):
        if not callable(getattr(cls, attribute, None)):
            raise ConfigError(f"{where}: {cls.__name__} must have {what}")
    reads = getattr(cls, "reads", None)
    if not (isinstance(reads, str) and reads.strip() and "\n" not in reads):
        raise ConfigError(f"{where}: {cls.__name__} must state what it reads: a class attribute reads, one line "
                          f"(e.g. \"image f32[H, W, C]\"), got {reads!r}")
    if not callable(getattr(cls, "check_observation", lambda obs: None)):
        raise ConfigError(f"{where}: {cls.__name__}.check_observation must be a method check_observation(obs) "
                          f"returning None or why it cannot read obs")
    if not isinstance(description, str) or "\n" in description:
        raise ConfigError(f"{where}: description must be one line of text, got {description!r}")
    try:
        net = cls(num_actions=2, continuous=False)
        jax.eval_shape(lambda: net.initialize_carry(1))
    except Exception as err:  # the user's class: its own error, one line
        first = (str(err).strip().splitlines() or [""])[0]
        raise ConfigError(f"{where}: {cls.__name__}(num_actions=2, continuous=False).initialize_carry(1) failed "
                          f"(every field but num_actions and continuous needs a default): "
                          f"{type(err).__name__}{': ' + first if first else ''}") from None
    NETWORKS[name] = cls
    NETWORK_HELP[name] = description
    return cls


def make_network(kind: str, num_actions: int, continuous: bool = False, **kwargs) -> nn.Module:
    """Build the network registered as ``kind`` (:data:`NETWORKS`), with a Gaussian policy output
    if ``continuous`` (``num_actions`` = action dimensions; for a discrete head, the number of
    policy logits).

    ``kwargs`` are module fields (e.g. ``hidden=(64, 64)`` for ``"mlp"``); lists become tuples.
    Raises :class:`remidi.errors.ConfigError` for an unknown kind, option or activation.
    """
    if kind not in NETWORKS:
        raise one_of("network", kind, list(NETWORKS))
    cls = NETWORKS[kind]
    allowed = network_options(cls)
    for key in kwargs:
        if key not in allowed:
            raise one_of(f"network.{kind} option", key, allowed)
    if "activation" in kwargs:
        activation_fn(kwargs["activation"])
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in kwargs.items()}
    return cls(num_actions=num_actions, continuous=continuous, **kwargs)


def reads(net) -> str:
    """What the network (a class or an instance) says it reads, one line."""
    return getattr(net, "reads", None) or "(it does not say)"


def observation_problem(net: nn.Module, obs) -> str | None:
    """Why ``net`` cannot read ``obs`` (one observation, unbatched leaves) by its own
    ``check_observation``, None if it says it can (or has no check). A check that raises is
    reported as its error, one line."""
    check = getattr(net, "check_observation", None)
    if check is None:
        return None
    try:
        problem = check(obs)
    except Exception as err:  # the network's own check failing is a reason too
        first = (str(err).strip().splitlines() or [""])[0]
        return f"its check_observation raised {type(err).__name__}{': ' + first if first else ''}"
    return None if problem is None else str(problem).strip().replace("\n", " ")


def describe_observation(obs) -> str:
    """One observation's leaves, one line: ``f32[65]`` for a single array, else each leaf by its
    path, e.g. ``image u8[5, 5, 3], agent_dir i32[]``."""
    leaves = jax.tree_util.tree_flatten_with_path(obs)[0]
    if len(leaves) == 1 and not leaves[0][0]:
        return shape_text(leaves[0][1])
    parts = []
    for path, leaf in leaves:
        key = ".".join(str(getattr(p, "key", getattr(p, "name", getattr(p, "idx", p)))) for p in path)
        parts.append(f"{key} {shape_text(leaf)}")
    return ", ".join(parts) or "empty (no arrays)"
