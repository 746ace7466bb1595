"""A task function's keyword arguments (``--task-arg NAME=VALUE``, ``run_ued(task_args=...)``):
parsed, checked against the function's signature before anything is written, and limited to JSON
scalars, which ``config.json`` gives back unchanged."""

from __future__ import annotations

import math
from typing import Any, Sequence

from remidi.envs.interface import UEDTask
from remidi.errors import ConfigError, a_type

SCALARS = (str, int, float, bool, type(None))  # what a task argument may be: JSON gives it back as it was


def task_args_argument(args, key: str = "task_args") -> dict[str, Any]:
    """``args`` (keyword arguments, or None) checked to round-trip through ``config.json``: str keys,
    JSON scalar values (finite floats). ConfigError (one line, naming ``key``)."""
    if args is None:
        return {}
    if not isinstance(args, dict) or not all(isinstance(name, str) and name.isidentifier() for name in args):
        raise ConfigError(f"{key}: must be a dict of keyword arguments (e.g. {{'size': 9, 'dark': True}}), "
                          f"got {described(args)}")
    for name, value in args.items():
        if not isinstance(value, SCALARS) or (isinstance(value, float) and not math.isfinite(value)):
            raise ConfigError(f"{key}: {name} must be a JSON scalar (str, int, float, bool or None) for config.json "
                              f"to record it, got {described(value)}")
    return dict(args)


def parse_task_args(items: Sequence[str], key: str = "--task-arg") -> dict[str, Any]:
    """``["size=9", "dark=true", "name=big"]`` → ``{"size": 9, "dark": True, "name": "big"}``: a
    value is a JSON scalar where it parses, else the string; the last of a repeated name wins.
    ConfigError (one line) for an item not ``NAME=VALUE`` with NAME an identifier."""
    import json

    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name.isidentifier():
            raise ConfigError(f"{key}: expected NAME=VALUE (NAME a keyword argument of the task's function), "
                              f"got {item!r}")
        try:
            value = json.loads(text)
        except ValueError:
            value = text
        out[name] = value if isinstance(value, SCALARS) and value not in (float("inf"), float("-inf")) else text
    return out


def check_task_args(target, path: str, args: dict[str, Any], key: str = "--task-arg") -> None:
    """ConfigError (one line, with the parameters taken) unless ``target`` accepts ``args`` as
    keywords: an unknown name, a missing required parameter, or arguments for a ``UEDTask``."""
    import inspect

    if isinstance(target, UEDTask) or not callable(target):
        if args:
            raise ConfigError(f"{key}: {path} is {a_type(target)}, not a function: it takes no arguments "
                              f"(given: {', '.join(args)})")
        return
    try:
        signature = inspect.signature(target)
    except (TypeError, ValueError):  # a builtin without a signature: its own call says what is wrong
        return
    params = [p for p in signature.parameters.values() if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    accepted = ", ".join(p.name for p in params) or "none"
    takes_any = any(p.kind == p.VAR_KEYWORD for p in signature.parameters.values())
    for name in args:
        named = [p for p in params if p.name == name]
        if not takes_any and (not named or named[0].kind == named[0].POSITIONAL_ONLY):
            raise ConfigError(f"{key}: {name} is no parameter of {path}; it accepts: {accepted}")
    try:
        if args:  # none given: a function that needs some fails when it is called, as any other error of its own
            signature.bind(**args)
    except TypeError as err:
        raise ConfigError(f"{key}: {path} cannot be called with {shown_args(args)} ({err}); it accepts: {accepted}") \
            from None


def shown_args(args: dict[str, Any]) -> str:
    """``size=9, dark=True``, or ``no arguments``."""
    return ", ".join(f"{name}={value!r}" for name, value in args.items()) or "no arguments"


def described(value) -> str:
    """``value`` for a message: its repr where short, else its type's name."""
    text = repr(value)
    return text if len(text) <= 60 else a_type(value)


def parameter_names(target) -> str:
    """The names of ``target``'s parameters, comma-separated (``none``; ``?`` where unknown)."""
    import inspect

    try:
        names = [p.name for p in inspect.signature(target).parameters.values()
                 if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    except (TypeError, ValueError):
        return "?"
    return ", ".join(names) or "none"
