"""Growth that slows under pressure: the growth law of a colony run.

**Growth under pressure** (:func:`pressure_growth_rate`): ``r = r₀·max(0, 1 − p/p_s)``
(``"linear"``: growth stops at the stall pressure ``p_s``) or ``r = r₀·exp(−p/p_s)``
(``"exponential"``), with tension (``p < 0``) counted as no pressure, so that growth is never
faster than ``r₀``: the two usual forms of growth inhibited by contact pressure in models of
growing colonies and self-driven jamming. The pressure of each cell is that of its contact
forces (:func:`qpcontact.cell_pressure`, :class:`~qpcontact.timestep.mechanics.CellMechanics`).
In a run, :class:`PressureGrowth` applies the law before every step
(:func:`qpcontact.simulation.run_colony`, ``--pressure-growth``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import number, real_array
from ..errors import InvalidArgumentError
from ..timestep.mechanics import CellMechanics, Lineage

__all__ = ["GROWTH_LAWS", "PressureGrowth", "pressure_growth_rate"]


#: The laws of :func:`pressure_growth_rate`.
GROWTH_LAWS = ("linear", "exponential")


def pressure_growth_rate(base_rate: Any, pressure: Any, *, law: str = "linear", stall_pressure: float) -> np.ndarray:
    """Growth rates slowed by pressure (module docstring).

    Args:
        base_rate: the rate without pressure, a number or (N,) [1/time].
        pressure: (N,) cell pressures (:func:`qpcontact.cell_pressure`) in the units of ``stall_pressure``;
            tension (``p < 0``) counts as 0.
        law: ``"linear"``: ``r₀·max(0, 1 − p/p_s)``, growth stops at ``p_s``;
            ``"exponential"``: ``r₀·exp(−p/p_s)``, growth slows by ``e`` at ``p_s``.
        stall_pressure: ``p_s`` > 0, in the units of ``pressure`` (a run's: [force/µm] in 2D,
            [force/µm²] in 3D; :class:`CellMechanics`).

    Returns:
        (N,) rates [1/time], ``0 ≤ r ≤ r₀``.

    Raises:
        InvalidArgumentError: an unknown law, a stall pressure that is not a finite number > 0,
            rates or pressures that are not finite, negative rates, or shapes that do not match.
    """
    if law not in GROWTH_LAWS:
        raise InvalidArgumentError(f"law: expected one of {', '.join(GROWTH_LAWS)}, got {law!r}")
    stall_pressure = number("stall_pressure", stall_pressure, minimum=0.0, open_minimum=True)
    base = real_array("base_rate", base_rate, InvalidArgumentError)
    p = real_array("pressure", pressure, InvalidArgumentError)
    if p.ndim != 1 or base.ndim > 1 or (base.ndim == 1 and base.shape != p.shape):
        raise InvalidArgumentError(f"base_rate and pressure: expected a number or (N,) rates and (N,) pressures, got "
                                   f"shapes {base.shape} and {p.shape}")
    if not (np.all(np.isfinite(base)) and np.all(base >= 0) and np.all(np.isfinite(p))):
        raise InvalidArgumentError("base_rate and pressure: rates must be finite and >= 0, pressures finite")
    load = np.maximum(p, 0.0) / stall_pressure
    factor = np.maximum(0.0, 1.0 - load) if law == "linear" else np.exp(-load)
    return base * factor


@dataclass(frozen=True)
class PressureGrowth:
    """Pressure-dependent growth in a colony run (:func:`qpcontact.simulation.run_colony`): before
    each step, every cell's rate is :func:`pressure_growth_rate` of its own rate (the colony's
    ``rates``, which stay as they are: the slowed rates apply to that step only) and the
    pressure of the step before.

    Attributes:
        law: ``"linear"`` or ``"exponential"`` (:func:`pressure_growth_rate`).
        stall_pressure: ``p_s`` > 0 in the run's pressure units ([force/µm] in 2D, [force/µm²]
            in 3D).
    """

    law: str
    stall_pressure: float

    def __post_init__(self) -> None:
        pressure_growth_rate(np.zeros(0), np.zeros(0), law=self.law, stall_pressure=self.stall_pressure)  # checks

    def rates(self, colony: Lineage, mechanics: CellMechanics) -> np.ndarray:
        """The rates of ``colony``'s cells for the next step."""
        return pressure_growth_rate(colony.rates, mechanics.pressure, law=self.law, stall_pressure=self.stall_pressure)

