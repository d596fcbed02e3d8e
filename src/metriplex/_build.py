"""Alias of :mod:`metriplex.app._build`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex._build`` gives that same module object.
Code inside the package imports ``metriplex.app._build``."""

import sys

from .app import _build as _module

sys.modules[__name__] = _module
