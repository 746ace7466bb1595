import sys

from remidi.cli import main

sys.exit(main())
