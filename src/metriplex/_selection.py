"""Alias of :mod:`metriplex.app._selection`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex._selection`` gives that same module object.
Code inside the package imports ``metriplex.app._selection``."""

import sys

from .app import _selection as _module

sys.modules[__name__] = _module
