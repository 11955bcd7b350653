"""``qpcontact demo``: resolve one colony scene with every installed solver and print a table.

The quick start's main job: it shows, on this machine, what each solver returns for the same
timestep (time and error against a high-accuracy reference of the same formulation). Exit
status 1 when a solver installed with qpcontact itself (:attr:`~qpcontact.solvers.SolverSpec.bundled`)
fails.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..assembly import build_system
from ..errors import QPContactError
from ..geometry import colliding, find_contacts
from ..resolve import metrics, reference_solution, resolve
from ..solvers import FORMULATIONS, available_solvers, get_solver
from .scenes import colony_2d, colony_3d

COLUMNS = ("solver", "formulation", "status", "ok", "total ms", "solve ms", "penetration", "distance", "momentum", "ΔKE/KE_imp")


def run(n_cells: int, seed: int, dimensions: int, tolerance: float) -> tuple[str, list[tuple[str, ...]]]:
    """Resolve one scene with every solver × formulation; returns (scene line, table rows)."""
    cells = (colony_2d if dimensions == 2 else colony_3d)(n_cells, seed)
    active, b = colliding(find_contacts(cells))
    system = build_system(cells, active, b)
    references = {f: reference_solution(system, f) for f in FORMULATIONS}
    rows: list[tuple[str, ...]] = []
    for solver in available_solvers():
        for formulation in get_solver(solver).formulations:
            start = time.perf_counter()
            try:
                r = resolve(cells, solver=solver, formulation=formulation, tolerance=tolerance, on_failure="return")
            except QPContactError as exc:  # e.g. a backend that cannot take the problem at all
                rows.append((solver, formulation, f"error: {exc}"[:40], "no", f"{(time.perf_counter() - start) * 1e3:.1f}",
                             "", "", "", "", ""))
                continue
            dist = metrics.distance(r.scaled_solution, references[r.formulation]) if r.scaled_solution is not None else float("nan")
            rows.append((
                solver, r.formulation, r.status[:28], "yes" if r.converged else "NO",
                f"{r.times['total'] * 1e3:.1f}", f"{r.times['solve'] * 1e3:.1f}",
                f"{r.errors.get('penetration', float('nan')):.1e}", f"{dist:.1e}",
                f"{r.errors.get('momentum_change', float('nan')):.1e}", f"{r.errors.get('energy_change_relative', float('nan')):+.2f}",
            ))
    scene = (f"{dimensions}D colony, {cells.n} cells, {len(active)} colliding contacts, {system.shape[1]} unknowns "
             f"({'planar' if system.planar else '3D'} reduction), tolerance {tolerance:g}")
    return scene, rows


def markdown(rows: list[tuple[str, ...]]) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="qpcontact demo", description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--cells", type=int, default=500, help="number of cells (default 500)")
    parser.add_argument("--dimensions", type=int, choices=(2, 3), default=2,
                        help="2D monolayer or 3D biofilm (default 2)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tolerance", type=float, default=1e-6, help="solver tolerance (default 1e-6)")
    parser.add_argument("--out", type=Path, default=None, help="also write the table (Markdown) to this file")
    args = parser.parse_args(argv)
    scene, rows = run(args.cells, args.seed, args.dimensions, args.tolerance)
    text = (f"{scene}\n\n{markdown(rows)}\n\npenetration: worst remaining approach / largest approach speed; "
            "distance: ‖x − x*‖_W/‖x*‖_W to a high-accuracy reference of the same formulation; momentum: |ΣΔp|/Σ|λ|; "
            "ΔKE/KE_imp: kinetic energy change over the impulse energy (≤ 0 for inelastic contact).")
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")
    failed = [row for row in rows if row[3] != "yes" and get_solver(row[0]).bundled]
    return 1 if failed else 0
