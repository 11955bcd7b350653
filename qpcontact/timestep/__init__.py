"""The per-timestep calls, the product of this project: one step of a user's own simulation.

- :mod:`.position`: :func:`position_step`, the step with non-penetration at the end of the
  step (sequential linearization; the default of ``qpcontact simulate``);
- :mod:`.step`: :func:`step`, the velocity-level step (momenta before contact, contacts with
  cells and planes, resolve, move), and its helpers;
- :mod:`.mechanics`: contact forces as mechanics: :func:`cell_forces`, :func:`cell_stress`,
  :func:`cell_pressure` (virial stress and pressure of each cell), :class:`CellMechanics`,
  :func:`radial_profile`, :func:`fit_parabola`, growth slowed by pressure
  (:func:`pressure_growth_rate`, :class:`PressureGrowth`).

Imports the geometry, assembly, solvers and resolve wings only: nothing of the colony model,
of what a run writes, or of ensembles (docs/architecture.md).
"""

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
from .step import StepResult, advance, largest_overlap, overlap_fractions, step

__all__ = [
    "CellMechanics", "CellMotion", "ContactImpulses", "PositionSettings", "PositionStepResult", "PressureGrowth",
    "StepResult", "advance", "cell_forces", "cell_pressure", "cell_stress", "fit_parabola", "largest_overlap", "move",
    "overlap_fractions", "position_step", "pressure_growth_rate", "radial_profile", "step",
]
