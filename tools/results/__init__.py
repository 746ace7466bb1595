"""The results page's generator (``docs/results.md`` and the README's claims table), a development
tool of this repository, not part of the installed package: run it from the repository root,
``python -m tools.results.page`` (``--check``: exit 1 where the page or the README is stale)."""
