"""The per-timestep calls, the product of this project: one step of a user's own simulation.

- :mod:`.position`: :func:`position_step` and its :class:`PositionSettings`, the step with
  non-penetration at the end of the step (sequential linearization; the default of
  ``qpcontact simulate``);
- :mod:`.step`: :func:`step` and its :class:`VelocitySettings`, the velocity-level step
  (momenta before contact, contacts with cells and planes, resolve, move), and its helpers;
- :mod:`.mechanics`: contact forces as mechanics: :func:`cell_forces`, :func:`cell_stress`,
  :func:`cell_pressure` (virial stress and pressure of each cell), :class:`CellMechanics`,
  :func:`radial_profile`, :func:`fit_parabola`.

Both steps move the cells with :func:`qpcontact.geometry.motion.move` and measure overlap with
:mod:`qpcontact.geometry.overlap`. Imports the geometry, assembly, solvers and resolve wings
only: nothing of the colony model, of what a run writes, or of ensembles
(docs/architecture.md).
"""

from typing import Any

from .. import moved
from .mechanics import (
    CellMechanics,
    cell_forces,
    cell_pressure,
    cell_stress,
    fit_parabola,
    radial_profile,
)
from .position import CellMotion, ContactImpulses, PositionSettings, PositionStepResult, position_step
from .step import StepResult, VelocitySettings, step


def __getattr__(name: str) -> Any:
    """The names that moved out of this package (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])


__all__ = [
    "CellMechanics", "CellMotion", "ContactImpulses", "PositionSettings", "PositionStepResult", "StepResult",
    "VelocitySettings", "cell_forces", "cell_pressure", "cell_stress", "fit_parabola", "position_step",
    "radial_profile", "step",
]
