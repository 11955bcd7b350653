"""Colony: the timestep loop around :func:`qpcontact.resolve`, growth, division, snapshots.

- :mod:`.step`: :func:`step` (momenta before contact, contacts with cells and planes, resolve,
  move) and its helpers;
- :mod:`.position`: :func:`position_step`, the step with non-penetration at the end of the
  step (sequential linearization; the default of ``qpcontact simulate``);
- :mod:`.growth`: :class:`Colony` (cells with lineage), :func:`grow` (velocity-level step) and
  :func:`grow_position` (position-level step), :func:`divide`, the time-step rules
  :func:`growth_time_step` and :func:`expansion_time_step`;
- :mod:`.snapshots`: colony snapshots as NPZ (:func:`save_colony`, :func:`load_colony`,
  :func:`load_snapshot`; format version 2 with the run's settings, step and random state), the
  one reader and writer of cells in NPZ files;
- :mod:`.simulate`: ``qpcontact simulate`` (:func:`run_colony` with :class:`Settings`);
- :mod:`.runs`: what keeps a run from losing anything: the output folder
  (:class:`RunFolder`), history appends, atomic snapshots, Ctrl-C, resuming, ``config.toml``;
- :mod:`.hooks`: model hooks, the user's per-step function (:class:`StepControl`);
- :mod:`.paraview`: ParaView files (``.vtu`` per snapshot, ``.pvd`` series; needs meshio);
- :mod:`.plots`: pictures of a run (matplotlib; imported only when drawing:
  ``from qpcontact.colony import plots``).

Imports the geometry, assembly, solvers and resolve wings only.
"""

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
from .position import ContactImpulses, PositionSettings, PositionStepResult, move, position_step
from .runs import RunFolder
from .simulate import Run, Settings, StepOutcome, run_colony
from .snapshots import Snapshot, load_colony, load_snapshot, save_colony
from .step import StepResult, advance, largest_overlap, overlap_fractions, rotate, step

__all__ = [
    "Colony", "ContactImpulses", "PositionSettings", "PositionStepResult", "Run", "RunFolder", "Settings", "Snapshot",
    "StepControl", "StepOutcome", "StepResult", "advance", "daughters_share", "divide", "expansion_time_step", "grow", "grow_position",
    "growth_drive", "growth_step", "growth_time_step", "largest_overlap", "load_colony", "load_snapshot", "move",
    "overlap_fractions", "position_step", "push", "rotate", "run_colony", "save_colony", "step", "volumes",
]
