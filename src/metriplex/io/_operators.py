"""Constant operators the user knows, read from a file: ``--poisson file:PATH`` and
``--friction file:PATH`` (a ``.npy`` array, or the variable ``L`` / ``M`` of a ``.npz`` or
``.mat`` file, as published GENERIC datasets store them)."""

from __future__ import annotations

import numpy as np

from .._errors import MetriplexError


def read_matrix(path: str, key: str, n: int) -> np.ndarray:
    """A constant ``n x n`` operator from ``.npy`` (the array), ``.npz`` or ``.mat`` (the
    variable ``key``, i.e. ``L`` or ``M``, as published GENERIC datasets store them)."""
    from pathlib import Path

    p = Path(path)
    option = "--poisson" if key == "L" else "--friction"
    if not p.is_file():
        raise MetriplexError(
            f"{option} file:PATH needs an existing file; {str(p)!r} does not exist. Give the "
            f"path of a .npy, .npz or .mat file holding the {n}x{n} matrix {key}."
        )
    try:
        if p.suffix == ".npy":
            a = np.load(p, allow_pickle=False)
        elif p.suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                names = list(z.files)
                if key not in names and len(names) != 1:
                    raise MetriplexError(
                        f"{str(p)!r} holds the arrays {names}; name the matrix {key!r} or store "
                        "it alone."
                    )
                a = z[key] if key in names else z[names[0]]
        elif p.suffix == ".mat":
            a = _mat_operator(p, key)
        else:
            raise MetriplexError(
                f"{option} file:PATH reads .npy, .npz or .mat files; got {p.suffix or 'no'} "
                "suffix. Save the matrix with numpy.save."
            )
    except MetriplexError:
        raise
    except (OSError, ValueError, NotImplementedError) as err:
        raise MetriplexError(f"cannot read the matrix {key} from {str(p)!r}: {err}.") from None
    if np.iscomplexobj(a):
        raise MetriplexError(
            f"the matrix {key} in {str(p)!r} holds complex numbers; {option} needs a real "
            f"{n}x{n} matrix. Store its real part."
        )
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (n, n):
        raise MetriplexError(
            f"the matrix {key} in {str(p)!r} has shape {a.shape}; the data have {n} variables, "
            f"so it must be {n}x{n}."
        )
    return a


def _mat_operator(path, key: str) -> np.ndarray:
    """The variable ``key`` of a MAT file, read as the data reader reads one (v4 to v7.3,
    sparse matrices dense, the fields of the file's only struct where the top level lacks it),
    as a real float64 array."""
    from ._checks import _real
    from ._mat import _mat_scope
    from ._mat_load import _load_mat

    scope, where = _mat_scope(_load_mat(path), path, key)
    if key not in scope:
        found = sorted(scope)
        raise MetriplexError(
            f"{where} has no variable {key!r} (found {found}); store the matrix as {key}."
        )
    a = scope[key]
    if np.iscomplexobj(a):
        return a  # read_matrix refuses it, naming the option
    return _real(a, f"the matrix {key}", where)
