"""Trajectory files: every format round-trips exactly, and every malformed file is explained.

Round trips compare bits (``float64`` views as ``uint64``), so ``-0.0``, subnormals and the last
digit of every CSV number count. Each malformed-file test pins the message: the rule, the value
found and the fix, raised as :class:`MetriplexError` and never as an h5py/SciPy/NumPy error.
"""

from __future__ import annotations

import tempfile
import zipfile
from pathlib import Path

import h5py
import hypothesis.strategies as st
import numpy as np
import pytest
import scipy.io
import scipy.sparse
from hypothesis import HealthCheck, given, settings

import metriplex as mx
from metriplex import MetriplexError, Trajectories
from metriplex.io import natural_key, read_mat, read_mat_operators, write_mat

EXTS = ["npz", "csv", "h5", "hdf5", "mat"]


def _same(a: Trajectories, b: Trajectories) -> None:
    """Bit-identical rows, ids and names."""
    assert a.names == b.names
    assert np.array_equal(a.trajectory, b.trajectory)
    assert a.t.dtype == b.t.dtype == a.x.dtype == b.x.dtype == np.float64
    assert np.array_equal(a.t.view(np.uint64), b.t.view(np.uint64))
    assert a.x.shape == b.x.shape
    assert np.array_equal(a.x.view(np.uint64), b.x.view(np.uint64))


def _ragged() -> Trajectories:
    """Three trajectories of lengths 4, 2, 6 with non-uniform times and awkward values."""
    rng = np.random.default_rng(0)
    parts = []
    for T in (4, 2, 6):
        t = -1.5 + np.cumsum(rng.uniform(1e-3, 2.0, T))
        x = rng.normal(size=(T, 3)) * 10.0 ** rng.integers(-300, 300, size=(T, 3))
        parts.append((t, x))
    parts[0][1][0] = [-0.0, 5e-324, 0.1]
    data = Trajectories.from_list(parts, names=["q", "p, momentum", 's"1"'])
    # Non-contiguous ids must survive too.
    return Trajectories(np.array([3, 7, 12])[data.trajectory], data.t, data.x, data.names)


def _square(K=3, T=5, n=2, uniform=True) -> Trajectories:
    rng = np.random.default_rng(1)
    t = np.arange(T) * 0.25 if uniform else np.cumsum(rng.uniform(0.1, 1.0, T))
    return Trajectories.from_arrays(t, rng.normal(size=(K, T, n)), names=[f"v{i}" for i in range(n)])


# -- round trips ------------------------------------------------------------------------------

@pytest.mark.parametrize("ext", EXTS)
def test_round_trip_ragged(tmp_path, ext):
    data = _ragged()
    mx.write(tmp_path / f"d.{ext}", data)
    _same(mx.read(tmp_path / f"d.{ext}"), data)


@pytest.mark.parametrize("ext", EXTS)
@pytest.mark.parametrize("uniform", [True, False])
def test_round_trip_equal_lengths(tmp_path, ext, uniform):
    data = _square(uniform=uniform)
    mx.write(tmp_path / f"d.{ext}", data)
    _same(mx.read(tmp_path / f"d.{ext}"), data)


def test_printed_trajectories_are_summarised_not_dumped():
    # A new-user check printed mx.read(...) and got every array in full.
    x = np.zeros((200, 9))
    data = Trajectories.from_list([(np.linspace(0, 20, 200), x), (np.linspace(0, 2, 11), x[:11])],
                                  names=[f"q{i}" for i in range(9)])
    assert repr(data) == ("Trajectories(2 trajectories of 11 to 200 samples; 9 variables "
                          "(q0, q1, q2, q3, q4, q5, ...); t from 0 to 20)")
    one = Trajectories.from_list([(np.arange(3.0), np.ones(3))])
    assert repr(one) == "Trajectories(1 trajectory of 3 samples; 1 variable (x0); t from 0 to 2)"


def test_write_is_dispatched_by_suffix_and_unknown_suffix_refused(tmp_path):
    data = _square()
    mx.write(tmp_path / "d.H5", data)
    assert h5py.is_hdf5(tmp_path / "d.H5")
    with pytest.raises(MetriplexError, match=r"unknown extension '\.parquet'.*\.csv, \.h5"):
        mx.write(tmp_path / "d.parquet", data)
    with pytest.raises(MetriplexError, match="takes a Trajectories; got dict"):
        mx.write(tmp_path / "d.npz", {"t": data.t})


def test_csv_writer_refuses_names_that_would_not_read_back(tmp_path):
    data = _square().with_names([" q", "p"])
    with pytest.raises(MetriplexError, match=r"name ' q' has surrounding whitespace.*Rename"):
        mx.write(tmp_path / "d.csv", data)
    assert not (tmp_path / "d.csv").exists()


# -- HDF5 layout ------------------------------------------------------------------------------

def test_hdf5_layout_written(tmp_path):
    mx.write(tmp_path / "d.h5", _ragged())
    with h5py.File(tmp_path / "d.h5") as f:
        assert sorted(f) == ["trajectory_03", "trajectory_07", "trajectory_12"]
        assert [s for s in f.attrs["names"]] == ["q", "p, momentum", 's"1"']
        assert f["trajectory_07/x"].shape == (2, 3)
        assert f["trajectory_07"].attrs["trajectory"] == 7


def test_hdf5_groups_in_natural_order_names_per_group(tmp_path):
    with h5py.File(tmp_path / "d.h5", "w") as f:
        for name, start in (("run10", 10.0), ("run2", 2.0), ("Run1", 1.0)):
            g = f.create_group(name)
            g["t"] = start + np.array([0.0, 0.5, 2.0])
            g["x"] = np.full(3, start)  # one variable may be a vector
            g.attrs["names"] = ["theta"]
    data = mx.read(tmp_path / "d.h5")
    assert data.names == ("theta",)
    assert data.ids.tolist() == [0, 1, 2]
    assert [t[0] for t, _ in data] == [1.0, 2.0, 10.0]


def test_natural_key():
    names = ["traj10", "traj2", "traj1", "a", "traj02"]
    assert sorted(names, key=natural_key) == ["a", "traj1", "traj02", "traj2", "traj10"]


# -- MATLAB layouts ---------------------------------------------------------------------------

def _spnn(K=3, n=4, T=6, dt=0.01):
    rng = np.random.default_rng(2)
    Z = rng.normal(size=(K, n, T))
    L = np.zeros((n, n))
    L[0, 1], L[1, 0] = 1.0, -1.0
    return Z, L, np.eye(n), dt


def test_mat_spnn_layout(tmp_path):
    """``Z`` (K, n, T), ``t_vec`` (1, T), ``dt`` (1, 1), ``L``, ``M``, as in the SPNN datasets."""
    Z, L, M, dt = _spnn()
    t_vec = dt * np.arange(Z.shape[2])[None]
    scipy.io.savemat(tmp_path / "db.mat", {"Z": Z, "L": L, "M": M, "dt": dt, "t_vec": t_vec})
    data = mx.read(tmp_path / "db.mat")
    assert len(data) == 3 and data.n == 4 and data.names == ("x0", "x1", "x2", "x3")
    for k, (t, x) in enumerate(data):
        assert np.array_equal(t, t_vec[0]) and np.array_equal(x, Z[k].T)
    ops = read_mat_operators(tmp_path / "db.mat")
    assert set(ops) == {"L", "M"}
    assert np.array_equal(ops["L"], L) and np.array_equal(ops["M"], M)


def test_mat_snapshots_before_variables_are_read_by_the_time_vector(tmp_path):
    # numpy's habit, trajectories x snapshots x variables, was read as snapshots of variables
    # where the time vector said otherwise only through a refusal, and with a step silently.
    Z, *_ = _spnn()
    t = 0.1 * np.arange(Z.shape[2])
    scipy.io.savemat(tmp_path / "ktn.mat", {"X": Z.transpose(0, 2, 1), "t": t})
    scipy.io.savemat(tmp_path / "tn.mat", {"x": Z[1].T, "t": t[:, None]})
    data, one = mx.read(tmp_path / "ktn.mat"), mx.read(tmp_path / "tn.mat")
    assert len(data) == 3 and data.n == 4 and len(one) == 1 and one.n == 4
    for k, (tk, x) in enumerate(data):
        assert np.array_equal(tk, t) and np.array_equal(x, Z[k].T)
    assert np.array_equal(one.x, Z[1].T)


def test_mat_step_only_struct_and_char_names(tmp_path):
    Z, *_ = _spnn()
    names = np.array(["q1", "q2", "p1", "p2"])  # saved as a padded char matrix
    scipy.io.savemat(tmp_path / "s.mat", {"data": {"X": Z, "dt": 0.5, "names": names}})
    data = read_mat(tmp_path / "s.mat")
    assert data.names == ("q1", "q2", "p1", "p2")
    assert np.array_equal(next(iter(data))[0], 0.5 * np.arange(6))
    assert read_mat_operators(tmp_path / "s.mat") == {}


def test_mat_single_trajectory_per_trajectory_steps_and_overrides(tmp_path):
    rng = np.random.default_rng(3)
    scipy.io.savemat(tmp_path / "a.mat", {"x": rng.normal(size=(2, 5)), "t": np.linspace(1, 2, 5)})
    one = mx.read(tmp_path / "a.mat")
    assert len(one) == 1 and one.n == 2 and np.array_equal(one.t, np.linspace(1, 2, 5))

    scipy.io.savemat(tmp_path / "b.mat", {"Z": rng.normal(size=(2, 1, 3)), "dt": [[0.1], [0.2]]})
    t0, t1 = (t for t, _ in mx.read(tmp_path / "b.mat"))
    assert np.allclose(t0, [0, 0.1, 0.2]) and np.allclose(t1, [0, 0.2, 0.4])

    scipy.io.savemat(tmp_path / "c.mat", {"Y": rng.normal(size=(2, 3, 4)), "tout": np.arange(4.0)})
    with pytest.raises(MetriplexError, match=r"no state array.*Y \(numeric 2×3×4\); tout"):
        mx.read(tmp_path / "c.mat")
    data = read_mat(tmp_path / "c.mat", states="Y", time="tout")
    assert data.n == 3 and np.array_equal(data.t[:4], np.arange(4.0))
    scipy.io.savemat(tmp_path / "d.mat", {"Z": rng.normal(size=(2, 3, 4))})
    assert np.array_equal(read_mat(tmp_path / "d.mat", dt=2.0).t[:4], [0, 2, 4, 6])


def test_mat_writer_layouts(tmp_path):
    write_mat(tmp_path / "sq.mat", _square(), L=np.eye(2), M=np.zeros((2, 2)))
    raw = scipy.io.loadmat(tmp_path / "sq.mat")
    assert raw["Z"].shape == (3, 2, 5) and raw["t_vec"].shape == (1, 5)
    assert raw["dt"][0, 0] == 0.25
    assert np.array_equal(read_mat_operators(tmp_path / "sq.mat")["L"], np.eye(2))
    mx.write(tmp_path / "nu.mat", _square(uniform=False))
    assert "dt" not in scipy.io.loadmat(tmp_path / "nu.mat")
    mx.write(tmp_path / "rg.mat", _ragged())
    raw = scipy.io.loadmat(tmp_path / "rg.mat")
    assert raw["x"].shape == (12, 3) and "Z" not in raw
    with pytest.raises(MetriplexError, match=r"operator `M` must be 2×2.*got 3×3"):
        write_mat(tmp_path / "bad.mat", _square(), M=np.eye(3))


def _write_mat73(path, variables: dict) -> None:
    """A file laid out as MATLAB's ``save -v7.3``: HDF5, column-major, classes as attributes."""
    with h5py.File(path, "w", userblock_size=512) as f:
        refs = f.create_group("#refs#")
        for key, v in variables.items():
            if isinstance(v, list) and isinstance(v[0], str):  # a cell array of strings
                ref_list = []
                for j, s in enumerate(v):
                    d = refs.create_dataset(f"{key}{j}", data=np.array([[ord(c)] for c in s], np.uint16))
                    d.attrs["MATLAB_class"] = np.bytes_("char")
                    ref_list.append(d.ref)
                ds = f.create_dataset(key, data=np.array(ref_list, dtype=h5py.ref_dtype)[:, None])
                ds.attrs["MATLAB_class"] = np.bytes_("cell")
            elif scipy.sparse.issparse(v):  # compressed sparse columns, 0-based
                v = scipy.sparse.csc_matrix(v)
                g = f.create_group(key)
                g.attrs["MATLAB_class"] = np.bytes_("double")
                g.attrs["MATLAB_sparse"] = np.uint64(v.shape[0])
                g["data"], g["ir"], g["jc"] = v.data, v.indices.astype(np.uint64), v.indptr.astype(np.uint64)
            else:
                ds = f.create_dataset(key, data=np.asarray(v, dtype=np.float64).T)
                ds.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: test HDF5 schema 1.00 .")


def test_mat_v73(tmp_path):
    Z, L, M, dt = _spnn(K=2, n=3, T=4)
    _write_mat73(tmp_path / "v73.mat", {
        "Z": Z, "dt": [[dt]], "t_vec": dt * np.arange(4)[None], "L": L[:3, :3], "M": M[:3, :3],
        "names": ["q", "p", "s"],
    })
    data = mx.read(tmp_path / "v73.mat")
    assert data.names == ("q", "p", "s")
    for k, (t, x) in enumerate(data):
        assert np.array_equal(x, Z[k].T) and np.allclose(t, dt * np.arange(4))
    assert np.array_equal(read_mat_operators(tmp_path / "v73.mat")["L"], L[:3, :3])


# -- malformed files --------------------------------------------------------------------------

def _raises(match: str, kind: str, path: Path) -> None:
    """``mx.read(path)`` raises a MetriplexError matching ``match`` that names the file."""
    with pytest.raises(MetriplexError, match=match) as e:
        mx.read(path)
    assert f"{kind} {str(path)!r}" in str(e.value)


def _bytes(tmp_path, name, content: bytes) -> Path:
    p = tmp_path / name
    p.write_bytes(content)
    return p


def _npz(tmp_path, **arrays) -> Path:
    p = tmp_path / "bad.npz"
    np.savez(p, **arrays)
    return p


def _csv(tmp_path, text: str) -> Path:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    return p


GOOD = dict(trajectory=np.array([0, 0, 1, 1]), t=np.array([0.0, 1, 0, 1]), x=np.ones((4, 2)))


@pytest.mark.parametrize("ext", EXTS)
def test_any_format_empty_garbage_and_truncated(tmp_path, ext):
    with pytest.raises(MetriplexError, match=r"is empty"):
        mx.read(_bytes(tmp_path, f"e.{ext}", b""))
    mx.write(tmp_path / f"ok.{ext}", _ragged())
    whole = (tmp_path / f"ok.{ext}").read_bytes()
    with pytest.raises(MetriplexError, match=r"not a readable|not valid|must start with|not UTF-8"):
        mx.read(_bytes(tmp_path, f"g.{ext}", b"\x89\x00garbage\xff" * 50))
    with pytest.raises(MetriplexError, match=r"truncated"):
        mx.read(_bytes(tmp_path, f"t.{ext}", whole[: len(whole) * 2 // 3]))


@pytest.mark.parametrize(
    "arrays, match",
    [
        (dict(t=GOOD["t"], x=GOOD["x"]), r"lacks the array `trajectory`: without it .* t does not increase at row 2 .*Found \['t', 'x'\]"),
        ({**GOOD, "v": np.ones(4)}, r"unknown array\(s\) \['v'\].*make them columns of `x`"),
        ({**GOOD, "names": np.array(["q"])}, r"got 1 variable names for 2 state columns"),
        ({**GOOD, "names": np.array([1, 2])}, r"`names`.*must hold strings.*int64"),
        ({**GOOD, "x": np.array([[1, 2], [np.nan, 0], [0, 0], [0, 0]])}, r"NaN or inf at row 1"),
        ({**GOOD, "x": np.array([[1, 2], [np.nan, 0], [0, np.inf], [np.nan, 0]])},
         r"NaN or inf at row 1 \(trajectory 0, t=1\.0\)\. 2 other rows \(2, 3\) have them too\."),
        ({**GOOD, "t": np.array([0.0, 1, 1, 1])}, r"strictly increasing.*trajectory 1 has t\[1\]=.*1\.0.* <= t\[0\]="),
        ({**GOOD, "trajectory": np.array([0, 0, 0, 1]), "t": np.arange(4.0)}, r"at least two samples.*trajectory 1 has 1"),
        ({**GOOD, "x": np.ones((4, 2, 2))}, r"x 2-D.*\(4, 2, 2\)"),
        ({**GOOD, "x": np.ones((3, 2))}, r"one entry per row; got 4, 4 and 3"),
        ({**GOOD, "trajectory": np.array(["a", "a", "b", "b"])}, r"trajectory ids must be integers"),
    ],
)
def test_npz_malformed(tmp_path, arrays, match):
    _raises(match, "NPZ file", _npz(tmp_path, **arrays))


def test_npz_pickled_names_and_bare_array(tmp_path):
    p = tmp_path / "bad.npz"
    np.savez(p, **GOOD, names=np.array(["q", "p"], dtype=object), allow_pickle=True)
    with pytest.raises(MetriplexError, match=r"`names`.*stored as Python objects \(pickle\).*dtype=str"):
        mx.read(p)
    np.save(tmp_path / "bare.npy", np.ones(3))
    (tmp_path / "bare.npy").rename(tmp_path / "bare.npz")
    with pytest.raises(MetriplexError, match=r"one bare array of shape \(3,\), not an NPZ archive"):
        mx.read(tmp_path / "bare.npz")


def test_npz_damaged_member(tmp_path):
    p = _npz(tmp_path, **GOOD)
    # Corrupt x's payload inside the archive, keeping the zip directory intact.
    with zipfile.ZipFile(p) as z:
        members = {n: z.read(n) for n in z.namelist()}
    members["x.npy"] = members["x.npy"][:-20]
    with zipfile.ZipFile(p, "w") as z:
        for n, b in members.items():
            z.writestr(n, b)
    with pytest.raises(MetriplexError, match=r"array `x` of NPZ file .* damaged.*truncated"):
        mx.read(p)


@pytest.mark.parametrize(
    "text, match",
    [
        ("\n\n", r"is empty; it holds no header"),
        ("trajectory,t,q\n", r"has a header but no data rows"),
        ("0,0.0,1.0\n0,1.0,2.0\n", r"header `trajectory,t,<name_1>,...`.*got '0,0\.0,1\.0'\. The first line holds numbers: the header line is missing"),
        ("id,time,q\n0,0,1\n", r"header `trajectory,t,<name_1>,...`.*got 'id,time,q'.*rename"),
        ("trajectory,t\n0,0\n0,1\n", r"at least one state column"),
        ("trajectory,t,q,\n0,0,1,2\n", r"header column 4 has no name"),
        ("trajectory,t,q,q\n0,0,1,2\n", r"header column 4 repeats the variable name 'q'"),
        ("trajectory,t,q,p\n0,0,1,2\n0,1,1\n", r"line 3, has 3 columns; the header has 4.*truncated"),
        ("trajectory,t,q\n0,0,1\n0,1,abc\n", r"line 3, column 'q' holds 'abc'; every cell must be a finite number"),
        ("trajectory,t,q\n0,0,1\n0, ,1\n", r"line 3, column 't' is empty"),
        ("trajectory,t,q\n0,0,1\n\n0,1,nan\n", r"line 4, column 'q' holds 'nan'"),
        ("trajectory,t,q\n0,0,1\n0,1,-inf\n", r"line 3, column 'q' holds '-inf'"),
        # Every bad cell in one run, not one per run (a new-user check fixed them one by one).
        ("trajectory,t,q,p\n0,0,1,nan\n0,1,,2\n1,0,x,1\n", r"line 2, column 'p' holds 'nan'.* "
         r"2 other cells are not a finite number either: line 3 column 'q' \(is empty\), "
         r"line 4 column 'q' \(holds 'x'\)\.$"),
        ("trajectory,t,q\n0.5,0,1\n0.5,1,1\n", r"line 2: trajectory id '0\.5' is not an integer"),
        ("trajectory,t,q\n0,1,1\n0,0,1\n", r"strictly increasing.*sort the rows by trajectory and time"),
        ("trajectory,t,q\n0,0,1\n0,1,1\n1,0,1\n", r"at least two samples.*trajectory 1 has 1"),
        ('trajectory,t,q\n0,0,"1\n', r"not valid CSV \(unexpected end of data\)"),
        # What a new user's own files gave, each with the fix that applies (not "rename").
        ("trajectory;t;q\n0;0;1\n", r"separated by ';': metriplex reads comma-separated"),
        ("trajectory\tt\tq\n0\t0\t1\n", r"separated by a tab"),
        ("trajectory,t,q\n0,0,1,5\n", r"more columns than the header: decimal commas"),
        ("trajectory,t,q\nrun0,0,1\n", r"holds 'run0'.*Trajectory ids are integers"),
        ("trajectory,t,q\n0,2024-01-01T12:00:00,1\n", r"Times are numbers in one unit, not dates"),
        # Python's repr of numbers (new-user check 29: told that times are not dates).
        ("trajectory,t,q\n0,np.float64(0.0),np.float64(1.5)\n",
         r"holds 'np\.float64\(0\.0\)'; .*'np\.float64\(0\.0\)' is how Python prints a number "
         r"object, not the number: write plain numbers"),
        (",trajectory,t,q\n0,0,0,1\n", r"first two columns are '' and 'trajectory'.*index column"),
        # A wide table (a new-user check: told to rename t and q_0 to trajectory and t).
        ("t,q_0,p_0,q_1,p_1\n0,1,0,2,0\n", r"first column is 't' and there is no trajectory "
         r"column: a wide table .* is not read; write the long table, one row per sample"),
    ],
)
def test_csv_malformed(tmp_path, text, match):
    _raises(match, "CSV file", _csv(tmp_path, text))


def test_csv_accepts_bom_spaces_and_blank_lines(tmp_path):
    p = tmp_path / "ok.csv"
    p.write_bytes("\ufefftrajectory, t, q\n\n0, 0.0, 1.5\n0, 1e-1, -2\n".encode())
    data = mx.read(p)
    assert data.names == ("q",) and data.x[:, 0].tolist() == [1.5, -2.0]


def test_csv_slow_path_reads_what_the_fast_path_rejects(tmp_path):
    """Quoted numbers and whitespace-only lines go the line-by-line way; the values agree."""
    clean = tmp_path / "clean.csv"
    clean.write_text("trajectory,t,q,p\n4,0.0,0.1,-2e-300\n4,0.5,1.0,3.0\n")
    odd = tmp_path / "odd.csv"
    odd.write_text('trajectory,t,q,p\n4,"0.0",0.1,-2e-300\n   \n4,0.5,"1.0",3.0\n')
    _same(mx.read(odd), mx.read(clean))


def test_csv_not_text(tmp_path):
    with pytest.raises(MetriplexError, match=r"not UTF-8 text.*Save it as UTF-8 CSV"):
        mx.read(_bytes(tmp_path, "b.csv", b"trajectory,t,q\n\xff\xfe\x00\x01"))


def _h5(tmp_path, build) -> Path:
    p = tmp_path / "bad.h5"
    with h5py.File(p, "w") as f:
        build(f)
    return p


def _traj(f, name, T=3, n=2, **attrs):
    g = f.create_group(name)
    g["t"] = np.arange(float(T))
    g["x"] = np.zeros((T, n))
    g.attrs.update(attrs)
    return g


@pytest.mark.parametrize(
    "build, match",
    [
        (lambda f: f.attrs.update(names=["q"]), r"holds no groups, so no trajectories.*one group per trajectory"),
        (lambda f: (_traj(f, "a"), f.create_dataset("x", data=np.ones(3))), r"holds \['x'\] at its root, which are not trajectory groups"),
        (lambda f: f.create_group("a").create_dataset("t", data=np.arange(3.0)), r"group 'a'.*lacks the dataset\(s\) \['x'\]; it holds \['t'\]"),
        (lambda f: _traj(f, "a").create_dataset("v", data=np.ones(3)), r"group 'a'.*unknown member\(s\) \['v'\]"),
        (lambda f: f.create_group("a").update(t=np.arange(3.0), x=np.ones((2, 4))), r"`x` in group 'a'.*shape \(2, 4\); with 3 times in `t` it must be \(3, n\), one row per time \(or \(n, 3\)\)"),
        (lambda f: (_traj(f, "a"), _traj(f, "b", n=3)), r"same number of state variables.*'a' has 2 and group 'b' has 3"),
        (lambda f: (_traj(f, "a", names=["q", "p"]), _traj(f, "b", names=["q", "v"])), r"names of group 'b'.*\['q', 'v'\].*differ from those of group 'a'"),
        (lambda f: (f.attrs.update(names=["q"]), _traj(f, "a")), r"got 1 variable names for 2 state columns"),
        (lambda f: f.create_group("a").update(t=np.arange(3.0), x=np.array([[0, 1], [np.inf, 0], [0, 0]])), r"NaN or inf at row 1"),
        (lambda f: f.create_group("a").update(t=np.array([0.0, 2, 1]), x=np.zeros((3, 1))), r"strictly increasing.*t\[2\]=.*1\.0.* <= t\[1\]=.*2\.0"),
        (lambda f: _traj(f, "a", T=1), r"at least two samples.*trajectory 0 has 1"),
        (lambda f: f.create_group("a").update(t=np.arange(2.0), x=np.array([b"a", b"b"])), r"dataset `x`.*must hold numbers.*char"),
        (lambda f: f.create_group("a").update(t=np.zeros((2, 2)), x=np.zeros((4, 1))), r"dataset `t`.*must be a vector; it is 2×2"),
        (lambda f: (_traj(f, "a", trajectory=1), _traj(f, "b", trajectory=1)), r"same `trajectory` id attribute \[1\]"),
        (lambda f: (_traj(f, "a", names=[1, 2])), r"attribute `names`.*must hold strings"),
    ],
)
def test_hdf5_malformed(tmp_path, build, match):
    _raises(match, "HDF5 file", _h5(tmp_path, build))


def _mat(tmp_path, variables: dict) -> Path:
    p = tmp_path / "bad.mat"
    scipy.io.savemat(p, variables)
    return p


Z0 = np.arange(24.0).reshape(2, 3, 4)


@pytest.mark.parametrize(
    "variables, match",
    [
        ({"a": np.ones(3), "s": "text"}, r"no state array: .*named one of Z, z, X, x, data, states, yout.*a \(numeric 1×3\); s \(char 1\)\. Rename the variable \(MATLAB: Z = NAME.*in Python, pass read_mat\(path, states='NAME'\)"),
        ({"Z": Z0, "X": Z0, "dt": 1.0}, r"several candidates for the state array: \['Z', 'X'\].*read_mat\(path, states='Z'\)"),
        ({"Z": Z0, "t": np.arange(4.0), "t_vec": np.arange(4.0)}, r"several candidates for the time vector.*time='t_vec'"),
        ({"Z": Z0}, r"gives no times for state array `Z`.*t_vec, tvec, t.*dt, Dt.*read_mat\(path, dt=STEP\)"),
        ({"Z": Z0, "dt": -0.1}, r"time step `dt`.*positive and finite; got \[-0\.1\]"),
        ({"Z": Z0, "dt": [0.1, 0.2, 0.3]}, r"time step `dt`.*3 entries; give one step, or one per trajectory \(2\)"),
        ({"Z": Z0, "t_vec": np.arange(5.0)}, r"time vector `t_vec`.*is 1×5; state array `Z` \(2×3×4\) has 4 snapshots"),
        ({"Z": Z0, "t_vec": np.arange(4.0), "dt": 0.5}, r"time step `dt`=0\.5.*disagrees with time vector `t_vec`, whose step 0.*is 1\.0"),
        ({"Z": np.ones((2, 2, 2, 2)), "dt": 1.0}, r"state array `Z`.*is 2×2×2×2; it must be trajectories × variables × snapshots"),
        ({"Z": Z0 + 1j, "dt": 1.0}, r"state array `Z`.*complex.*Store the real part"),
        ({"Z": np.array([[Z0]], dtype=object), "dt": 1.0}, r"state array `Z`.*must hold numbers; it is cell"),
        ({"Z": np.where(Z0 == 5, np.nan, Z0), "dt": 1.0}, r"x has NaN or inf at row 1 \(trajectory 0, t=1\.0\)"),
        ({"Z": Z0, "t_vec": [[0.0, 1, 1, 2]]}, r"strictly increasing.*t\[2\]=.*1\.0.* <= t\[1\]="),
        ({"Z": Z0[:, :, :1], "dt": 1.0}, r"at least two samples.*trajectory 0 has 1"),
        ({"Z": Z0, "dt": 1.0, "names": np.array(["q", "p"], dtype=object)}, r"`names`.*lists 2 names \['q', 'p'\] but state array `Z` has 3 variables"),
        ({"Z": Z0, "dt": 1.0, "names": np.ones(3)}, r"`names`.*must be strings"),
        ({"Z": Z0, "dt": 1.0, "names": ["a"], "labels": ["b"]}, r"several candidates for the variable names: \['names', 'labels'\]\. Rename or remove all but one"),
        ({"Z": Z0, "dt": 1.0, "trajectory_ids": [0, 1, 2]}, r"`trajectory_ids`.*has 3 entries; 2 are needed"),
        ({"trajectory": [0, 0], "t": [0.0, 1.0]}, r"read as the long table.*`x` is missing"),
        ({"trajectory": [0, 0, 0], "t": [0.0, 1.0, 2.0], "x": np.ones((2, 3))}, r"`x`.*is 2×3; with 3 rows in `trajectory` it must be 3×n.*transposed"),
        ({"a": {"b": 1.0}, "c": {"d": 2.0}}, r"no state array.*a \(struct with fields b\); c \(struct with fields d\)"),
    ],
)
def test_mat_malformed(tmp_path, variables, match):
    _raises(match, "MAT file", _mat(tmp_path, variables))


def test_mat_operators_malformed_and_overrides(tmp_path):
    p = _mat(tmp_path, {"Z": Z0, "dt": 1.0, "L": np.ones((2, 2))})
    with pytest.raises(MetriplexError, match=r"operator `L`.*is 2×2; with 3 state variables it must be 3×3"):
        read_mat_operators(p)
    p = _mat(tmp_path, {"Z": Z0, "dt": 1.0, "M": np.full((3, 3), np.nan)})
    with pytest.raises(MetriplexError, match=r"operator `M`.*NaN or inf"):
        read_mat_operators(p)
    with pytest.raises(MetriplexError, match=r"no variable 'Y' \(asked for as the state array\); it holds Z"):
        read_mat(p, states="Y")
    with pytest.raises(MetriplexError, match=r"dt must be positive and finite; got 0"):
        read_mat(_mat(tmp_path, {"Z": Z0}), dt=0)


def test_mat_sparse_operators(tmp_path):
    """MATLAB often stores L and M sparse; both v5 and v7.3 sparse matrices are read dense."""
    L = np.zeros((3, 3))
    L[0, 2], L[2, 0] = 2.0, -2.0
    scipy.io.savemat(tmp_path / "v5.mat", {"Z": Z0, "dt": 1.0, "L": scipy.sparse.csc_matrix(L)})
    assert np.array_equal(read_mat_operators(tmp_path / "v5.mat")["L"], L)
    _write_mat73(tmp_path / "v73.mat", {"Z": Z0, "dt": [[1.0]], "M": scipy.sparse.csc_matrix(L)})
    assert np.array_equal(read_mat_operators(tmp_path / "v73.mat")["M"], L)


def test_mat_that_is_plain_hdf5_or_matlab_object(tmp_path):
    mx.write(tmp_path / "d.h5", _square())
    (tmp_path / "d.h5").rename(tmp_path / "d.mat")
    with pytest.raises(MetriplexError, match=r"HDF5 file without MATLAB's v7.3 header.*suffix \.h5"):
        mx.read(tmp_path / "d.mat")
    _write_mat73(tmp_path / "o.mat", {"dt": [[1.0]]})
    with h5py.File(tmp_path / "o.mat", "a") as f:
        f.create_group("Z").attrs["MATLAB_class"] = np.bytes_("containers.Map")
    with pytest.raises(MetriplexError, match=r"`Z`.*is a MATLAB containers.Map object, which metriplex does not read"):
        mx.read(tmp_path / "o.mat")


def test_mat_v73_truncated(tmp_path):
    _write_mat73(tmp_path / "v.mat", {"Z": Z0, "dt": [[1.0]]})
    whole = (tmp_path / "v.mat").read_bytes()
    with pytest.raises(MetriplexError, match=r"truncated"):
        mx.read(_bytes(tmp_path, "t.mat", whole[: len(whole) // 2]))


def test_read_names_the_file_and_refuses_unknown_suffix(tmp_path):
    with pytest.raises(MetriplexError, match=r"unknown extension '\.xlsx'. Supported: \.csv, \.h5, \.hdf5, \.mat, \.npy, \.npz"):
        mx.read(_bytes(tmp_path, "d.xlsx", b"x"))
    with pytest.raises(MetriplexError, match=r"does not exist"):
        mx.read(tmp_path / "missing.h5")


# -- property-based ---------------------------------------------------------------------------

NAME = st.text(
    alphabet=st.sampled_from("abcxyzQP_019 .,;:'\"-+é/"), min_size=1, max_size=6
).filter(lambda s: s == s.strip())
FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def trajectories(draw) -> Trajectories:
    n = draw(st.integers(1, 3))
    names = draw(st.lists(NAME, min_size=n, max_size=n, unique=True))
    K = draw(st.integers(1, 4))
    ids = draw(st.lists(st.integers(-50, 10**6), min_size=K, max_size=K, unique=True))
    equal = draw(st.booleans())
    T0 = draw(st.integers(2, 6))
    parts = []
    for _ in range(K):
        T = T0 if equal else draw(st.integers(2, 6))
        t0 = draw(st.floats(-1e3, 1e3))
        steps = draw(st.lists(st.floats(1e-3, 1e3), min_size=T - 1, max_size=T - 1))
        t = np.cumsum([t0, *steps])
        x = np.array(draw(st.lists(FINITE, min_size=T * n, max_size=T * n))).reshape(T, n)
        parts.append((t, x))
    data = Trajectories.from_list(parts, names=names)
    return Trajectories(np.array(ids)[data.trajectory], data.t, data.x, data.names)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=trajectories(), ext=st.sampled_from(EXTS))
def test_property_round_trip(data, ext):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / f"data.{ext}"
        mx.write(p, data)
        back = mx.read(p)
    _same(back, data)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ext=st.sampled_from(EXTS),
    cut=st.floats(0.0, 1.0),
    flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)), max_size=3),
)
def test_property_damaged_files_raise_only_metriplex_errors(ext, cut, flips):
    """A truncated or bit-flipped file reads correctly or raises MetriplexError, nothing else."""
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / f"data.{ext}"
        mx.write(p, _ragged())
        raw = bytearray(p.read_bytes())
        for where, byte in flips:
            raw[int(where * (len(raw) - 1))] = byte
        p.write_bytes(bytes(raw[: max(1, int(cut * len(raw)))]) if cut < 1.0 else bytes(raw))
        try:
            mx.read(p)
        except MetriplexError as e:
            assert str(p) in str(e)


def test_mat_simulink_outputs_and_ragged_cells(tmp_path):
    # Simulink's workspace output (tout, yout: samples x outputs) had no way in from the
    # command line; a cell array of ragged runs was told to become a numeric array.
    t = 0.1 * np.arange(50)
    y = np.c_[np.cos(t), np.sin(t)]
    scipy.io.savemat(tmp_path / "sim.mat", {"tout": t[:, None], "yout": y})
    data = mx.read(tmp_path / "sim.mat")
    assert data.n == 2 and np.array_equal(data.t, t) and np.array_equal(data.x, y)
    cells = np.empty((1, 2), dtype=object)
    cells[0, 0], cells[0, 1] = np.zeros((5, 2)), np.zeros((7, 2))
    scipy.io.savemat(tmp_path / "cells.mat", {"data": cells, "dt": 0.1})
    with pytest.raises(mx.MetriplexError, match="different lengths cannot be one array: store "
                                                "the long table"):
        mx.read(tmp_path / "cells.mat")


def test_npy_states_alone_with_a_step(tmp_path):
    # A bare (K, T, n) array is how many datasets come; it was refused as an unknown format.
    rng = np.random.default_rng(0)
    states = rng.normal(size=(3, 7, 2))
    np.save(tmp_path / "x.npy", states)
    np.save(tmp_path / "one.npy", states[1])
    with pytest.raises(MetriplexError, match=r"holds states only \(3x7x2\), no times: pass --dt"):
        mx.read(tmp_path / "x.npy")
    data = mx.read(tmp_path / "x.npy", dt=0.25)
    assert len(data) == 3 and data.n == 2
    for k, (t, x) in enumerate(data):
        assert np.array_equal(t, 0.25 * np.arange(7)) and np.array_equal(x, states[k])
    one = mx.read(tmp_path / "one.npy", dt=0.25)
    assert len(one) == 1 and np.array_equal(one.x, states[1])
    np.save(tmp_path / "bad.npy", np.zeros(4))
    with pytest.raises(MetriplexError, match=r"1-D array .* \(K, T, n\) or snapshots x "
                                             r"variables \(T, n\)"):
        mx.read(tmp_path / "bad.npy", dt=0.1)
    with pytest.raises(MetriplexError, match=r"unknown extension '\.npy'\. Trajectories are "
                                             r"written as"):
        mx.write(tmp_path / "out.npy", data)


def test_npz_stacked_states_without_trajectory_ids(tmp_path):
    # np.savez(f, x=(K, T, n), t=(T,)) was refused for lacking `trajectory`.
    rng = np.random.default_rng(1)
    x, t = rng.normal(size=(3, 6, 2)), 0.5 * np.arange(6)
    np.savez(tmp_path / "k.npz", x=x, t=t)
    np.savez(tmp_path / "one.npz", x=x[2], t=t)
    np.savez(tmp_path / "bare.npz", x=x)
    data = mx.read(tmp_path / "k.npz")
    assert len(data) == 3 and all(np.array_equal(tk, t) and np.array_equal(xk, x[k])
                                  for k, (tk, xk) in enumerate(data))
    assert len(mx.read(tmp_path / "one.npz")) == 1
    with pytest.raises(MetriplexError, match=r"lacks the array\(s\) \['t'\].*pass --dt STEP"):
        mx.read(tmp_path / "bare.npz")
    assert np.array_equal(next(iter(mx.read(tmp_path / "bare.npz", dt=0.1)))[0],
                          0.1 * np.arange(6))
    np.savez(tmp_path / "short.npz", x=x, t=t[:4])
    with pytest.raises(MetriplexError, match=r"`t` .* is \(4,\), but `x` \(3, 6, 2\) has 6 "
                                             r"snapshots"):
        mx.read(tmp_path / "short.npz")


def test_npz_with_its_own_time_step_and_states_under_another_name(tmp_path):
    # np.savez(f, X=(K, T, n), dt=0.1), as published data are saved: the step was refused as an
    # unknown array, and the missing `x` was explained by the long table alone.
    rng = np.random.default_rng(3)
    x = rng.normal(size=(3, 6, 2))
    np.savez(tmp_path / "step.npz", x=x, dt=0.25)
    data = mx.read(tmp_path / "step.npz")
    assert len(data) == 3 and np.array_equal(next(iter(data))[0], 0.25 * np.arange(6))
    with pytest.raises(MetriplexError, match=r"--dt 0.5 would replace the file's own times"):
        mx.read(tmp_path / "step.npz", dt=0.5)  # the file's step is its times
    np.savez(tmp_path / "both.npz", x=x, t=0.25 * np.arange(6), dt=0.25)
    assert np.array_equal(mx.read(tmp_path / "both.npz").x, mx.read(tmp_path / "step.npz").x)
    np.savez(tmp_path / "clash.npz", x=x, t=0.25 * np.arange(6), dt=0.5)
    with pytest.raises(MetriplexError, match=r"time step `dt`=0.5 .* disagrees with its times "
                                             r"`t`, which step by 0.25 at row 1"):
        mx.read(tmp_path / "clash.npz")
    np.savez(tmp_path / "steps.npz", x=x, dt=[0.1, 0.2])
    with pytest.raises(MetriplexError, match=r"`dt` .* must be one positive finite number; "
                                             r"got .*\[0.1, 0.2\]"):
        mx.read(tmp_path / "steps.npz")
    np.savez(tmp_path / "X.npz", X=x, dt=0.25)
    with pytest.raises(MetriplexError, match=r"lacks the array\(s\) \['trajectory', 'x'\].*"
                                             r"\(K, T, n\).*`X` 3×6×2 may hold the states: save "
                                             r"it as `x`"):
        mx.read(tmp_path / "X.npz")


def test_hdf5_states_stored_variables_by_times_are_read_by_the_times(tmp_path):
    import h5py

    rng = np.random.default_rng(2)
    x = rng.normal(size=(6, 2))
    with h5py.File(tmp_path / "nT.h5", "w") as f:
        f.create_group("a").update(t=0.1 * np.arange(6), x=x.T)
    assert np.array_equal(mx.read(tmp_path / "nT.h5").x, x)


def test_hdf5_stacked_states_at_the_root(tmp_path):
    import h5py

    rng = np.random.default_rng(3)
    x, t = rng.normal(size=(2, 5, 3)), 0.2 * np.arange(5)
    with h5py.File(tmp_path / "root.h5", "w") as f:
        f.update(x=x, t=t)
    data = mx.read(tmp_path / "root.h5")
    assert len(data) == 2 and all(np.array_equal(tk, t) and np.array_equal(xk, x[k])
                                  for k, (tk, xk) in enumerate(data))
    with h5py.File(tmp_path / "bare.h5", "w") as f:
        f.update(x=x)
    assert len(mx.read(tmp_path / "bare.h5", dt=0.5)) == 2
    with pytest.raises(MetriplexError, match=r"holds `x` at its root and no times `t`: .*--dt"):
        mx.read(tmp_path / "bare.h5")


def test_mat_layouts_a_matlab_user_writes_are_refused_with_the_permutation(tmp_path):
    # A new-user check's natural files: K×T×n with a scalar dt was read as 201 variables of 3
    # samples (train then asked for 6 GB); T×n×K with its time vector was told to pass --dt,
    # which read it as 201 trajectories of the 8 states at one time; a cell array was told
    # to rename it, which only moved the refusal.
    rng = np.random.default_rng(0)
    X = rng.normal(size=(8, 201, 3))
    scipy.io.savemat(tmp_path / "ktn.mat", {"X": X, "dt": 0.05})
    _raises(r"8×201×3 with times from a step alone.*201 variables and only 3 snapshots.*"
            r"permute\(X, \[1 3 2\]\)", "MAT file", tmp_path / "ktn.mat")
    scipy.io.savemat(tmp_path / "tn.mat", {"X": X[0], "dt": 0.05})
    _raises(r"201×3 with times from a step alone.*Z = X\.'", "MAT file", tmp_path / "tn.mat")
    scipy.io.savemat(tmp_path / "tnk.mat", {"X": X.transpose(1, 2, 0), "t": np.arange(201.0)})
    _raises(r"has 201 entries, the first dimension .*snapshots × variables × trajectories.*"
            r"permute\(X, \[3 2 1\]\)", "MAT file", tmp_path / "tnk.mat")
    cell = np.empty((1, 8), dtype=object)
    for k in range(8):
        cell[0, k] = X[k]
    scipy.io.savemat(tmp_path / "cell.mat", {"trajs": cell, "t": np.arange(201.0)})
    _raises(r"`trajs` is a cell array, which is not read.*cat\(3, trajs\{:\}\)", "MAT file",
            tmp_path / "cell.mat")
    # The documented layout with a step, and K×T×n with its time vector, still read.
    scipy.io.savemat(tmp_path / "knt.mat", {"Z": X.transpose(0, 2, 1), "dt": 0.05})
    assert mx.read(tmp_path / "knt.mat").n == 3
    scipy.io.savemat(tmp_path / "ktn_t.mat", {"X": X, "t": np.arange(201.0)})
    assert mx.read(tmp_path / "ktn_t.mat").n == 3
