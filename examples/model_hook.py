"""A model hook: your own growth, division and forces in a colony run (as CellModeller's model
scripts do).

``hook(colony, step)`` is called at the start of every step of ``qpcontact simulate`` (with
``--hook examples/model_hook.py``) or of ``qpcontact.simulation.run_colony(..., hook=hook)``. Here:

- **growth rates**: nutrients run short inside the colony, so a cell grows at
  ``ln 2 · (0.3 + 0.7 r/R)``, ``r`` its distance from the colony's centre and ``R`` the largest;
- **division**: each cell divides at its own length, drawn once at birth between 3 and 5 µm and
  kept in the colony's per-cell arrays (``colony.cell_data["division_length"]``, like
  CellModeller's ``cell.targetVol``);
- **cell types**: the founder's daughters found two lineages, type A (0) and type B (1)
  (``colony.cell_types``); every daughter inherits her mother's type;
- **forces**: cells of type B swim along +x at 0.5 µm per doubling time.

The types and the per-cell arrays live in the colony: the snapshots save them, so a run resumed
from one (``--resume``) continues exactly. Random numbers come from a generator seeded by the
cell's id, so the hook gives the same answer whenever it is asked.

    python examples/model_hook.py [--cells 150] [--out model-out]
    qpcontact simulate --hook examples/model_hook.py --cells 150
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from qpcontact.colony import Colony, StepControl, push
from qpcontact.io import RunFolder
from qpcontact.simulation import Settings, run_colony

SEED = 2024
#: Growth rate of a cell at the colony's edge [1/doubling time].
EDGE_RATE = float(np.log(2.0))
SWIM_SPEED = 0.5  # [µm/doubling time]


def per_cell(ids: np.ndarray, salt: int) -> np.ndarray:
    """A uniform random number in [0, 1) for each cell id (the same for an id, whenever asked)."""
    return np.array([np.random.default_rng([SEED, salt, int(i)]).random() for i in ids])


TYPE_A, TYPE_B = 0, 1


def hook(colony: Colony, step: int) -> StepControl:
    cells = colony.cells
    r = np.linalg.norm(cells.centers[:, :2] - cells.centers[:, :2].mean(axis=0), axis=1)
    rates = EDGE_RATE * (0.3 + 0.7 * r / max(float(r.max()), 1e-9))
    # A daughter inherits her mother's row: a new length is drawn for a cell born since the last
    # call (her parent's id is not the one the row was drawn for).
    drawn_for = colony.cell_data.get("drawn_for", np.full(cells.n, -2))
    newborn = drawn_for != colony.ids
    division_length = colony.cell_data.get("division_length", np.zeros(cells.n)).copy()
    division_length[newborn] = 3.0 + 2.0 * per_cell(colony.ids[newborn], salt=1)
    types = colony.cell_types.copy()
    founders_daughters = newborn & (colony.parent_ids == 0)
    types[founders_daughters] = np.where(colony.ids[founders_daughters] % 2 == 0, TYPE_A, TYPE_B)
    swimmers = types == TYPE_B
    drive = push(colony, [SWIM_SPEED, 0.0, 0.0]) * swimmers[:, None]
    data = {**colony.cell_data, "division_length": division_length, "drawn_for": colony.ids.copy()}
    return StepControl(colony.replace(rates=rates, cell_types=types, cell_data=data), drive=drive,
                       division_length=division_length)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--cells", type=int, default=150, help="grow to this many cells (default: 150)")
    parser.add_argument("--out", type=Path, default=Path("model-out"), help="output folder (default: ./model-out)")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier run in --out")
    args = parser.parse_args(argv)

    settings = Settings().updated({"cells": args.cells, "hook": str(Path(__file__).resolve())})  # saved with the run
    folder = RunFolder.create(args.out, overwrite=args.overwrite)
    folder.write_config(settings.to_tables(applying=True))
    run = run_colony(settings, folder=folder, progress=False)  # the hook comes from settings.model.hook
    colony = run.colony
    swimmers = colony.cell_types == TYPE_B
    x = colony.cells.centers[:, 0]
    print(f"{colony.cells.n} cells ({swimmers.sum()} swimmers) at t = {colony.time:.2f} doubling times; the swimmers "
          f"pulled the colony's centre to x = {x.mean():+.2f} µm; lengths {colony.cells.lengths.min():.2f}-"
          f"{colony.cells.lengths.max():.2f} µm")
    from qpcontact.io.plots import save_colony_picture

    folder.note(save_colony_picture(args.out / "colony.png", colony.cells, f"model_hook.py: {colony.cells.n} cells",
                                    values=colony.cell_types, value_label="type (0: A, 1: B swims along +x)",
                                    discrete=True))
    print(f"wrote {', '.join(map(str, folder.written))}")
    return 1 if run.error else 0


if __name__ == "__main__":
    sys.exit(main())
