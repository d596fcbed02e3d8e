"""The application layer: everything that turns text into objects and results into files.

``config`` (the typed run configuration; the option strings are parsed here and in the modules
it reads: ``_option`` a structure option's kind and argument and ``--param`` values,
``_spellings`` and ``_thermal`` their arguments, ``_selection`` trajectory ids; nothing outside
this package parses them), ``_build`` (a configuration -> model, loss, stopping
rule), ``runs`` and ``_lock`` (run folders and their lock), ``plots`` (figures),
``experiments`` (the reference experiments), ``cli`` (the parser and ``main``) and
``_commands`` (what each command does).

The core (``data``, ``structure``, ``losses``, ``train``, ``integrate``, ``diagnostics``,
``verdict``, ``systems``, ``io``, ...) never imports this package; ``tests/test_layers.py``
checks that. The old paths (``metriplex.config``, ``metriplex.cli``, ...) are aliases of
these modules, kept so that existing imports go on working.
"""
