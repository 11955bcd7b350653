"""A solver comparison on your own scene.

Builds a scene of your own (here: a heap of rods in 3D thrown together, every tenth one fixed),
then resolves the same contact step with every
installed solver and formulation and prints time, status and the distance to a high-accuracy
reference of the same formulation (``qpcontact.reference_solution``), as ``qpcontact demo``
does for its colony scenes. Replace :func:`my_scene` with yours.

    python examples/compare_solvers.py [--cells 80] [--tolerance 1e-6]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import qpcontact as qc
from qpcontact.resolve import metrics


def my_scene(n_cells: int, seed: int = 0) -> qc.Cells:
    """Rods of mixed sizes in a box [µm], moving towards its centre; every tenth one fixed."""
    rng = np.random.default_rng(seed)
    side = 1.6 * n_cells ** (1 / 3)
    centers = rng.uniform(0.0, side, (n_cells, 3))
    axes = rng.normal(size=(n_cells, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    lengths = rng.uniform(1.0, 3.0, n_cells)
    masses = np.where(np.arange(n_cells) % 10 == 0, np.inf, lengths + 1.0)
    momenta = -(centers - centers.mean(axis=0)) * np.where(np.isfinite(masses), masses, 0.0)[:, None]
    return qc.Cells(centers=centers, axes=axes, lengths=lengths, radii=0.5, masses=masses, growth_inertia=np.inf,
                    momenta=momenta)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--cells", type=int, default=80, help="number of rods (default: 80)")
    parser.add_argument("--tolerance", type=float, default=1e-6, help="solver tolerance [dimensionless] (default: 1e-6)")
    args = parser.parse_args(argv)

    cells = my_scene(args.cells)
    active, b = qc.colliding(qc.find_contacts(cells))
    system = qc.build_system(cells, active, b)
    references = {f: qc.reference_solution(system, f) for f in qc.FORMULATIONS}
    print(f"{cells.n} rods, {len(active)} colliding contacts, {system.shape[1]} unknowns; tolerance {args.tolerance:g}\n")
    print(f"{'solver':10s} {'formulation':16s} {'status':24s} {'ms':>8s} {'distance':>9s}")
    failures = 0
    for solver in qc.available_solvers():
        for formulation in qc.get_solver(solver).formulations:
            start = time.perf_counter()
            result = qc.resolve(cells, solver=solver, formulation=formulation, tolerance=args.tolerance,
                                on_failure="return")
            ms = 1e3 * (time.perf_counter() - start)
            distance = (metrics.distance(result.scaled_solution, references[result.formulation])
                        if result.converged and result.scaled_solution is not None else float("nan"))
            failures += not result.converged and qc.get_solver(solver).bundled
            print(f"{solver:10s} {result.formulation:16s} {result.status[:24]:24s} {ms:8.1f} {distance:9.1e}")
    print("\ndistance: ‖x − x*‖_W / ‖x*‖_W to the reference of the same formulation (linear: the plain solve)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
