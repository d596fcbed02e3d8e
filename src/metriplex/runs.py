"""Alias of :mod:`metriplex.app.runs`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex.runs`` gives that same module object.
Code inside the package imports ``metriplex.app.runs``."""

import sys

from .app import runs as _module

sys.modules[__name__] = _module
