"""User-facing errors.

Anything a user can get wrong (a malformed game file, an unknown algorithm, a value out of
range) raises :class:`RemidiError` with a one-line message that names the offending field and,
where there is a finite set, the allowed values. The CLI prints it as ``remidi: error: ...`` and
exits with status 2, before anything is written.
"""


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
