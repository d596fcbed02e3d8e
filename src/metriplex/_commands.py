"""Alias of :mod:`metriplex.app._commands`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex._commands`` gives that same module object.
Code inside the package imports ``metriplex.app._commands``."""

import sys

from .app import _commands as _module

sys.modules[__name__] = _module
