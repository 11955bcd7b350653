"""Colony: the timestep loop around :func:`qpcontact.resolve`, growth, division, snapshots.

- :mod:`.step`: :func:`step` (momenta before contact, contacts with cells and planes, resolve,
  move) and its helpers;
- :mod:`.position`: :func:`position_step`, the step with non-penetration at the end of the
  step (sequential linearization; the default of ``qpcontact simulate``);
- :mod:`.mechanics`: contact forces as mechanics: :func:`cell_forces`, :func:`cell_stress`,
  :func:`cell_pressure` (virial stress and pressure of each cell), :class:`CellMechanics`,
  :func:`radial_profile`, :func:`fit_parabola`, growth slowed by pressure
  (:func:`pressure_growth_rate`, :class:`PressureGrowth`);
- :mod:`.growth`: :class:`Colony` (cells with lineage), :func:`grow` (velocity-level step) and
  :func:`grow_position` (position-level step), :func:`divide`, the time-step rules
  :func:`growth_time_step` and :func:`expansion_time_step`;
- :mod:`.snapshots`: colony snapshots as NPZ (:func:`save_colony`, :func:`load_colony`,
  :func:`load_snapshot`; format version 3 with the run's settings, step, random state, cell
  types and a model's per-cell arrays), the
  one reader and writer of cells in NPZ files;
- :mod:`.settings`: the settings of a run, one table per concern (:class:`Settings`:
  :class:`ModelSettings`, :class:`RunSettings`, :class:`OutputSettings`, :class:`PositionSettings`,
  :class:`VelocitySettings`), each described once; the one merge of their sources;
- :mod:`.simulate`: ``qpcontact simulate`` (:func:`run_colony` with :class:`Settings`);
- :mod:`.sweep`: ``qpcontact sweep``, replicates and parameter sweeps of runs on Dask (imported
  by the command only);
- :mod:`.runs`: what keeps a run from losing anything: the output folder
  (:class:`RunFolder`), history appends, atomic snapshots, Ctrl-C, resuming, ``config.toml``;
- :mod:`.hooks`: model hooks, the user's per-step function (:class:`StepControl`);
- :mod:`.paraview`: ParaView files (``.vtu`` per snapshot, ``.pvd`` series; needs meshio);
- :mod:`.cellmodeller`: CellModeller's saved states (its pickles, read by an unpickler that
  builds nothing else) as snapshots: :func:`read_cellmodeller`, ``qpcontact import-cellmodeller``;
- :mod:`.plots`: pictures of a run (matplotlib; imported only when drawing:
  ``from qpcontact.colony import plots``); :mod:`.picture`: ``qpcontact plot``, a snapshot
  drawn again;
- :mod:`.tables`: one row per cell of a snapshot, one row per step of a run
  (:func:`colony_frame`, :func:`run_frame`: pandas DataFrames, the extra ``qpcontact[table]``;
  ``qpcontact table``: CSV or Parquet).

Imports the geometry, assembly, solvers and resolve wings only.
"""

from ..geometry.motion import rotate
from .cellmodeller import CellModellerState, read_cellmodeller
from .growth import (
    Colony,
    daughters_share,
    divide,
    expansion_time_step,
    grow,
    grow_position,
    growth_drive,
    growth_step,
    growth_time_step,
    volumes,
)
from .hooks import StepControl, push
from .mechanics import (
    CellMechanics,
    PressureGrowth,
    cell_forces,
    cell_pressure,
    cell_stress,
    fit_parabola,
    pressure_growth_rate,
    radial_profile,
)
from .position import CellMotion, ContactImpulses, PositionSettings, PositionStepResult, move, position_step
from .runs import RunFolder
from .settings import ModelSettings, OutputSettings, RunSettings, Settings, VelocitySettings
from .simulate import Run, StepOutcome, run_colony
from .snapshots import Snapshot, load_colony, load_snapshot, save_colony
from .step import StepResult, advance, largest_overlap, overlap_fractions, step
from .tables import colony_columns, colony_frame, run_frame

__all__ = [
    "CellMechanics", "CellModellerState", "CellMotion", "Colony", "ContactImpulses", "ModelSettings", "OutputSettings", "PositionSettings",
    "PositionStepResult", "PressureGrowth", "Run", "RunFolder", "RunSettings", "Settings", "Snapshot", "VelocitySettings",
    "cell_forces", "cell_pressure", "cell_stress", "fit_parabola", "pressure_growth_rate", "radial_profile",
    "read_cellmodeller", "StepControl", "StepOutcome", "StepResult", "advance", "colony_columns", "colony_frame", "daughters_share", "divide",
    "expansion_time_step", "grow",
    "grow_position",
    "growth_drive", "growth_step", "growth_time_step", "largest_overlap", "load_colony", "load_snapshot", "move",
    "overlap_fractions", "position_step", "push", "rotate", "run_colony", "run_frame", "save_colony", "step", "volumes",
]
