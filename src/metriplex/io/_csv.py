"""The long table as CSV: header ``trajectory,t,<name_1>,...``, one row per state
(docs/design.md, 'Trajectory data')."""

from __future__ import annotations

import contextlib
import csv
import os
from pathlib import Path

import numpy as np

from .._errors import MetriplexError
from ..data import Trajectories, uniform_times
from ._files import atomic_write


def read_csv(path: Path, *, dt: float | None = None) -> Trajectories:
    """The long table from CSV: header ``trajectory,t,<name_1>,...``, one row per state; with
    ``dt``, the ``t`` column is replaced by ``k * dt`` (see
    :func:`metriplex.io.read`)."""
    import warnings

    path = Path(path)
    where = f"CSV file {str(path)!r}"

    def check_header(row: list[str]) -> list[str]:
        header = [c.strip() for c in row]
        if len(header) < 3 or header[0] != "trajectory" or header[1] != "t":
            hint = ""
            with contextlib.suppress(ValueError):
                [float(c) for c in header]
                hint = " The first line holds numbers: the header line is missing."
            sep = next((c for c in ";\t|" if len(header) == 1 and c in header[0]), None)
            if sep is not None:
                hint = (f" Its columns are separated by {'a tab' if sep == chr(9) else repr(sep)}"
                        ": metriplex reads comma-separated files with decimal points (pandas: "
                        "df.to_csv(path, index=False)).")
            elif len(header) >= 3 and not hint and header[0].split(" ")[0] in ("t", "time"):
                hint = (f" Its first column is {header[0]!r} and there is no trajectory column: "
                        "a wide table (one time column, each trajectory's variables beside it) "
                        "is not read; write the long table, one row per sample: its trajectory "
                        "id, its time, its state (pandas: melt or stack the trajectories into "
                        "rows; or save a .npz with x of shape (K, T, n) and t).")
            elif len(header) >= 3 and not hint:
                hint = (f" The first two columns are {header[0]!r} and {header[1]!r}: name them "
                        "`trajectory` (integer ids) and `t` (numbers), and leave out an index "
                        "column (pandas: to_csv(index=False)).")
            raise MetriplexError(
                f"{where} must start with the header `trajectory,t,<name_1>,...` (at least one "
                f"state column); got {','.join(header)!r}.{hint}"
                + (" Add, rename or reorder the columns." if sep is None else "")
            )
        names = header[2:]
        for k, name in enumerate(names):
            if not name:
                raise MetriplexError(
                    f"{where}: header column {k + 3} has no name; every state column needs one."
                )
            if name in names[:k]:
                raise MetriplexError(
                    f"{where}: header column {k + 3} repeats the variable name {name!r}; names "
                    "must be unique."
                )
        return header

    def build(arr: np.ndarray, header: list[str]) -> Trajectories:
        t = arr[:, 1] if dt is None else uniform_times(arr[:, 0], dt)
        try:
            return Trajectories(arr[:, 0], t, arr[:, 2:], tuple(header[2:]))
        except MetriplexError as e:
            raise MetriplexError(f"{where}: {e}") from None

    # Fast path: NumPy's C parser (correctly rounded, as float() is) reads a clean body at once.
    # Whatever it rejects (quoted cells included: they may hide a truncated quote) is read again
    # line by line below, to say exactly what and where.
    first = arr = None
    with contextlib.suppress(Exception):
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f, strict=True)
            first = next((r for r in reader if r and any(c.strip() for c in r)), None)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "input contained no data"
                arr = np.loadtxt(
                    f, delimiter=",", comments=None, dtype=np.float64, ndmin=2
                )
    if (
        first is not None
        and arr is not None
        and arr.shape[0] > 0
        and arr.shape[1] == len(first)
        and np.all(np.isfinite(arr))
        and np.all(arr[:, 0] == np.round(arr[:, 0]))
    ):
        return build(arr, check_header(first))

    rows, lines = [], []
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f, strict=True)
            for r in reader:
                if r and any(c.strip() for c in r):
                    rows.append(r)
                    lines.append(reader.line_num)
    except UnicodeDecodeError as e:
        raise MetriplexError(
            f"{where} is not UTF-8 text (byte {e.start} cannot be decoded); it may be binary or "
            "another format. Save it as UTF-8 CSV."
        ) from None
    except csv.Error as e:
        raise MetriplexError(
            f"{where} is not valid CSV ({e}); it may be truncated. Save it again as plain CSV."
        ) from None
    if not rows:
        raise MetriplexError(f"{where} is empty; it holds no header and no rows.")
    header = check_header(rows[0])
    body, body_lines = rows[1:], lines[1:]
    if not body:
        raise MetriplexError(f"{where} has a header but no data rows.")
    width = len(header)
    for r, line in zip(body, body_lines):
        if len(r) != width:
            raise MetriplexError(
                f"{where}, line {line}, has {len(r)} columns; the header has {width}. Every row "
                "needs `trajectory`, `t` and one value per state variable (a short last line "
                "means a truncated file" + ("; more columns than the header: decimal commas "
                "such as 1,5 split cells, write decimal points" if len(r) > width else "") + ")."
            )
    arr = np.empty((len(body), width))
    problems = []  # (line, column, what, fix) of every cell that is not a finite number
    for k, (r, line) in enumerate(zip(body, body_lines)):
        for j, (name, c) in enumerate(zip(header, r)):
            try:
                arr[k, j] = v = float(c)
            except ValueError:
                v = None
            if j == 1 and dt is not None:  # the file's times are not used
                arr[k, j] = 0.0
                continue
            if v is None or v != v or v in (float("inf"), float("-inf")):
                what = "is empty" if not c.strip() else f"holds {c.strip()!r}"
                fix = "Fix or remove that row (interpolate missing samples)."
                if v is None and _repr_of_number(c):
                    fix = (f"{c.strip()!r} is how Python prints a number object, not the "
                           "number: write plain numbers (float(v), numpy.savetxt or pandas' "
                           "to_csv of a numeric table).")
                elif v is None and c.strip() and j == 0:
                    fix = "Trajectory ids are integers (0, 1, 2, ...): number the trajectories."
                elif v is None and c.strip() and j == 1:
                    fix = ("Times are numbers in one unit, not dates or clock times: convert "
                           "the column (pandas: (t - t.iloc[0]).dt.total_seconds()).")
                problems.append((line, name, what, fix))
    if problems:
        line, name, what, fix = problems[0]
        raise MetriplexError(
            f"{where}, line {line}, column {name!r} {what}; every cell must be a finite "
            f"number. {fix}" + _others(problems[1:])
        )
    bad = np.flatnonzero(arr[:, 0] != np.round(arr[:, 0]))
    if len(bad):
        raise MetriplexError(
            f"{where}, line {body_lines[bad[0]]}: trajectory id {body[bad[0]][0].strip()!r} is "
            "not an integer; ids label trajectories 0, 1, 2, ..."
        )
    return build(arr, header)


def _repr_of_number(cell: str) -> bool:
    """Whether ``cell`` is a Python repr of a number, ``np.float64(0.5)`` or
    ``tensor(1.)`` (a new-user check wrote a CSV of such cells and was told that times are not
    dates)."""
    head, _, rest = cell.strip().partition("(")
    if not head or not rest.endswith(")") or not head.replace(".", "").replace("_", "").isalnum():
        return False
    try:
        float(rest[:-1].split(",")[0])
    except ValueError:
        return False
    return True


def _others(problems: list[tuple[int, str, str, str]]) -> str:
    """The rest of a file's bad cells, so that one run names them all: their count and
    where the first few are (file lines, the header being line 1)."""
    if not problems:
        return ""
    shown = ", ".join(f"line {line} column {name!r} ({what})"
                      for line, name, what, _ in problems[:5])
    more = f", and {len(problems) - 5} more" if len(problems) > 5 else ""
    other = "1 other cell is" if len(problems) == 1 else f"{len(problems)} other cells are"
    return f" {other} not a finite number either: {shown}{more}."


def write_csv(path: str | os.PathLike, data: Trajectories) -> None:
    """Write ``data`` as the long table in CSV (atomically); each number as the shortest
    decimal that reads back to the same float64."""
    path = Path(path)
    for name in data.names:
        if name != name.strip() or not name:
            raise MetriplexError(
                f"cannot write {str(path)!r}: variable name {name!r} has surrounding "
                "whitespace, which CSV readers strip, so it would not read back. Rename it "
                "(data.with_names([...])) or write .npz."
            )
    with atomic_write(path, "w") as f:
        csv.writer(f, lineterminator="\n").writerow(["trajectory", "t", *data.names])
        # repr gives the shortest decimal that parses back to the same float64; numbers
        # never need CSV quoting, so rows are joined directly (10x faster than csv.writer).
        f.writelines(
            f"{i},{t!r},{','.join(map(repr, x))}\n"
            for i, t, x in zip(data.trajectory.tolist(), data.t.tolist(), data.x.tolist())
        )
