"""Reading and writing trajectories and model files: the public names, and where each lives.

Trajectories: the long table (docs/design.md, 'Trajectory data') in NPZ or CSV; also read from
and written to HDF5 (one group per trajectory) and MATLAB ``.mat``. Model files are a JSON
header followed by ``equinox.tree_serialise_leaves`` bytes: loading reads numbers only and
never executes code (no pickle). Every file is written atomically: to a temporary file in the
same folder, then renamed, so an interrupted write never leaves a half-written file behind.
Every reader checks its file and raises :class:`MetriplexError` naming the rule, the value
found and the fix; no h5py, SciPy or NumPy traceback reaches the user.

Where each thing lives; a module imports only from the groups above its own:

1. ``_files``: :func:`atomic_write`, :func:`write_json` (strict JSON: a NaN or infinite number
   is written as ``null``), :func:`check_output_file`, :func:`check_output_folder`.
   ``_checks``: the value checks several readers share (``_real``, ``_vector``, ``_strings``,
   ``_build``, ...).
2. One module per format, its reader and its writer: ``_npz`` (:func:`read_npz`), ``_csv``
   (:func:`read_csv`), ``_hdf5`` (:func:`read_hdf5`, :func:`write_hdf5`, :func:`natural_key`;
   the HDF5 layout in its docstring), ``_mat`` (:func:`read_mat`, :func:`read_mat_operators`,
   :func:`write_mat`; the MATLAB layouts in its docstring), which loads files through
   ``_mat_load`` (v4 to v7.3 into plain values). h5py and SciPy are imported by the functions
   that need them.
3. ``_registry``: ``FORMATS``, the one table of suffix -> reader and writer, and what goes
   through it: :func:`read`, :func:`write`, :func:`trajectory_suffixes`. A new format is one
   module and one line in ``FORMATS``.

``_model_file`` (:func:`save`, :func:`load`, :func:`read_header`) imports only ``_files``;
``_operators`` (:func:`read_matrix`: a constant L or M for ``--poisson/--friction file:PATH``)
imports nothing from io.
"""

from ._csv import read_csv
from ._files import (
    atomic_write,
    check_output_file,
    check_output_folder,
    write_json,
)
from ._hdf5 import natural_key, read_hdf5, write_hdf5
from ._mat import read_mat, read_mat_operators, write_mat
from ._model_file import FORMAT_VERSION, MAGIC, MODEL_DTYPES, load, read_header, save
from ._npz import read_npz
from ._operators import read_matrix
from ._registry import read, trajectory_suffixes, write

__all__ = ["FORMAT_VERSION", "MAGIC", "MODEL_DTYPES", "atomic_write", "check_output_file",
           "check_output_folder", "load", "natural_key", "read", "read_csv", "read_hdf5",
           "read_header", "read_mat", "read_mat_operators", "read_matrix", "read_npz", "save",
           "trajectory_suffixes", "write", "write_hdf5", "write_json", "write_mat"]
