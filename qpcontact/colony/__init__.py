"""Colony: the timestep loop around :func:`qpcontact.resolve`, growth, division, snapshots.

- :mod:`.step`: :func:`step` (momenta before contact, contacts with cells and planes, resolve,
  move) and its helpers;
- :mod:`.growth`: :class:`Colony` (cells with lineage), :func:`grow`, :func:`divide`,
  :func:`expansion_time_step`;
- :mod:`.snapshots`: colony snapshots as NPZ (:func:`save_colony`, :func:`load_colony`), the one
  reader and writer of cells in NPZ files;
- :mod:`.simulate`: ``qpcontact simulate`` (:func:`run_colony` with :class:`Settings`);
- :mod:`.plots`: pictures of a run (matplotlib; imported only when drawing:
  ``from qpcontact.colony import plots``).

Imports the geometry, assembly, solvers and resolve wings only.
"""

from .growth import Colony, divide, expansion_time_step, grow, growth_drive, growth_step, volumes
from .simulate import Run, Settings, run_colony
from .snapshots import load_colony, save_colony
from .step import StepResult, advance, largest_overlap, overlap_fractions, rotate, step

__all__ = [
    "Colony", "Run", "Settings", "StepResult", "advance", "divide", "expansion_time_step", "grow", "growth_drive",
    "growth_step", "largest_overlap", "load_colony", "overlap_fractions", "rotate", "run_colony", "save_colony",
    "step", "volumes",
]
