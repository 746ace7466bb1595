"""Development tools of this repository (not installed with ``pip install remidi``); run them from
the repository root with ``python -m tools.<name>``."""
