"""Experiment configuration: presets, ``--set key=value`` overrides and validation.

An experiment's configuration is a frozen dataclass whose defaults are the paper's values. A
preset is a dict of overrides (``paper`` is empty), and ``--set`` adds more on top. Keys may be
dotted to reach nested dataclasses (``--set ppo.lr=3e-4``). Every problem raises
:class:`~remidi.errors.ConfigError` with one line naming the key and what is allowed.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import typing
from typing import Any, Iterable

from remidi.errors import ConfigError, one_of


def parse_set_items(items: Iterable[str]) -> dict[str, str]:
    """``["a=1", "b.c=x"]`` → ``{"a": "1", "b.c": "x"}``."""
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"--set: expected key=value, got {item!r}")
        out[key] = value.strip()
    return out


def field_names(config) -> list[str]:
    """All settable keys of a (nested) config dataclass, dotted, in declaration order.

    A config class (or any of its base classes) may name keys it derives itself in a
    ``DERIVED_KEYS`` attribute of the module that defines it
    (e.g. ``ppo.total_updates`` follows ``num_updates``); those are not settable.
    """
    derived = {key for cls in type(config).__mro__
               for key in getattr(sys.modules.get(cls.__module__), "DERIVED_KEYS", ())}
    names = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            names += [f"{f.name}.{sub}" for sub in field_names(value) if f"{f.name}.{sub}" not in derived]
        elif f.name not in derived:
            names.append(f.name)
    return names


def _convert(key: str, text: Any, kind) -> Any:
    """Convert ``text`` (a string from the command line, or a JSON value) to ``kind``."""
    if kind is bool:
        if isinstance(text, bool):
            return text
        lowered = str(text).lower()
        if lowered in ("true", "1", "yes", "on"):
            return True
        if lowered in ("false", "0", "no", "off"):
            return False
        raise ConfigError(f"{key}: expected true or false, got {text!r}")
    if kind is int:
        if isinstance(text, bool):
            raise ConfigError(f"{key}: expected an integer, got {text!r}")
        try:
            number = float(text)
        except (TypeError, ValueError):
            raise ConfigError(f"{key}: expected an integer, got {text!r}") from None
        if not math.isfinite(number) or number != int(number):
            raise ConfigError(f"{key}: expected an integer, got {text!r}")
        return int(number)
    if kind is float:
        if isinstance(text, bool):
            raise ConfigError(f"{key}: expected a number, got {text!r}")
        try:
            number = float(text)
        except (TypeError, ValueError):
            raise ConfigError(f"{key}: expected a number, got {text!r}") from None
        if not math.isfinite(number):
            raise ConfigError(f"{key}: expected a finite number, got {text!r}")
        return number
    if kind is str:
        return str(text)
    raise ConfigError(f"{key}: cannot be set from the command line")


def apply_overrides(config, overrides: dict[str, Any], *, source: str = "--set", prefix: str = ""):
    """Return ``config`` with ``overrides`` (dotted keys → text or JSON values) applied.
    ``prefix``: the dotted path of ``config`` inside the top-level config, for error messages."""
    allowed = field_names(config)
    nested: dict[str, dict[str, Any]] = {}
    direct: dict[str, Any] = {}
    hints = typing.get_type_hints(type(config))
    for key, value in overrides.items():
        if key not in allowed:
            raise ConfigError(f"{source}: unknown key {prefix + key!r}; "
                              f"allowed: {', '.join(prefix + name for name in allowed)}")
        head, _, rest = key.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = _convert(prefix + key, value, hints[head])
    for head, sub in nested.items():
        direct[head] = apply_overrides(getattr(config, head), sub, source=source, prefix=f"{prefix}{head}.")
    return dataclasses.replace(config, **direct)


def config_to_dict(config) -> dict[str, Any]:
    return dataclasses.asdict(config)


def config_from_dict(cls, data: dict[str, Any]):
    """Rebuild a config dataclass from :func:`config_to_dict` output (e.g. a run's config.json)."""
    flat: dict[str, Any] = {}

    def walk(prefix, d):
        for k, v in d.items():
            if isinstance(v, dict):
                walk(f"{prefix}{k}.", v)
            else:
                flat[f"{prefix}{k}"] = v

    walk("", data)
    settable = set(field_names(cls()))
    return apply_overrides(cls(), {k: v for k, v in flat.items() if k in settable}, source="config.json")


# ------------------------------------------------------------------------------ validation
def require(cond: bool, key: str, what: str, value: Any) -> None:
    """Raise ``ConfigError("key: must be WHAT, got VALUE")`` unless ``cond``."""
    if not cond:
        raise ConfigError(f"{key}: must be {what}, got {value!r}")


def positive_int(key: str, value: int) -> None:
    require(isinstance(value, int) and value >= 1, key, "an integer ≥ 1", value)


def non_negative(key: str, value: float) -> None:
    require(value >= 0, key, "≥ 0", value)


def positive(key: str, value: float) -> None:
    require(value > 0, key, "> 0", value)


def probability(key: str, value: float) -> None:
    require(0.0 <= value <= 1.0, key, "in [0, 1]", value)


def choice(key: str, value: Any, allowed: Iterable[Any]) -> None:
    allowed = tuple(allowed)
    if value not in allowed:
        raise one_of(key, value, allowed)
