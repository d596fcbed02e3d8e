"""Alias of :mod:`metriplex.app.plots`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex.plots`` gives that same module object.
Code inside the package imports ``metriplex.app.plots``."""

import sys

from .app import plots as _module

sys.modules[__name__] = _module
