"""The colony model: cells with lineage, growth and division, time-step rules, model hooks.

- :mod:`.growth`: :class:`Colony` (cells with lineage), :func:`grow` (velocity-level step) and
  :func:`grow_position` (position-level step), :func:`divide`, the time-step rules
  :func:`growth_time_step` and :func:`expansion_time_step`;
- :mod:`.pressure`: growth slowed by pressure (:func:`pressure_growth_rate`,
  :class:`PressureGrowth`);
- :mod:`.hooks`: model hooks, the user's per-step function (:class:`StepControl`);
- :mod:`.statistics`: :func:`colony_statistics`, the packing, contacts, microdomains, edge
  alignment and (3D) layers of a colony state (:class:`ColonyStatistics`; docs/statistics.md).

Imports the per-timestep calls (:mod:`qpcontact.timestep`) and the wings below them only. The
run loop and its settings are :mod:`qpcontact.simulation`, what a run writes and reads
:mod:`qpcontact.io`, sweeps :mod:`qpcontact.ensembles` (docs/architecture.md). The names and
submodules this package held before that layout still work until the version
:data:`qpcontact.moved.REMOVED_IN` and warn with a :class:`DeprecationWarning` naming their new
home (:mod:`qpcontact.moved`).
"""

from typing import Any

from .. import moved
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
from .pressure import GROWTH_LAWS, PressureGrowth, pressure_growth_rate
from .statistics import ColonyStatistics, StatisticsOptions, colony_statistics


def __getattr__(name: str) -> Any:
    """The names that moved out of this package (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])


__all__ = [
    "GROWTH_LAWS", "Colony", "ColonyStatistics", "PressureGrowth", "StatisticsOptions", "StepControl",
    "colony_statistics", "daughters_share", "divide", "expansion_time_step", "grow", "grow_position",
    "growth_drive", "growth_step", "growth_time_step", "pressure_growth_rate", "push", "volumes",
]
