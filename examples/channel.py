"""A colony growing between two walls (a microfluidic channel), in your own loop.

One cell grows and divides in a channel 4 µm wide along x: ``qpcontact.divide`` then
``qpcontact.grow`` (growth drive, contact solve with the cells and the two walls, move) each
step (dividing first, so that the step's contact solve sees the daughters), with
the options ``qpcontact simulate`` uses (``Settings().step_options()``) plus the walls
(``qpcontact.channel``). The colony fills the channel and spreads along it. Writes a picture
with the walls drawn.

    python examples/channel.py [--cells 60] [--width 4] [--out channel-out]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import qpcontact as qc
from qpcontact.simulation import Settings, loop


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--cells", type=int, default=60, help="grow to this many cells (default: 60)")
    parser.add_argument("--width", type=float, default=4.0, help="channel width [µm] (default: 4)")
    parser.add_argument("--out", type=Path, default=Path("channel-out"), help="output folder (default: ./channel-out)")
    args = parser.parse_args(argv)

    settings = Settings()
    walls = qc.channel(args.width)
    options = {**settings.step_options(), "planes": walls}
    colony = loop.founder(settings)  # one cell at the origin, along x
    rng = np.random.default_rng(settings.run.seed)
    while colony.cells.n < args.cells:
        colony = qc.divide(colony, settings.model.division_length, rng, axis_noise=settings.model.axis_noise,
                           rate_noise=settings.model.rate_noise, base_rate=settings.model.rate, planar=True)
        dt = qc.expansion_time_step(colony, max_dt=settings.run.max_dt, cfl=settings.run.cfl)
        colony, out = qc.grow(colony, dt, **options)
    cells = colony.cells
    half = 0.5 * cells.lengths[:, None] * cells.axes
    reach = np.abs(np.concatenate([cells.centers - half, cells.centers + half])[:, 1]) + np.tile(cells.radii, 2)
    print(f"{cells.n} cells at t = {colony.time:.2f} doubling times; colony length {np.ptp(cells.centers[:, 0]):.1f} µm; "
          f"outermost cell surface at |y| = {reach.max():.3f} µm (walls at {args.width / 2:g} µm)")

    from qpcontact.io import plots  # matplotlib: only when drawing

    args.out.mkdir(parents=True, exist_ok=True)
    picture = plots.save_colony_picture(args.out / "channel.png", cells, f"{cells.n} cells in a {args.width:g} µm channel",
                                        planes=walls)
    print(f"wrote {picture}")
    return 0 if reach.max() <= args.width / 2 + 0.02 * 2 * settings.model.radius else 1


if __name__ == "__main__":
    sys.exit(main())
