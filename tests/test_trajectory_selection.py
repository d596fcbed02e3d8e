"""Which trajectories train, validate and test (issue 14): `--trajectories`, `--validation-ids`
and `--split` for `train`, `--trajectories` for `rollout` and `evaluate`; the ids used are
recorded in the run folder, and `--resume` refuses other data or another split.

Every refusal is one message (the rule, the value, the fix), exit status 2, no traceback, and
nothing written. The tests that need a run share the session's short training
(``trained_run`` in tests/conftest.py: ``--trajectories 0-5 --validation-ids 4,5`` on 8
trajectories).
"""

import contextlib
import io
import dataclasses
import json
import re
import subprocess

import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex._errors import MetriplexError
from metriplex.cli import main
from metriplex.config import (
    TrajectoryIds,
    check_selection,
    choose_trajectories,
    format_ids,
    parse_ids,
    read_split,
)
from helpers import oscillator_data


def run(*args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:  # argparse usage errors
            code = e.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def refused(res, pattern):
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr, res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("metriplex"), res.stderr
    assert re.search(pattern, res.stderr), res.stderr


STRUCTURE = ["--entropy", "sum:2", "--poisson", "canonical:1", "--width", "8", "--quiet"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("selection")
    mx.write(tmp / "data.npz", oscillator_data())
    (tmp / "model").mkdir()
    model = mx.GenericModel(mx.MLPPotential(3, width=4, depth=1, key=jr.key(0)),
                            mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    mx.save(tmp / "model" / "model.mpx", model, n=3, names=("q", "p", "s"))
    splits = {
        "overlap.json": {"train": [0, 1, 2], "validation": [2, 3]},
        "test_overlap.json": {"train": [0, 1], "validation": [2], "test": [1, 5]},
        "unknown_key.json": {"train": [0, 1], "valid": [2]},
        "not_ints.json": {"train": [0, 1.5], "validation": [2]},
        "empty_train.json": {"train": [], "validation": [2]},
        "list.json": [0, 1, 2],
        "missing_ids.json": {"train": [0, 1, 40], "validation": [41]},
    }
    for name, obj in splits.items():
        (tmp / name).write_text(json.dumps(obj))
    (tmp / "broken.json").write_text('{"train": [0, 1')
    (tmp / "folder").mkdir()
    return tmp


# -- the IDS syntax ---------------------------------------------------------------------------

def test_ids_syntax():
    assert parse_ids("0,3,5-9", "--trajectories").ranges == ((0, 0), (3, 3), (5, 9))
    assert parse_ids(" 7 , 2-4,3,5", "--trajectories").ranges == ((2, 5), (7, 7))
    huge = parse_ids("0-999999999999", "--trajectories")  # kept as a range: no memory
    assert len(huge) == 10**12
    assert list(parse_ids("1,3-4", "--trajectories").pick(np.arange(6), "data")) == [1, 3, 4]
    assert format_ids([0, 1, 2, 3, 7, 9, 10]) == "0-3,7,9-10"
    # Negative ids, which data files may hold, are selectable, and said as they are parsed.
    assert parse_ids("-5--3,-1-1,7", "--trajectories").ranges == ((-5, -3), (-1, 1), (7, 7))
    assert format_ids([-5, -4, -3, -1, 0, 1]) == "-5--3,-1-1"
    assert format_ids(range(0, 40, 2)).endswith("(20 ids)")
    assert len(TrajectoryIds.of([], "x")) == 0


@pytest.mark.parametrize(
    "text,pattern",
    [
        ("", r"--trajectories expects a comma list .* such as 0,3,5-9; got an empty value"),
        ("1,,2", r"got '1,,2', in which an empty item"),
        ("1,", r"got '1,', in which an empty item"),
        ("a", r"got 'a', in which 'a' is neither an id nor a range LO-HI"),
        ("2.0", r"'2\.0' is neither an id nor a range"),
        ("--1", r"'--1' is neither an id nor a range"),
        ("-2--5", r"the range '-2--5' .* runs backwards; write it from low to high \(-5--2\)"),
        ("3-", r"'3-' is neither an id nor a range"),
        ("1-2-3", r"'1-2-3' is neither"),
        ("9-5", r"the range '9-5' in '9-5' runs backwards; write it from low to high \(5-9\)"),
        ("1" + "0" * 30, r"too large"),
    ],
)
def test_malformed_ids(text, pattern):
    with pytest.raises(MetriplexError, match=pattern):
        parse_ids(text, "--trajectories")


def test_ids_not_in_the_data_are_named_even_in_a_huge_range():
    with pytest.raises(MetriplexError, match=r"--trajectories '5,30,40-1000000000' names "
                       r"999999962 trajectory ids that are not in the data \(30, 40, 41, 42, 43, "
                       r"\.\.\.\); the ids there are 0-19 \(20 trajectories\)"):
        parse_ids("5,30,40-1000000000", "--trajectories").pick(np.arange(20), "the data")


# -- refusals on the command line, before any work --------------------------------------------

@pytest.mark.parametrize(
    "options,pattern",
    [
        (["--trajectories", "0-9"], r"--trajectories '0-9' names 2 trajectory ids that are not "
         r"in the data file '.*data\.npz' \(8, 9\); the ids there are 0-7 \(8 trajectories\)"),
        (["--trajectories", "3,,4"], r"--trajectories expects .*; got '3,,4'"),
        (["--validation-ids", "5-3"], r"--validation-ids: the range '5-3'"),
        (["--trajectories", "0-3", "--validation-ids", "4"],
         r"--validation-ids '4' names 1 trajectory id that is not in the selection of "
         r"--trajectories '0-3' \(4\)"),
        (["--validation-ids", "8"], r"--validation-ids '8' names 1 trajectory id that is not in "
         r"the data file"),
        (["--trajectories", "2-3", "--validation-ids", "2-3"],
         r"--validation-ids '2-3' takes every selected trajectory \(2-3\) for validation, which "
         r"leaves none to train on"),
        (["--validation-ids", "0-7"], r"takes every selected trajectory \(0-7\)"),
        (["--validation-ids", "1", "--validation", "0.3"],
         r"--validation-ids '1' names the validation trajectories and --validation 0\.3 takes a "
         r"random fraction of them; got both\. Give one of them"),
        (["--split", "{f}/list.json", "--trajectories", "1"],
         r"--split '.*list\.json' chooses the training and validation trajectories, and so does "
         r"--trajectories; got both"),
        (["--split", "{f}/overlap.json"], r"the 'train' and 'validation' lists share 1 "
         r"trajectory id \(2\); a trajectory either trains or validates"),
        (["--split", "{f}/test_overlap.json"], r"the 'train' and 'test' lists share 1 trajectory "
         r"id \(1\); a test trajectory must never train or validate"),
        (["--split", "{f}/unknown_key.json"], r"must hold the lists \"train\" and "
         r"\"validation\" \(optionally \"test\"\), or be a run folder's config\.json; found "
         r"train, valid"),
        (["--split", "{f}/not_ints.json"], r"the 'train' list of --split file .* must be a list "
         r"of integer trajectory ids .*; got \[0, 1\.5\]"),
        (["--split", "{f}/empty_train.json"], r"the 'train' list is empty; at least one "
         r"trajectory must train"),
        (["--split", "{f}/list.json"], r"must hold a JSON object .*; it holds a list"),
        (["--split", "{f}/broken.json"], r"--split file .*broken\.json' is not valid JSON"),
        (["--split", "{f}/nothere.json"], r"--split file .*nothere\.json' does not exist"),
        (["--split", "{f}/folder"], r"--split '.*folder' is a folder without config\.json"),
        (["--split", "{f}/missing_ids.json"], r"--split '.*missing_ids\.json' names 2 "
         r"trajectory ids that are not in the data file .* \(40, 41\)"),
        (["--dt", "0"], r"--dt must be a positive finite number; got 0\.0"),
        (["--dt", "nan"], r"--dt must be a positive finite number; got nan"),
    ],
)
def test_train_refuses_a_bad_selection(files, tmp_path, options, pattern):
    options = [o.replace("{f}", str(files)) for o in options]
    res = run("train", files / "data.npz", "--out", tmp_path / "r", "--steps", "20",
              *STRUCTURE, *options)
    refused(res, pattern)
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("command", ["rollout", "evaluate"])
@pytest.mark.parametrize(
    "options,pattern",
    [
        (["--trajectories", "7-12"], r"--trajectories '7-12' names 5 trajectory ids that are "
         r"not in the data file '.*data\.npz' \(8, 9, 10, 11, 12\); the ids there are 0-7"),
        (["--trajectories", "x"], r"--trajectories expects .*; got 'x'"),
        (["--dt", "-0.1"], r"--dt must be a positive finite number; got -0\.1"),
    ],
)
def test_rollout_and_evaluate_refuse_a_bad_selection(files, tmp_path, command, options,
                                                     pattern):
    out = ["--out", tmp_path / ("p.npz" if command == "rollout" else "m.json")]
    refused(run(command, files / "model", files / "data.npz", *out, *options), pattern)
    assert list(tmp_path.iterdir()) == []


# -- a run: the ids it used, reusing its split, resuming it ------------------------------------

@pytest.fixture
def trained(trained_run):
    """The run folder of the session's shared training (tests/conftest.py), made by
    ``train DATA --steps 20 [STRUCTURE] --trajectories 0-5 --validation-ids 4,5`` with DATA
    its ``data.npz`` (``oscillator_data()``, as here)."""
    return trained_run / "run"


def test_the_run_records_the_ids_it_used(trained):
    data_file = trained.parent / "data.npz"
    header = json.loads((trained / "config.json").read_text())
    assert header["train_trajectories"] == [0, 1, 2, 3]
    assert header["validation_trajectories"] == [4, 5]
    assert header["validation_by"] == "ids"
    data = mx.read(data_file)
    assert header["data"]["trajectory_ids"] == list(range(8))  # the file's, not the selection
    assert header["data"]["shape"] == [len(data.t), 3]
    assert header["data"]["sha256"] == data.fingerprint()["sha256"]
    assert header["data"]["file"] == str(data_file) and header["data"]["dt"] is None
    metrics = json.loads((trained / "metrics.json").read_text())
    assert metrics["trajectory_ids"] == [4, 5] and metrics["trajectories"] == 2


def test_a_split_is_reused_exactly_from_a_run_folder_or_a_file(files, trained, tmp_path):
    data = mx.read(files / "data.npz")
    for split in (trained, trained / "config.json"):
        chosen, held = choose_trajectories(data.ids, "data", check_selection(split=split))
        assert list(chosen) == [0, 1, 2, 3, 4, 5] and list(held) == [4, 5]
    (tmp_path / "s.json").write_text(json.dumps({"train": "0-2", "validation": [6],
                                                 "test": [7]}))
    train, valid = read_split(tmp_path / "s.json")
    assert train.ranges == ((0, 2),) and valid.ranges == ((6, 6),)
    (tmp_path / "none.json").write_text(json.dumps({"train": [0, 1]}))  # no validation
    chosen, held = choose_trajectories(data.ids, "data",
                                       check_selection(split=tmp_path / "none.json"))
    assert list(chosen) == [0, 1] and list(held) == []
    # Without any option: nothing chosen, the --validation fraction applies as before.
    assert choose_trajectories(data.ids, "data", check_selection()) == (None, None)


def test_resume_refuses_other_data_or_another_split(trained, tmp_path):
    data_file = trained.parent / "data.npz"
    same = ["--steps", "20", *STRUCTURE, "--resume"]
    before = json.loads((trained / "config.json").read_text())
    other = oscillator_data()
    other = mx.Trajectories(other.trajectory, other.t, other.x + 1e-9, other.names)
    mx.write(tmp_path / "other.npz", other)
    sha = before["data"]["sha256"][:12]
    refused(run("train", tmp_path / "other.npz", "--out", trained, *same, "--trajectories",
                "0-5", "--validation-ids", "4,5"),
            rf"--resume needs the data of the interrupted run, but they differ: it trained on "
            rf"'.*data\.npz' \(8 trajectories, ids 0-7; 168 rows x 3 variables; sha256 {sha}\); "
            r"this command gives '.*other\.npz' \(8 trajectories, ids 0-7; 168 rows x 3 "
            r"variables; sha256 (?!" + sha + r")[0-9a-f]{12}\)\. Resume with the same data file")
    # Another step is refused before the resume is considered: it would replace the file's
    # own times (a file without times, trained with --dt, resumes only with the same --dt).
    refused(run("train", data_file, "--out", trained, *same, "--trajectories", "0-5",
                "--validation-ids", "4,5", "--dt", "0.2"),
            r"--dt 0\.2 would replace the file's own times, whose steps are 0\.1\.")
    refused(run("train", data_file, "--out", trained, *same, "--trajectories", "0-5",
                "--validation-ids", "3,5"),
            r"--resume needs the trajectories of the interrupted run, but they differ: it "
            r"trained on 0-3 and validated on 4-5; this command trains on 0-2,4 and validates "
            r"on 3,5\. .*--split RUN_DIR")
    refused(run("train", data_file, "--out", trained, *same),
            r"it trained on 0-3 and validated on 4-5; this command trains on")
    lr = before["config"]["lr"]
    refused(run("train", data_file, "--out", trained, *same, "--trajectories", "0-5",
                "--validation-ids", "4,5", "--lr", str(lr / 10)),
            rf"--resume needs the options of the interrupted run, but they differ: --lr was "
            rf"{lr!r}, given {lr / 10!r}\. Repeat the original options")
    assert json.loads((trained / "config.json").read_text()) == before  # untouched


def test_rollout_and_evaluate_on_chosen_trajectories(trained, tmp_path):
    # Two trajectories, as many as the run validates on: the rollout reuses the compiled
    # rollout of the training's held-out checks (comma lists with ranges: test_ids_syntax).
    res = run("rollout", trained, trained.parent / "data.npz", "--out", tmp_path / "p.npz",
              "--trajectories", "1,7")
    assert res.returncode == 0, res.stderr
    assert list(mx.read(tmp_path / "p.npz").ids) == [1, 7]
    status = json.loads((tmp_path / "p.npz.status.json").read_text())
    assert [e["trajectory"] for e in status["trajectories"]] == [1, 7]
    res = run("evaluate", trained, trained.parent / "data.npz", "--out", tmp_path / "m.json",
              "--trajectories", "6-7", "--no-verdict")
    assert res.returncode == 0, res.stderr
    metrics = json.loads((tmp_path / "m.json").read_text())
    assert metrics["trajectory_ids"] == [6, 7] and len(metrics["rollout_error"]) == 2


def test_resume_compares_what_decided_options_decide():
    # A run saved with the wall decided (confine false, or spelled out before the option's
    # default became None) resumes with the option left out where it decides the same; a real
    # difference names the flags, not False/None.
    from metriplex.app.config import RunConfig
    from metriplex.app._resume import resume_differences

    given = RunConfig(entropy="sum:2", poisson="canonical:1")  # the wall decided: on
    assert resume_differences(dataclasses.replace(given, confine=True), given) == ""
    assert resume_differences(dataclasses.replace(given, reversible_first=True,
                                                   w_temperature=1.0), given) == ""
    said = resume_differences(dataclasses.replace(given, confine=False), given)
    assert said == "it ran with --no-confine, this command gives --confine"
    penalty = RunConfig(degeneracy="soft")  # M grad E = 0 a penalty: the wall decided off
    assert resume_differences(dataclasses.replace(penalty, confine=False), penalty) == ""


def test_resume_names_the_step_that_gave_a_file_its_times():
    # A file without times trained with --dt 0.1 and resumed with --dt 0.2 has other data
    # (other times): the refusal names both steps. (A file with its own times never gets
    # that far with another step: its read refuses it.)
    from metriplex.app._resume import check_resume

    info = {"file": "d.mat", "trajectory_ids": [0, 1], "shape": [40, 2]}
    with pytest.raises(mx.MetriplexError, match=r"it trained on 'd\.mat' with --dt 0\.1 .*; "
                       r"this command gives 'd\.mat' with --dt 0\.2 .*same --dt"):
        check_resume({"data": {**info, "dt": 0.1, "sha256": "a" * 64}},
                      {**info, "dt": 0.2, "sha256": "b" * 64}, None, None)
