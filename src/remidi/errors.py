"""User-facing errors.

Anything a user can get wrong (a malformed game file, an unknown algorithm, a value out of
range) raises :class:`RemidiError` with a one-line message that names the offending field and,
where there is a finite set, the allowed values. The CLI prints it as ``remidi: error: ...`` and
exits with status 2, before anything is written.

The validation helpers below (:func:`require`, :func:`choice`, ...) raise those errors; the engine,
the environments and the experiments all use them.
"""

import re
from typing import Any, Iterable


class RemidiError(Exception):
    """A problem with the user's input, reported as one line and exit code 2."""


class ConfigError(RemidiError):
    """An invalid experiment configuration (unknown key, bad value, unknown choice)."""


class GameFileError(RemidiError):
    """A malformed game file given to ``remidi solve``."""


def one_of(field: str, value, allowed) -> ConfigError:
    """Error for a value outside a finite set: names the field, the value and the allowed values."""
    allowed = ", ".join(str(a) for a in allowed)
    return ConfigError(f"{field}: unknown value {value!r}; allowed: {allowed}")


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


def check_name(kind: str, name) -> None:
    """ConfigError unless ``name`` can be a registered ``kind``'s name: a non-empty string of
    letters, digits, ``_``, ``-`` and ``.`` (it is written after ``--algo`` or ``--set score=``,
    in comma-separated lists and in file names)."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name) or name == "all":
        raise ConfigError(f"register_{kind}: name must be a non-empty string of letters, digits, _, - and . "
                          f"(not 'all'), got {name!r}")
