"""Alias of :mod:`metriplex.app.cli`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex.cli`` gives that same module object.
Code inside the package imports ``metriplex.app.cli``."""

import sys

from .app import cli as _module

sys.modules[__name__] = _module
