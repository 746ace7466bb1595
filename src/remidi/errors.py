"""User-facing errors.

Anything a user can get wrong (a malformed game file, an unknown algorithm, a value out of
range) raises :class:`RemidiError` with a one-line message that names the offending field and,
where there is a finite set, the allowed values. The CLI prints it as ``remidi: error: ...`` and
exits with status 2, before anything is written.

The validation helpers below (:func:`require`, :func:`choice`, ...) raise those errors; the engine,
the environments and the experiments all use them.
"""

import re
from dataclasses import dataclass
from typing import Any, Iterable


class RemidiError(Exception):
    """A problem with the user's input, reported as one line and exit code 2."""


class ConfigError(RemidiError):
    """An invalid experiment configuration (unknown key, bad value, unknown choice)."""


class GameFileError(RemidiError):
    """A malformed game file given to ``remidi solve``."""


def a_type(value) -> str:
    """``value``'s type's name with its article, for messages: ``an int``, ``a dict``, ``an
    UnderspecifiedEnv``, ``a UEDTask`` (an acronym's U is said "you")."""
    name = type(value).__name__
    vowel = name[:1].lower() in "aeiou" and not (name[:1] == "U" and name[1:2].isupper())
    return f"{'an' if vowel else 'a'} {name}"


def one_of(field: str, value, allowed) -> ConfigError:
    """Error for a value outside a finite set: names the field, the value and the allowed values."""
    allowed = ", ".join(str(a) for a in allowed)
    return ConfigError(f"{field}: unknown value {value!r}; allowed: {allowed}")


# ------------------------------------------------------------------------------ the caller's words
@dataclass(frozen=True)
class Naming:
    """How a message names what the user gave: the command line's options (:data:`COMMAND_LINE`) or
    a Python caller's arguments (:data:`PYTHON`, ``run_ued``'s). The caller chooses it once (a
    run's ``RunSpec.naming``); the checks it reaches read their words from it."""

    algos: str = "--algo"  # the algorithms
    seeds: str = "--seeds"  # the seeds (the command line's count)
    first_seed: str = "--seed"  # the first seed
    out: str = "--out"  # the run folder of a fresh run
    resume: str = "--resume"  # the run folder of a resumed run
    overrides: str = "--set"  # the configuration keys given, as the field of an unknown key
    setting_form: str = "--set {key}={value}"  # how to give one key a value
    where_set: str = "with --set"  # where keys are given, in a sentence ("set them with --set")
    resume_form: str = "--resume {out}"  # how to resume the run in a folder
    resumes: str = "--resume"  # what resumes a run, as a sentence's subject ("--resume writes ...")
    seed_fix: str = "; lower --seed or --seeds"  # what lowers a seed out of range

    def setting(self, key: str, value: Any) -> str:
        """``--set num_envs=N`` or ``config["num_envs"]=N``: how to give ``key`` the value ``value``."""
        return self.setting_form.format(key=key, value=value)

    def resuming(self, out: Any) -> str:
        """``--resume OUT`` or ``out='OUT', resume=True``: how to resume the run in ``out``."""
        return self.resume_form.format(out=str(out))


#: the command line's words (``remidi run``)
COMMAND_LINE = Naming()
#: ``run_ued``'s words: its arguments, a configuration key as an entry of its ``config`` dict
PYTHON = Naming(algos="algos", seeds="seeds", first_seed="seeds", out="out", resume="out", overrides="config",
                setting_form='config["{key}"]={value}', where_set="in config", resume_form="out={out!r}, resume=True",
                resumes="resume=True", seed_fix="")


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


# ------------------------------------------------------------------------------ the user's code
DEBUG_ENV = "REMIDI_DEBUG"  # REMIDI_DEBUG=1: an error in the user's code shows its whole traceback


def debugging() -> bool:
    """Whether ``REMIDI_DEBUG`` asks for the whole traceback of an error in the user's code."""
    import os

    return os.environ.get(DEBUG_ENV, "").strip().lower() not in ("", "0", "off", "false", "no")


def _innermost(tb) -> str:
    """``file.py:LINE`` of the last frame of traceback ``tb`` outside this package (the user's
    code, where it failed); "" where there is none."""
    import traceback

    frames = [f for f in traceback.extract_tb(tb) if "/remidi/" not in f.filename.replace("\\", "/")]
    return f"{frames[-1].filename.rsplit('/', 1)[-1]}:{frames[-1].lineno}" if frames else ""


def user_code_error(what: str, err: BaseException) -> ConfigError:
    """One line for an exception ``err`` raised by the user's code while doing ``what``: its type,
    the first line of its message, where it was raised, and how to see the whole traceback."""
    detail = (str(err).strip().splitlines() or [""])[0]
    where = _innermost(err.__traceback__)
    return ConfigError(f"{what} failed ({type(err).__name__}{': ' + detail if detail else ''}"
                       f"{', at ' + where if where else ''}; {DEBUG_ENV}=1 shows the traceback)")


_RAISED = re.compile(r"^([A-Za-z_][\w.]*(?:Error|Exception|Interrupt|Exit|Warning)|[A-Z]\w*): (.*)$")
_FRAME = re.compile(r'^\s*File "([^"]+)", line (\d+)')


def callback_failure(err: BaseException) -> RemidiError | None:
    """One line for an exception that the user's code raised inside a JAX callback (``jax.debug.callback``,
    ``jax.pure_callback``) while a compiled program ran: JAX reports it as a ``JaxRuntimeError``
    whose message holds the Python traceback as text. None for any other exception."""
    text = str(err)
    if type(err).__name__ != "JaxRuntimeError" or "allback" not in text.split("\n", 1)[0]:
        return None
    lines = text.split("--------------------", 1)[0].strip().splitlines()
    raised = next((m for m in map(_RAISED.match, reversed(lines)) if m), None)
    frames = [m for m in map(_FRAME.match, lines) if m and "/jax/" not in m.group(1) and "/jaxlib/" not in m.group(1)]
    where = f", at {frames[-1].group(1).rsplit('/', 1)[-1]}:{frames[-1].group(2)}" if frames else ""
    what = f"{raised.group(1)}: {raised.group(2)}" if raised else lines[-1] if lines else type(err).__name__
    return RemidiError(f"the environment (or other code of yours in a JAX callback) raised {what} "
                       f"({where.removeprefix(', at ') + '; ' if where else ''}{DEBUG_ENV}=1 shows the traceback)")


def missing_extra(err: ModuleNotFoundError, what: str, extra: str, note: str = "") -> RemidiError:
    """One line for ``what`` needing an optional dependency that is not installed (``err``): the
    ``pip install`` of the package's ``extra`` to run."""
    return RemidiError(f"{what} needs the {err.name or 'missing'} package, which is not installed: "
                       f"pip install \"remidi[{extra}]\"{note}")
