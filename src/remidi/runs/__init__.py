"""The commands that read run folders (``remidi run``'s outputs): ``status``, ``table``,
``compare``, ``evaluate`` and ``render``, one module each."""

from __future__ import annotations

from pathlib import Path

from remidi.errors import ConfigError


def require_folder(flag: str, folder: Path) -> None:
    """ConfigError (one line, starting with ``flag``) when ``folder`` does not exist or is not a
    folder: said as such, before a command looks for a run in it."""
    folder = Path(folder)
    if not folder.exists():
        raise ConfigError(f"{flag}: {folder} does not exist")
    if not folder.is_dir():
        raise ConfigError(f"{flag}: {folder} is a file, not a folder")
