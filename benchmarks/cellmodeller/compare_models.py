"""One CellModeller model grown by CellModeller and by ``qpcontact cellmodeller``, side by side:
the simulated time (the model's own unit) and the wall time to each size, and the colony at a
size both reached (2D): type fractions, sectors at the rim, and the statistics of issue 32
(packing, contacts per cell, nematic correlation length, local order S, edge alignment).

Inputs, per seed: CellModeller's folder from ``grow_cellmodeller.py --model MODEL --targets
...,N`` (its ``steps.json`` and ``cellmodeller_<N>.npz``), and qpcontact's run folder from
``qpcontact cellmodeller MODEL --cells N --seed S --out FOLDER`` (its ``history.csv`` and last
snapshot). README.md beside this file has the commands.

    python benchmarks/cellmodeller/compare_models.py --size 5000 \\
        --cellmodeller cm-s1 cm-s2 cm-s3 --qpcontact qp-s1 qp-s2 qp-s3

Definitions (issue 32): packing = the cells' capsule area over the area of the colony's filled
footprint (0.1 µm pixels); contacts per cell = twice the pairs with surface gap < 0.1 µm, over the
cells; nematic correlation length = the distance at which ⟨cos 2(θi − θj)⟩ over pairs falls to
1/e; local order S = |⟨exp 2iθ⟩| over the cells within 3 µm of each cell, averaged; edge alignment
= ⟨cos 2(θ − φ)⟩ of the cells within 2 µm of the footprint's edge (φ their polar angle about the
centroid: +1 radial, −1 tangential); sectors = runs of one type (of at least 3 cells) along the
cells at the rim, ordered by polar angle.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from qpcontact.geometry import Cells
from qpcontact.geometry.contacts import find_contacts
from qpcontact.io.snapshots import load_snapshot

PIXEL = 0.1  # µm


def footprint(cells: Cells) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """The filled footprint as a boolean image, its distance-to-edge map [µm], its area [µm²] and
    the image's origin [µm]."""
    lo = cells.centers[:, :2].min(axis=0) - cells.lengths.max() - 2.0
    hi = cells.centers[:, :2].max(axis=0) + cells.lengths.max() + 2.0
    shape = np.ceil((hi - lo) / PIXEL).astype(int)
    image = np.zeros(shape, dtype=bool)
    steps = np.linspace(-0.5, 0.5, 41)
    points = (cells.centers[:, None, :2] + steps[None, :, None] * cells.lengths[:, None, None]
              * cells.axes[:, None, :2]).reshape(-1, 2)
    pixels = np.floor((points - lo) / PIXEL).astype(int)
    image[pixels[:, 0], pixels[:, 1]] = True
    radius = int(round(float(np.median(cells.radii)) / PIXEL))
    disk = np.hypot(*np.mgrid[-radius:radius + 1, -radius:radius + 1]) <= radius
    filled = ndimage.binary_fill_holes(ndimage.binary_dilation(image, structure=disk))
    edge = ndimage.distance_transform_edt(filled) * PIXEL
    return filled, edge, float(filled.sum()) * PIXEL**2, lo


def statistics(cells: Cells, types: np.ndarray) -> dict[str, float]:
    """The colony statistics of the module docstring for a 2D colony."""
    filled, edge, area, lo = footprint(cells)
    capsules = float(np.sum(np.pi * cells.radii**2 + 2 * cells.radii * cells.lengths))
    contacts = find_contacts(cells, 0.1, planar=True)
    pairs = {(int(a), int(b)) for a, b in zip(contacts.cell_a, contacts.cell_b, strict=True) if b >= 0}
    theta = np.arctan2(cells.axes[:, 1], cells.axes[:, 0])
    xy = cells.centers[:, :2]
    tree = cKDTree(xy)
    i, j = tree.query_pairs(30.0, output_type="ndarray").T
    distance = np.linalg.norm(xy[i] - xy[j], axis=1)
    width = 0.25
    which = np.minimum((distance / width).astype(int), int(30.0 / width) - 1)
    count = np.bincount(which, minlength=int(30.0 / width))
    correlation = np.bincount(which, np.cos(2 * (theta[i] - theta[j])), count.size) / np.maximum(count, 1)
    centre = (np.arange(count.size) + 0.5) * width
    below = np.flatnonzero((correlation < 1 / np.e) & (count > 0))
    if below.size == 0:
        length = float("inf")
    elif below[0] == 0:
        length = float(centre[0])
    else:  # linear between the last bin above 1/e and the first below
        k = below[0]
        c0, c1 = correlation[k - 1], correlation[k]
        length = float(centre[k - 1] + (c0 - 1 / np.e) / (c0 - c1) * width)
    near = tree.query_ball_point(xy, 3.0)
    phase = np.exp(2j * theta)
    local = float(np.mean([abs(phase[k].mean()) for k in near]))
    pixels = np.clip(np.floor((xy - lo) / PIXEL).astype(int), 0, np.array(filled.shape) - 1)
    rim = edge[pixels[:, 0], pixels[:, 1]] <= 2.0
    phi = np.arctan2(*(xy - xy.mean(axis=0))[:, ::-1].T)
    order = np.argsort(phi[rim])
    rim_types = types[rim][order]
    changes = np.flatnonzero(rim_types != np.roll(rim_types, 1))
    runs = np.diff(np.concatenate([changes, [changes[0] + rim_types.size]])) if changes.size else np.array([])
    return {"cells": float(cells.n), "type1_fraction": float(np.mean(types == 1)), "packing": capsules / area,
            "contacts_per_cell": 2 * len(pairs) / cells.n, "nematic_length": length, "local_S": local,
            "edge_alignment": float(np.mean(np.cos(2 * (theta[rim] - phi[rim])))),
            "sectors": float(np.sum(runs >= 3))}


def cellmodeller_side(folder: Path, size: int, dt: float) -> tuple[dict[str, float], dict[int, tuple[float, float]]]:
    """CellModeller's state at ``size`` (its statistics) and its (time, wall) to each size."""
    log = json.loads((folder / "steps.json").read_text())["log"]
    wall = np.cumsum([row["t_sim"] for row in log])
    reached = {n: next((row["step"] * dt, float(w)) for row, w in zip(log, wall, strict=True) if row["n"] >= n)
               for n in (1000, 2000, size)}
    data = np.load(folder / f"cellmodeller_{size}.npz")
    cells = Cells(centers=data["centers"], axes=data["axes"], lengths=data["lengths"], radii=data["radii"],
                  normalize_axes=True)
    return statistics(cells, data["cell_types"]), reached


def qpcontact_side(folder: Path, size: int) -> tuple[dict[str, float], dict[int, tuple[float, float]]]:
    """qpcontact's state at ``size`` (the first snapshot at least that large) and its (time, wall)."""
    with open(folder / "history.csv") as fh:
        rows = list(csv.DictReader(fh))
    wall = np.cumsum([float(r["step_seconds"]) for r in rows])
    reached = {n: next((float(r["time"]), float(w)) for r, w in zip(rows, wall, strict=True) if int(r["cells"]) >= n)
               for n in (1000, 2000, size)}
    snapshots = sorted((folder / "snapshots").glob("step_*.npz"))
    colony = next(s.colony for s in map(load_snapshot, snapshots) if s.colony.cells.n >= size)
    return statistics(colony.cells, colony.cell_types), reached


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--size", type=int, default=5000, help="the colony size compared (default 5000)")
    parser.add_argument("--dt", type=float, default=0.025, help="the model's time step (default 0.025)")
    parser.add_argument("--cellmodeller", type=Path, nargs="+", required=True, help="CellModeller's folders, one per seed")
    parser.add_argument("--qpcontact", type=Path, nargs="+", required=True, help="qpcontact's run folders, one per seed")
    args = parser.parse_args(argv)
    sides = {"CellModeller": [cellmodeller_side(f, args.size, args.dt) for f in args.cellmodeller],
             "qpcontact": [qpcontact_side(f, args.size) for f in args.qpcontact]}
    for name, runs in sides.items():
        print(f"{name} ({len(runs)} seeds)")
        for n in (1000, 2000, args.size):
            times = [r[1][n][0] for r in runs]
            walls = [r[1][n][1] for r in runs]
            print(f"  {n:>6} cells at t = {np.mean(times):.3f} ({min(times):.3f}–{max(times):.3f}), wall "
                  f"{np.mean(walls):.1f} s ({min(walls):.1f}–{max(walls):.1f})")
        for key in runs[0][0]:
            values = [r[0][key] for r in runs]
            print(f"  {key:>18}: {np.mean(values):.3f} ({min(values):.3f}–{max(values):.3f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
