"""``python -m metriplex``: the command line, :func:`metriplex.app.cli.main`."""

import sys

from .app.cli import main

sys.exit(main())
