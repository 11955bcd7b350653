"""``qpcontact demo``: resolve one colony scene with every installed solver and print a table.

The quick start's main job: it shows, on this machine, what each solver returns for the same
timestep (time and error against a high-accuracy reference of the same formulation). Exit
status 1 when a solver installed with qpcontact itself (:attr:`~qpcontact.solvers.SolverSpec.bundled`)
fails.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

from ..assembly import build_system
from ..cli import non_negative_int, positive_int, run_standalone
from ..cli import tolerance as tolerance_type
from ..errors import PullingImpulseWarning, QPContactError
from ..geometry import colliding, find_contacts
from ..io.outputs import describe_written, prepare_folder, write_text
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
                with warnings.catch_warnings():  # the plain solve's pulling is in its status column
                    warnings.simplefilter("ignore", PullingImpulseWarning)
                    r = resolve(cells, solver=solver, formulation=formulation, tolerance=tolerance, on_failure="return")
            except QPContactError as exc:  # e.g. a backend that cannot take the problem at all
                rows.append((solver, formulation, f"error: {exc}"[:40], "no", f"{(time.perf_counter() - start) * 1e3:.1f}",
                             "", "", "", "", ""))
                continue
            dist = metrics.distance(r.scaled_solution, references[r.formulation]) if r.scaled_solution is not None else float("nan")
            rows.append((
                solver, r.formulation, r.status[:40], "yes" if r.converged else "NO",
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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact demo``."""
    parser.description = ("Resolve one colony scene with every installed solver and print a table: time and error "
                          "against a high-accuracy reference. Writes a file only with --out.")
    parser.add_argument("--cells", type=positive_int, default=500, help="number of cells (default: 500)")
    parser.add_argument("--dimensions", type=int, choices=(2, 3), default=2,
                        help="2: a monolayer; 3: a biofilm (default: 2)")
    parser.add_argument("--seed", type=non_negative_int, default=0, help="random seed of the scene (default: 0)")
    parser.add_argument("--tolerance", type=tolerance_type, default=1e-6,
                        help="solver tolerance [dimensionless, scaled units] (default: 1e-6)")
    parser.add_argument("--out", type=Path, default=None, metavar="FOLDER",
                        help="also write the table (Markdown) to FOLDER/demo.md (default: print only)")
    parser.add_argument("--overwrite", action="store_true", help="replace FOLDER/demo.md of an earlier run")


def run_command(args: argparse.Namespace) -> int:
    """``qpcontact demo``: exit status 1 when a bundled solver fails."""
    if args.out is not None:
        prepare_folder(args.out, ("demo.md",), overwrite=args.overwrite)
    scene, rows = run(args.cells, args.seed, args.dimensions, args.tolerance)
    text = (f"{scene}\n\n{markdown(rows)}\n\npenetration: worst remaining approach / largest approach speed; "
            "distance: ‖x − x*‖_W/‖x*‖_W to a high-accuracy reference of the same formulation; momentum: |ΣΔp|/Σ|λ|; "
            "ΔKE/KE_imp: kinetic energy change over the impulse energy (≤ 0 for inelastic contact); times in ms.")
    print(text)
    if args.out is not None:
        print(describe_written([write_text(args.out / "demo.md", text + "\n")]))
    failed = [row for row in rows if row[3] != "yes" and get_solver(row[0]).bundled]
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact demo", add_arguments, run_command, argv)
