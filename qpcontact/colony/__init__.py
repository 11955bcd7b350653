"""Colony: the timestep loop around :func:`qpcontact.resolve`, growth, division, snapshots.

- :mod:`.step`: :func:`step` (momenta before contact, contacts with cells and planes, resolve,
  move) and its helpers;
- :mod:`.position`: :func:`position_step`, the step with non-penetration at the end of the
  step (sequential linearization; the default of ``qpcontact simulate``);
- :mod:`.growth`: :class:`Colony` (cells with lineage), :func:`grow` (velocity-level step) and
  :func:`grow_position` (position-level step), :func:`divide`, the time-step rules
  :func:`growth_time_step` and :func:`expansion_time_step`;
- :mod:`.snapshots`: colony snapshots as NPZ (:func:`save_colony`, :func:`load_colony`), the one
  reader and writer of cells in NPZ files;
- :mod:`.simulate`: ``qpcontact simulate`` (:func:`run_colony` with :class:`Settings`);
- :mod:`.plots`: pictures of a run (matplotlib; imported only when drawing:
  ``from qpcontact.colony import plots``).

Imports the geometry, assembly, solvers and resolve wings only.
"""

from .growth import (
    Colony,
    divide,
    expansion_time_step,
    grow,
    grow_position,
    growth_drive,
    growth_step,
    growth_time_step,
    volumes,
)
from .position import ContactImpulses, PositionSettings, PositionStepResult, move, position_step
from .simulate import Run, Settings, run_colony
from .snapshots import load_colony, save_colony
from .step import StepResult, advance, largest_overlap, overlap_fractions, rotate, step

__all__ = [
    "Colony", "ContactImpulses", "PositionSettings", "PositionStepResult", "Run", "Settings", "StepResult", "advance", "divide",
    "expansion_time_step", "grow", "grow_position", "growth_drive", "growth_step", "growth_time_step",
    "largest_overlap", "load_colony", "move", "overlap_fractions", "position_step", "rotate", "run_colony",
    "save_colony", "step", "volumes",
]
