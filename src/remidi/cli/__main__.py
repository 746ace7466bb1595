"""``python -m remidi.cli``: the ``remidi`` command line."""

import sys

from remidi.cli import main

sys.exit(main())
