"""Growth that feels pressure: a model hook that slows each cell's growth by the pressure its
contacts put on it, so that a colony stalls inside and grows at its edge.

``hook(colony, step, mechanics)`` is called at the start of every step of ``qpcontact simulate``
(with ``--hook examples/pressure_growth.py``) or of ``qpcontact.simulation.run_colony(..., hook=hook)``;
because it takes a parameter named ``mechanics``, the run hands it each cell's pressure and
stress over the step before (a :class:`qpcontact.timestep.CellMechanics`; 2D pressure in F/µm,
F the force that moves 1 µm³ of cell at 1 µm per doubling time). Here:

- each cell's own rate is drawn once for its id around ln 2 (10 % spread), so the hook can
  always start again from it: the rate the hook sets is the one the next step grows with, and
  computing it from the rate set the step before would compound the slowing;
- growth slows linearly with pressure and stops at ``--stall-pressure``
  (:func:`qpcontact.pressure_growth_rate`; ``--law exponential`` for ``exp(−p/p_s)``).

It grows a colony to ``--cells`` twice, without feedback (a stall pressure of 1e300: the same
hook, rates exactly the cells' own) and with it, and says how much longer the second took and
how the pressure differs.

The same laws without a hook, for a whole run: the model settings ``pressure_growth`` and
``stall_pressure`` (``qpcontact simulate --pressure-growth linear --stall-pressure 40``; in
Python ``Settings().updated({"pressure_growth": "linear", "stall_pressure": 40.0})``, or
``run_colony(settings, pressure_growth=PressureGrowth("linear", 40.0))``), which slow each cell's
own rate without a hook. The pressure is in the snapshots, so a run resumed from one
(``--resume``) continues exactly.

    python examples/pressure_growth.py [--cells 400] [--stall-pressure 40] [--out pressure-out]
    qpcontact simulate --hook examples/pressure_growth.py --cells 400
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from qpcontact import pressure_growth_rate
from qpcontact.colony import Colony
from qpcontact.io import RunFolder
from qpcontact.simulation import Settings, run_colony
from qpcontact.timestep import CellMechanics

SEED = 2024
#: The mean growth rate of a free cell [1/doubling time].
BASE_RATE = float(np.log(2.0))
#: Where growth stops [F/µm]; a free colony of 400 cells reaches about 70 at its centre.
STALL_PRESSURE = 40.0


def own_rates(ids: np.ndarray) -> np.ndarray:
    """Each cell's rate without pressure, the same for an id whenever asked."""
    return np.array([BASE_RATE * (1.0 + 0.1 * np.random.default_rng([SEED, int(i)]).standard_normal()) for i in ids])


def make_hook(stall_pressure: float, law: str = "linear") -> Callable[[Colony, int, CellMechanics], Colony]:
    """A hook whose growth stops at ``stall_pressure`` [F/µm] (linear law) or slows by e there."""

    def hook(colony: Colony, step: int, mechanics: CellMechanics) -> Colony:
        rates = pressure_growth_rate(own_rates(colony.ids), mechanics.pressure, law=law, stall_pressure=stall_pressure)
        return colony.replace(rates=rates)

    return hook


#: What ``qpcontact simulate --hook examples/pressure_growth.py`` calls.
hook = make_hook(STALL_PRESSURE)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--cells", type=int, default=400, help="grow to this many cells (default: 400)")
    parser.add_argument("--stall-pressure", type=float, default=STALL_PRESSURE,
                        help=f"pressure at which growth stops [F/µm] (default: {STALL_PRESSURE:g})")
    parser.add_argument("--law", choices=("linear", "exponential"), default="linear", help="growth law (default: linear)")
    parser.add_argument("--out", type=Path, default=Path("pressure-out"), help="output folder (default: ./pressure-out)")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier run in --out")
    args = parser.parse_args(argv)

    folder = RunFolder.create(args.out, overwrite=args.overwrite)
    settings = Settings().updated({"cells": args.cells})
    free = run_colony(settings, progress=False, hook=make_hook(1e300, args.law))
    slowed = run_colony(settings, progress=False, hook=make_hook(args.stall_pressure, args.law), folder=folder)
    for name, run in (("without feedback", free), (f"growth {args.law}, stalling at {args.stall_pressure:g} F/µm", slowed)):
        pressure = run.mechanics.pressure
        print(f"{name}: {run.colony.cells.n} cells at t = {run.colony.time:.2f} doubling times, pressure "
              f"{np.median(pressure):.1f} (median) {pressure.max(initial=0.0):.1f} (largest) F/µm")
    from qpcontact.io.plots import plot_pressure_profile, pressure_label, save_colony_picture

    cells, pressure = slowed.colony.cells, slowed.mechanics.pressure
    folder.note(save_colony_picture(args.out / "colony.png", cells, f"pressure_growth.py: {cells.n} cells, growth "
                                    f"stops at {args.stall_pressure:g} F/µm", values=pressure,
                                    value_label=pressure_label(True)))
    folder.note(plot_pressure_profile(args.out / "pressure.png", cells, pressure, "growth that feels pressure"))
    print(f"wrote {', '.join(map(str, folder.written))}")
    return 1 if slowed.error or free.error else 0


if __name__ == "__main__":
    sys.exit(main())
