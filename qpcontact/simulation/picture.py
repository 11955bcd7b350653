"""``qpcontact plot SNAPSHOT``: draw a saved snapshot again as its run drew ``colony.png``.

The picture is :func:`qpcontact.colony.simulate.colony_picture` of the snapshot's colony, with
the run's settings stored in the snapshot (dimensions, planes, the step and solver in the
title): from above, and from the side too in 3D, coloured by ``--color`` (orientation,
pressure, cell_type, or the name of one of the model's own per-cell arrays,
:func:`qpcontact.colony.plots.colony_colors`). A snapshot without settings (version 1, or
written by another tool) is drawn with the default settings, in 3D if a cell lies off the plane
``z = 0``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from ..errors import InvalidArgumentError, OutputFolderError
from ..io.snapshots import Snapshot, load_snapshot
from ..io.tables import snapshot_file
from .settings import Settings


def snapshot_settings(snapshot: Snapshot) -> Settings:
    """The run's settings stored in the snapshot, or (none stored) the defaults, in 3D when a
    cell lies off the plane ``z = 0``."""
    if snapshot.settings is not None:
        return Settings.from_stored(snapshot.settings, f"{snapshot.path} (settings)")
    flat = not np.any(snapshot.colony.cells.centers[:, 2]) and not np.any(snapshot.colony.cells.axes[:, 2])
    return Settings().updated({"dimensions": 2 if flat else 3})


def plot_snapshot(snapshot: Snapshot, path: str | Path, color: str = "orientation") -> Path:
    """Draw ``snapshot`` into ``path`` (PNG, SVG, PDF, ... by the suffix) as its run drew
    ``colony.png`` (module docstring). Returns the path.

    Raises:
        InvalidArgumentError: ``color`` names nothing to colour by, or ``pressure`` for a
            snapshot without the cells' mechanics.
    """
    from .simulate import colony_picture, describe_run

    if color == "pressure" and snapshot.mechanics is None:
        raise InvalidArgumentError(f"--color pressure: {snapshot.path} holds no pressure (written before issue 19, or "
                                   "by another tool)")
    settings = snapshot_settings(snapshot)
    colony = snapshot.colony
    title = f"{colony.cells.n} cells at t = {colony.time:.2f} doubling times ({describe_run(settings)})"  # the run's
    return colony_picture(Path(path), colony, snapshot.mechanics, settings, color, title)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = ("Draw a saved snapshot again as its run drew colony.png: from above (and from the side in "
                          "3D), coloured by orientation, pressure, cell type or one of the model's own per-cell arrays.")
    parser.add_argument("source", type=Path, metavar="SNAPSHOT",
                        help="a snapshot (.npz), or a run's folder (its latest snapshot, or --snapshot)")
    parser.add_argument("--snapshot", metavar="N|NAME",
                        help="of a run's folder: the snapshot of step N, or the file NAME in its snapshots/")
    parser.add_argument("--out", type=Path, metavar="FILE",
                        help="the picture (.png, .svg, .pdf, ...; default: the snapshot's name with .png, in the "
                             "current folder)")
    parser.add_argument("--color", default="orientation", metavar="NAME",
                        help="orientation (default), pressure, cell_type, or the name of a per-cell array of the "
                             "model (cell_data) with one number per cell")
    parser.add_argument("--overwrite", action="store_true", help="replace --out if it exists (default: refuse)")


def run_command(args: argparse.Namespace) -> int:
    from matplotlib.figure import Figure

    path = snapshot_file(args.source, args.snapshot)
    out: Path = args.out if args.out is not None else Path(path.with_suffix(".png").name)
    kinds = Figure().canvas.get_supported_filetypes()
    if out.suffix.lower().lstrip(".") not in kinds:
        raise InvalidArgumentError(f"--out {out}: unknown picture suffix {out.suffix!r}; one of "
                                   f"{', '.join('.' + kind for kind in sorted(kinds))}")
    if out.exists() and not args.overwrite:
        raise OutputFolderError(f"--out {out}: exists; pass --overwrite to replace it")
    snapshot = load_snapshot(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    print(f"wrote {plot_snapshot(snapshot, out, args.color)}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    from ..arguments import run_standalone

    return run_standalone("qpcontact plot", add_arguments, run_command, argv)
