"""`--help` describes every option of every command, and the data format where data are read."""

import argparse

import pytest

from metriplex.cli import DATA_FORMAT, build_parser


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


@pytest.mark.parametrize("command", ["generate", "simulate", "train", "rollout", "evaluate", "reproduce"])
def test_every_option_and_argument_has_a_description(command):
    p = _subparsers()[command]
    silent = [a.option_strings[0] if a.option_strings else a.dest for a in p._actions
              if not isinstance(a, argparse._HelpAction) and not (a.help or "").strip()]
    assert silent == [], f"`metriplex {command} --help` says nothing about {silent}"
    p.format_help()  # formats without error (e.g. an unescaped % in a help text)


@pytest.mark.parametrize("command", ["train", "rollout", "evaluate"])
def test_commands_that_read_data_describe_the_format(command):
    text = _subparsers()[command].format_help()
    assert "data format" in text and "trajectory,t," in text
    for ext in (".csv", ".npz", ".h5", ".mat"):
        assert ext in DATA_FORMAT
