"""Alias of :mod:`metriplex.app._lock`, its home since the application layer moved to
``metriplex/app/`` (#15); ``import metriplex._lock`` gives that same module object.
Code inside the package imports ``metriplex.app._lock``."""

import sys

from .app import _lock as _module

sys.modules[__name__] = _module
