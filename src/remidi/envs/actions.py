"""A task's action space (``UEDTask.action_space``), from which the engine picks the policy's
distribution (:func:`remidi.engine.core.distributions.for_task`):

- :class:`Discrete` ``(n)``: an action is ``i32[]``;
- :class:`MultiDiscrete` ``(nvec)``: one choice per component (Kinetix: 3 per motor, 2 per
  thruster), ``i32[k]``;
- :class:`Box` ``(dims)``: unbounded floats (the environment clips), ``f32[dims]``.

:func:`from_env_space` reads one off an env's own space (gymnax, JaxMARL, gymnasium, Kinetix);
:func:`as_action_space` converts one given as ``action_space`` when the task is built."""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from remidi.errors import ConfigError, a_type

#: what :func:`from_env_space` reads, for messages
SUPPORTED = ("Discrete(n)", "MultiDiscrete(nvec) (a choice count per dimension: nvec, "
             "number_of_dims_per_distribution or num_categories)", "Box (float actions)")
#: the attributes that give a multi-discrete space's choice count per dimension, in the order read:
#: Kinetix's (read before its ``n``, the total), gymnasium's, JaxMARL's
COUNTS = ("number_of_dims_per_distribution", "nvec", "num_categories")


def _is_size(value) -> bool:
    """An integer ≥ 1 (a Python or NumPy integer, not a bool)."""
    return not isinstance(value, bool) and isinstance(value, (int, np.integer)) and value >= 1


@dataclass(frozen=True)
class Discrete:
    """One choice among ``n``: an action is ``i32[]`` in ``[0, n)``."""

    n: int

    @property
    def shape(self) -> tuple[int, ...]:
        return ()

    @property
    def dtype(self):
        return jnp.int32

    def problem(self) -> str | None:
        """Why this is no valid space (None: it is)."""
        return None if _is_size(self.n) else f"n must be an integer ≥ 1, got {self.n!r}"

    def task_fields(self) -> dict:
        """The ``UEDTask`` keywords that declare this space (the ``num_actions=`` shorthand)."""
        return {"num_actions": int(self.n)}

    def __str__(self) -> str:
        return f"Discrete({self.n})"


@dataclass(frozen=True)
class MultiDiscrete:
    """One choice per component: ``i32[k]`` (``k = len(nvec)``), entry ``i`` in ``[0, nvec[i])``; ``nvec``
    kept as a tuple."""

    nvec: tuple[int, ...]

    def __post_init__(self):  # any sequence or array of counts, kept as a tuple (hashable)
        try:
            object.__setattr__(self, "nvec", tuple(np.asarray(self.nvec).reshape(-1).tolist()))
        except (TypeError, ValueError):  # left as given: problem() names it
            pass

    @property
    def shape(self) -> tuple[int, ...]:
        return (len(self.nvec),)

    @property
    def dtype(self):
        return jnp.int32

    def problem(self) -> str | None:
        if not self.nvec or not all(_is_size(v) for v in self.nvec):
            return f"nvec must be a non-empty sequence of integers ≥ 1, got {self.nvec!r}"
        return None

    def task_fields(self) -> dict:
        return {"action_space": self}

    def __str__(self) -> str:
        return f"MultiDiscrete({self.nvec})"


@dataclass(frozen=True)
class Box:
    """``dims`` unbounded floats (the environment clips): an action is ``f32[dims]``."""

    dims: int

    @property
    def shape(self) -> tuple[int, ...]:
        return (self.dims,)

    @property
    def dtype(self):
        return jnp.float32

    def problem(self) -> str | None:
        return None if _is_size(self.dims) else f"dims must be an integer ≥ 1, got {self.dims!r}"

    def task_fields(self) -> dict:
        return {"num_actions": int(self.dims), "continuous": True}

    def __str__(self) -> str:
        return f"Box({self.dims})"


ActionSpace = Discrete | MultiDiscrete | Box


def example_action(space: ActionSpace) -> jax.ShapeDtypeStruct:
    """One action of ``space``, shapes only (for tracing a step)."""
    return jax.ShapeDtypeStruct(space.shape, space.dtype)


def zero_action(space: ActionSpace) -> jax.Array:
    """The all-zero action of ``space`` (a valid action of every kind)."""
    return jnp.zeros(space.shape, space.dtype)


def from_env_space(space, field: str = "task.env.action_space") -> ActionSpace:
    """The :data:`ActionSpace` of an environment's ``action_space(params)``: a space with a choice
    count per dimension (:data:`COUNTS`) → :class:`MultiDiscrete`; one with an integer ``n`` →
    :class:`Discrete`; one with a float ``dtype`` and a ``shape`` → :class:`Box` (its size).
    ConfigError (one line starting with ``field``, naming the supported spaces) for any other, or
    for one whose choices do not start at 0 (gymnasium's ``start``)."""
    start = np.asarray(getattr(space, "start", 0))
    if np.issubdtype(start.dtype, np.integer) and np.any(start != 0):
        raise ConfigError(f"{field}: {a_type(space)} whose choices start at {start.tolist()} is "
                          f"not supported (an action here is a choice from 0); allowed: {', '.join(SUPPORTED)}")
    try:
        read = _read_space(space)
    except (TypeError, ValueError):  # attributes of those names that are not numbers, shapes or dtypes
        read = None
    if read is None:
        raise ConfigError(f"{field}: {a_type(space)} is not supported; allowed: {', '.join(SUPPORTED)}")
    return read


def _read_space(space) -> ActionSpace | None:
    """:func:`from_env_space`'s reading of ``space``; None where it is none of the kinds."""
    counts = next((getattr(space, name) for name in COUNTS if getattr(space, name, None) is not None), None)
    if counts is not None and np.ndim(counts) >= 1:
        return MultiDiscrete(tuple(int(v) for v in np.asarray(counts).reshape(-1)))
    n = getattr(space, "n", None)
    if n is not None and np.ndim(n) == 0 and np.issubdtype(np.asarray(n).dtype, np.integer):
        return Discrete(int(n))
    shape, dtype = getattr(space, "shape", None), getattr(space, "dtype", None)
    if isinstance(shape, tuple) and dtype is not None and jnp.issubdtype(jnp.dtype(dtype), jnp.floating):
        return Box(math.prod(shape))
    return None


def as_action_space(space):
    """``space`` as a task's :data:`ActionSpace`: one of this module's as it is, an environment's own
    (gymnax, Kinetix, JaxMARL, gymnasium: :func:`from_env_space`) converted, None or anything else
    as it is (the task's check, ``validate_task``, names what is wrong in one line)."""
    if space is None or isinstance(space, (Discrete, MultiDiscrete, Box)):
        return space
    try:
        return from_env_space(space)
    except ConfigError:
        return space
