"""The plain linear solve on a grown colony: every route of ``solve_min_norm`` timed on one system.

The workload of docs/solvers.md, "The plain solve at colony scale": a snapshot of a grown colony
(``qpcontact simulate --cells 3000 --out run``), every cell given a unit velocity towards the
colony's centre, the contacts within ``--margin`` (0.05: the position step leaves its contacts at
a small gap, so the default margin 0 finds almost none), ``resolve(solver="linear")``, then each
route (``cholesky``, ``lu``, ``lsmr``) on the same scaled system at ``--tolerance``, and
``compare_with_linear`` twice on one Clarabel result (the second reuses the first's solve).

    python benchmarks/linear_grown.py RUN/snapshots/step_000262.npz

Prints a Markdown table (seconds, refinement steps or iterations, optimality, the largest
difference from the Cholesky answer, pulling contacts).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import warnings

import numpy as np

import qpcontact as qc
from qpcontact.errors import PullingImpulseWarning, SolverFailedError
from qpcontact.io.snapshots import load_cells
from qpcontact.solvers import solve_min_norm


def pushed_inward(cells: qc.Cells) -> qc.Cells:
    """Each cell moving at unit speed towards the centroid of the colony."""
    offset = cells.centers - cells.centers.mean(axis=0)
    inward = -offset / np.maximum(np.linalg.norm(offset, axis=1, keepdims=True), 1e-12)
    masses = np.broadcast_to(np.asarray(cells.masses, dtype=float), (cells.n,))
    return dataclasses.replace(cells, momenta=inward * masses[:, None])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("snapshot")
    parser.add_argument("--margin", type=float, default=0.05)
    parser.add_argument("--tolerance", type=float, default=1e-10)
    parser.add_argument("--methods", default="cholesky,lu,lsmr")
    args = parser.parse_args(argv)
    cells = pushed_inward(load_cells(args.snapshot))
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PullingImpulseWarning)
        result = qc.resolve(cells, solver="linear", margin=args.margin)
    system = result.system
    assert system is not None, "no contact: a larger --margin?"
    print(f"{cells.n} cells, {system.shape[0]} contacts, {system.shape[1]} unknowns; "
          f"resolve(solver='linear'): {time.perf_counter() - start:.2f} s, {result.status}")
    print("\n| route | seconds | steps | optimality | ‖ỹ − ỹ_cholesky‖/‖ỹ‖ | pulling |\n|---|---|---|---|---|---|")
    answers: dict[str, np.ndarray] = {}
    for method in args.methods.split(","):
        start = time.perf_counter()
        try:
            lin = solve_min_norm(system.matrix, system.rhs, tolerance=args.tolerance, method=method)
        except SolverFailedError as exc:
            print(f"| {method} | {time.perf_counter() - start:.2f} | failed: {exc} | | | |")
            continue
        seconds = time.perf_counter() - start
        answers[method] = lin.y
        ref = answers.get("cholesky", lin.y)
        difference = np.linalg.norm(lin.y - ref) / max(np.linalg.norm(ref), 1e-300)
        print(f"| {method} | {seconds:.2f} | {lin.iterations} | {lin.optimality:.1e} | {difference:.1e} | "
              f"{qc.solvers.linear.pulling_contacts(lin.lam)} |")
    qp = qc.resolve(cells, solver="clarabel", margin=args.margin, on_failure="return")
    times = []
    for tolerance in (1e-5, 1e-3):
        start = time.perf_counter()
        qc.compare_with_linear(qp, tolerance=tolerance)
        times.append(time.perf_counter() - start)
    print(f"\ncompare_with_linear on a Clarabel result: first call {times[0]:.3f} s, second {times[1]:.4f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
