"""Plugins: modules that register algorithms, scores and networks (:func:`remidi.register_algorithm`,
:func:`remidi.register_score`, :func:`remidi.register_network`) for the command line, which
imports them before it reads its arguments, so that ``--algo NAME``, ``--set score=NAME``,
``--set network=NAME``, ``remidi list`` and ``--resume`` of a run that used them see the
registered entries.

Two ways to name them (both may be used):

* the environment variable ``REMIDI_PLUGINS``: comma-separated module names, importable from
  ``sys.path`` (``REMIDI_PLUGINS=my_score PYTHONPATH=examples remidi run lever --set score=abs_gae``);
* the entry-point group ``remidi.plugins`` of an installed package (``pyproject.toml``:
  ``[project.entry-points."remidi.plugins"] my_algos = "my_package.algos"``).

A Python program that registers its entries itself, before calling :func:`remidi.run_ued` or
:func:`remidi.cli.main`, needs neither.
"""

from __future__ import annotations

import importlib
import os

from remidi.errors import RemidiError

ENV = "REMIDI_PLUGINS"
GROUP = "remidi.plugins"
_loaded: set[str] = set()  # what this process has imported already


def _reason(err: BaseException) -> str:
    first = (str(err).strip().splitlines() or [""])[0]
    return f"{type(err).__name__}{': ' + first if first else ''}"


def load_plugins() -> list[str]:
    """Import the modules ``REMIDI_PLUGINS`` names and load the ``remidi.plugins`` entry points
    (each once per process); the names loaded now. RemidiError (one line) for one that fails."""
    done = []
    for name in (part.strip() for part in os.environ.get(ENV, "").split(",")):
        if name and name not in _loaded:
            try:
                importlib.import_module(name)
            except RemidiError as err:  # a registration refused: its own line, with where it came from
                raise RemidiError(f"{ENV}: {name}: {err}") from None
            except (Exception, SystemExit) as err:  # SystemExit: a module that parses arguments or exits on import
                raise RemidiError(f"{ENV}: cannot import {name} ({_reason(err)})") from None
            _loaded.add(name)
            done.append(name)
    from importlib.metadata import entry_points

    for ep in entry_points(group=GROUP):
        key = f"{ep.name}={ep.value}"
        if key not in _loaded:
            try:
                ep.load()
            except RemidiError as err:
                raise RemidiError(f"plugin {ep.name} ({ep.value}): {err}") from None
            except Exception as err:
                raise RemidiError(f"plugin {ep.name} ({ep.value}, entry point group {GROUP}): "
                                  f"cannot load it ({_reason(err)})") from None
            _loaded.add(key)
            done.append(key)
    return done
