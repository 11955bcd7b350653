"""A 3D biofilm on a substrate, exported to ParaView.

Grows a biofilm from one cell on the plane z = 0 with ``qpcontact.simulation.run_colony`` (the
library behind ``qpcontact simulate --dimensions 3 --vtk``), saving a snapshot and a ParaView
file every few steps, then prints how to look at it. Needs meshio (``pip install
'qpcontact[vtk]'``).

    python examples/biofilm_paraview.py [--cells 200] [--out biofilm-out] [--overwrite]

In ParaView: File > Open ``biofilm-out/colony.pvd`` (a time series), Apply; then Filters >
Tube on it with *Vary Radius: By Absolute Scalar*, scalar ``radius``, *Capping* on, and
colour by ``growth_rate``, ``id`` or ``parent_id``; press Play.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import qpcontact as qc
from qpcontact.io import RunFolder, paraview
from qpcontact.io.plots import save_colony_picture
from qpcontact.simulation import Settings, run_colony


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--cells", type=int, default=200, help="grow to this many cells (default: 200)")
    parser.add_argument("--every", type=int, default=25, help="a snapshot and a ParaView file every N steps (default: 25)")
    parser.add_argument("--out", type=Path, default=Path("biofilm-out"), help="output folder (default: ./biofilm-out)")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier run in --out")
    args = parser.parse_args(argv)
    try:
        paraview.check_installed()
    except qc.NotInstalledError as exc:  # one line naming what to install, no traceback
        print(f"biofilm_paraview: {exc}", file=sys.stderr)
        return 2

    settings = Settings().updated({"cells": args.cells, "dimensions": 3, "snapshot_every": args.every, "vtk": True})
    folder = RunFolder.create(args.out, overwrite=args.overwrite, vtk=True)  # checked before the run
    folder.write_config(settings.to_tables(applying=True))
    run = run_colony(settings, folder=folder, progress=False)
    planes = settings.planes()  # the substrate
    folder.note(save_colony_picture(args.out / "colony.png", run.colony.cells, f"{run.colony.cells.n} cells",
                                    side_view=True, planes=planes))
    height = (run.colony.cells.centers[:, 2] + run.colony.cells.radii).max()
    print(f"{run.colony.cells.n} cells in {run.steps} steps, up to {height:.1f} µm above the substrate")
    print(f"open {args.out / 'colony.pvd'} in ParaView ({sum(p.suffix == '.vtu' for p in folder.written)} time steps)")
    return 1 if run.error else 0


if __name__ == "__main__":
    sys.exit(main())
