"""The command line's choices and help come from the registries, so adding a scheme or a
structure spelling is one class (or one table line), never an edit of the help text."""

import re

import pytest

from metriplex import config
from metriplex.cli import build_parser
from metriplex.integrate import ROOT_FINDERS, SCHEMES, AbstractScheme


def _help(command: str, monkeypatch) -> str:
    monkeypatch.setenv("COLUMNS", "10000")  # one line per option: no wrapping at hyphens
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return re.sub(r"\s+", " ", sub.choices[command].format_help())


@pytest.mark.parametrize("command", ["train", "rollout", "evaluate"])
def test_every_registered_scheme_is_in_the_help_with_its_summary(command, monkeypatch):
    text = _help(command, monkeypatch)
    for name, cls in SCHEMES.items():
        assert f"{name} ({cls.summary})" in text
    if command != "train":
        for name, (_, summary) in ROOT_FINDERS.items():
            assert f"{name} ({summary})" in text


@pytest.mark.parametrize("table", ["ENERGY_CHOICES", "ENTROPY_CHOICES", "POISSON_CHOICES",
                                   "FRICTION_CHOICES", "JACOBI_CHOICES"])
def test_structure_options_list_every_spelling_the_checks_accept(table, monkeypatch):
    text = _help("train", monkeypatch)
    for spelling in getattr(config, table).values():
        assert re.sub(r"\s+", " ", spelling) in text


def test_a_scheme_without_a_name_and_summary_cannot_be_made():
    class Nameless(AbstractScheme):
        def step(self, model, x, dt, guess):
            return x, True, 0

        def residual(self, model, x0, x1, dt, terms0, terms1):
            return x1 - x0

    with pytest.raises(TypeError):
        Nameless()


def test_presets_experiments_and_formats_in_the_help_come_from_their_tables(monkeypatch):
    from metriplex.app.experiments import EXPERIMENTS
    from metriplex.io._registry import FORMATS

    assert set(config.PRESETS) == set(EXPERIMENTS)  # one table: an experiment owns its preset
    train, simulate = _help("train", monkeypatch), _help("simulate", monkeypatch)
    reproduce = _help("reproduce", monkeypatch)
    assert " | ".join(config.PRESETS) in train and " | ".join(EXPERIMENTS) in reproduce
    for suffixes, _, writer, layout in FORMATS:
        for suffix in suffixes:  # the formats written, where a command writes data
            written = suffix in simulate and suffix in _help("rollout", monkeypatch)
            assert written == (writer is not None), suffix
        assert re.sub(r"\s+", " ", layout) in train  # the data format, in the epilog
    for name in config.FEATURES:
        assert name in train
