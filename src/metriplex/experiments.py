"""Alias of :mod:`metriplex.app.experiments`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex.experiments`` gives that same module object.
Code inside the package imports ``metriplex.app.experiments``."""

import sys

from .app import experiments as _module

sys.modules[__name__] = _module
