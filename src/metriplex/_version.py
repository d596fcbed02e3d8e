"""The version of metriplex, in a module of its own so that any module can read it without
importing the package (and, through it, every module it re-exports)."""

__version__ = "0.1.0"
