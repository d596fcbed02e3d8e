"""Alias of :mod:`metriplex.app.config`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex.config`` gives that same module object.
Code inside the package imports ``metriplex.app.config``."""

import sys

from .app import config as _module

sys.modules[__name__] = _module
