"""What a run writes and reads: run folders, snapshots, tables, ParaView files, pictures and
CellModeller's states.

- :mod:`.snapshots`: colony snapshots as NPZ (:func:`save_colony`, :func:`load_colony`,
  :func:`load_snapshot`; format version 3 with the run's settings, step, random state, cell
  types and a model's per-cell arrays), the one reader and writer of cells in NPZ files;
- :mod:`.runs`: what keeps a run from losing anything: the output folder
  (:class:`RunFolder`), history appends, atomic snapshots, Ctrl-C, resuming, ``config.toml``;
- :mod:`.tables`: one row per cell of a snapshot, one row per step of a run
  (:func:`colony_frame`, :func:`run_frame`: pandas DataFrames, the extra ``qpcontact[table]``;
  ``qpcontact table``: CSV or Parquet);
- :mod:`.paraview`: ParaView files (``.vtu`` per snapshot, ``.pvd`` series; needs meshio);
- :mod:`.plots`: pictures of a run (matplotlib; imported only when drawing:
  ``from qpcontact.io import plots``);
- :mod:`.cellmodeller`: CellModeller's saved states (its pickles, read by an unpickler that
  builds nothing else) as snapshots: :func:`read_cellmodeller`, ``qpcontact import-cellmodeller``.

Imports the colony model and the per-timestep calls below it, never the run loop or ensembles
above it (docs/architecture.md).
"""

from .cellmodeller import CellModellerState, read_cellmodeller
from .runs import RunFolder
from .snapshots import Snapshot, load_colony, load_snapshot, save_colony
from .tables import colony_columns, colony_frame, run_frame

__all__ = [
    "CellModellerState", "RunFolder", "Snapshot", "colony_columns", "colony_frame", "load_colony", "load_snapshot",
    "read_cellmodeller", "run_frame", "save_colony",
]
