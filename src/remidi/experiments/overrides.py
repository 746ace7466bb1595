"""Experiment configuration: presets, ``--set key=value`` overrides and validation.

A configuration is a frozen dataclass of the paper's values; a preset is a dict of overrides
(``paper`` is empty) and ``--set`` adds more, dotted keys reaching nested dataclasses
(``ppo.lr``). Every problem is a one-line :class:`~remidi.errors.ConfigError` naming the key."""

from __future__ import annotations

import dataclasses
import decimal
import math
import sys
import typing
from typing import Any, Iterable

from remidi.errors import ConfigError
from remidi.files import flat_keys


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
    """All settable keys of a (nested) config dataclass, dotted, in declaration order; keys named in
    the defining module's ``DERIVED_KEYS`` (e.g. ``ppo.total_updates``) are not settable."""
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


def key_help(config, key: str) -> str:
    """The one-line ``help`` metadata of dotted ``key``'s field (the one source of ``remidi list``),
    else ``""``."""

    def from_metadata(cfg, dotted: str) -> str:
        head, _, rest = dotted.partition(".")
        for f in dataclasses.fields(cfg):
            if f.name == head:
                return from_metadata(getattr(cfg, head), rest) if rest else f.metadata.get("help", "")
        return ""

    return from_metadata(config, key)


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
        try:  # exact decimal arithmetic: 10**30 or "1e30" stays 10**30 (a float would round it)
            number = decimal.Decimal(str(text).strip())
        except (TypeError, ValueError, decimal.InvalidOperation):
            raise ConfigError(f"{key}: expected an integer, got {text!r}") from None
        if not number.is_finite() or number.adjusted() > 100 or number != number.to_integral_value():
            raise ConfigError(f"{key}: expected an integer (at most 100 digits), got {text!r}")
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
    """``config`` with ``overrides`` (dotted keys → text or JSON values) applied; ``prefix``:
    ``config``'s dotted path, for errors."""
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


def get_value(config, key: str) -> Any:
    """The value of the dotted ``key`` in ``config`` (``get_value(cfg, "ppo.lr")``)."""
    for part in key.split("."):
        config = getattr(config, part)
    return config


def nearest_divisor(length: int, target: float) -> int:
    """The divisor of ``length`` closest to ``target`` in ratio (|log(d / target)|; the larger on
    a tie): 20 updates at a target of 3.3 give 4; a prime length gives itself or 1."""
    if length >= 2**31:  # no run is that long (validation refuses it): no divisor search over it
        return max(1, int(math.floor(target + 0.5)))
    small = [d for d in range(1, math.isqrt(length) + 1) if length % d == 0]
    divisors = small + [length // d for d in small]
    return min(divisors, key=lambda d: (abs(math.log(d / max(target, 1e-9))), -d))


def scale_dependents(config, base, overrides: dict[str, Any], rules: dict[str, tuple[str, ...]],
                     divisors: tuple[str, ...] = (), floors: dict[str, int] | None = None,
                     where_set: str = "with --set"):
    """Scale the keys depending on a length the user changed, in proportion; returns ``(config,
    note)``, ``note`` one line saying what was scaled (None: nothing).

    ``rules`` maps a length (``num_updates``) to its dependent keys. A dependent key the overrides
    leave alone becomes ``max(1, round(base value × new length / base length))``, ``base`` the
    preset's configuration. A key in ``divisors`` (a block length: a short last block compiles another
    program) becomes the nearest divisor of the new length instead. ``floors``: a scaled key is at
    least ``min(floor, new length)``. ``where_set``: the note's words for where keys are given."""
    scaled: dict[str, int] = {}
    parts = []
    for length, dependents in rules.items():
        if length not in overrides:
            continue
        old, new = get_value(base, length), get_value(config, length)
        if not (isinstance(old, int) and isinstance(new, int)) or old < 1 or new < 1 or old == new:
            continue
        changes = []
        for key in dependents:
            if key in overrides:
                continue
            value = get_value(base, key)
            wanted = max(value * new / old, min((floors or {}).get(key, 1), new))
            target = nearest_divisor(new, wanted) if key in divisors else max(1, int(math.floor(wanted + 0.5)))
            if target != value:
                scaled[key] = target
                changes.append(f"{key} {value} → {target}")
        if changes:
            parts.append(f"{length} {old} → {new}, so scaled {', '.join(changes)}")
    if not scaled:
        return config, None
    config = apply_overrides(config, scaled, source="scaling")
    return config, f"{'; '.join(parts)} (set them {where_set} to choose other values)"


def config_to_dict(config) -> dict[str, Any]:
    return dataclasses.asdict(config)


# keys added with a default that changes what a run does, and the value a run written before the
# key existed used: such a run (its config.json without the key) resumes as it started
BEFORE_THE_KEY = {"remidi.belief_spread": 0.0}


def config_from_dict(cls, data: dict[str, Any]):
    """Rebuild a config dataclass from :func:`config_to_dict` output (e.g. a run's config.json); a
    key of :data:`BEFORE_THE_KEY` it lacks takes the value the run was written with."""
    flat = flat_keys(data)
    settable = set(field_names(cls()))
    derived = {key for c in cls.__mro__ for key in getattr(sys.modules.get(c.__module__), "DERIVED_KEYS", ())}
    foreign = [k for k in flat if k not in settable and k not in derived]
    if foreign:  # another experiment's config (its file edited, or copied into this folder): nothing is trained
        raise ConfigError(f"config.json: {', '.join(foreign[:3])}{' …' if len(foreign) > 3 else ''} "
                          f"{'is no key' if len(foreign) == 1 else 'are no keys'} of this experiment's config; "
                          f"the file was written for another experiment or edited")
    flat.update({k: v for k, v in BEFORE_THE_KEY.items() if k in settable and k not in flat})
    return apply_overrides(cls(), {k: v for k, v in flat.items() if k in settable}, source="config.json")
