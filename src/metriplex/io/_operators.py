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
            import scipy.io

            scope = scipy.io.loadmat(p)
            if key not in scope:
                found = sorted(k for k in scope if not k.startswith("__"))
                raise MetriplexError(
                    f"{str(p)!r} has no variable {key!r} (found {found}); store the matrix as "
                    f"{key}."
                )
            a = scope[key]
        else:
            raise MetriplexError(
                f"{option} file:PATH reads .npy, .npz or .mat files; got {p.suffix or 'no'} "
                "suffix. Save the matrix with numpy.save."
            )
    except (OSError, ValueError, NotImplementedError) as err:
        raise MetriplexError(f"cannot read the matrix {key} from {str(p)!r}: {err}.") from None
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (n, n):
        raise MetriplexError(
            f"the matrix {key} in {str(p)!r} has shape {a.shape}; the data have {n} variables, "
            f"so it must be {n}x{n}."
        )
    return a
