"""One colony over MPI processes: time per step, memory per process, and agreement with one process.

    python benchmarks/mpi_scaling.py --states DIR [--steps 3] [--out mpi-scaling.md]

Run with the distributed stack's Python (``scripts/install-mpi VENV``; ``VENV/bin/python``). DIR holds
grown colonies as ``qpcontact bench-grown`` caches them (``2d-10000.npz``, ``2d-20000.npz``,
``3d-5000.npz`` for the scaling; ``2d-3000.npz`` and ``3d-1000.npz`` for the agreement; missing ones
are left out and said). Each measurement is a child, in one process or under ``mpiexec -n P``, that
takes one step from the state untimed (its warm start and predictor), then times ``--steps`` steps of
the run's own step function (``simulate``'s), each from the last:

- *strong scaling*: the same state in one process with ``ipm`` (CHOLMOD, the default), on one MPI
  process and on two with ``ipm-petsc`` (MUMPS), and (2D) on two with detection repeated in each
  process instead of shared by region (the path before it was shared), each step by phase;
- *weak scaling*: ``2d-10000`` on one process against ``2d-20000`` on two;
- *memory*: each process's peak resident memory (``ru_maxrss``) at the end;
- *agreement*: the end positions of ``--steps`` steps on two processes against one process's, in
  diameters (the tips of every cell), and the cells' ids;
- *alike runs* (``--grow N``): whole 2D runs from one cell to N cells in one process and on two:
  wall time, steps, time to size, largest overlap, the radial pressure profile.

Prints a Markdown table and writes it to ``--out`` (default ``./mpi-scaling.md``), with the date, the
commit, the machine and its load.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path
from statistics import median

from qpcontact.studies.grown import machine

sys.path.insert(0, str(Path(__file__).parent))
from profile_step import version  # noqa: E402  (the commit of the qpcontact the children import)

CHILD = r"""
import json, resource, sys, time
import numpy as np
from qpcontact.io import load_colony
from qpcontact.simulation import Settings
from qpcontact.simulation.steps import sink_drive, step_function

state, steps, how, ends = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
solver = "ipm" if how == "ipm" else "ipm-petsc"
comm = None
if solver == "ipm-petsc":
    from qpcontact.solvers.petsc import world
    comm = world()
colony, _ = load_colony(state)
three_d = bool(np.any(colony.cells.centers[:, 2] != 0))
settings = Settings().updated({"dimensions": 3 if three_d else 2, "position.solver": solver}, "mpi-scaling")
extra = {}
# "repeated": the solve split, detection in every process (as before it was shared by region)
take_step = step_function(settings, extra, None if how == "repeated" else comm)

colony = take_step(colony, settings.time_step_of(colony), drive=sink_drive(settings, colony)).colony
rows = []
for _ in range(steps):
    if comm is not None:
        comm.Barrier()
    t = time.perf_counter()
    outcome = take_step(colony, settings.time_step_of(colony), drive=sink_drive(settings, colony))
    total = time.perf_counter() - t
    result = outcome.result
    rows.append(dict(cells=colony.cells.n, total=total, solve=result.times["solve"], detect=result.times["detect"],
                     assemble=result.times["assemble"],
                     linearizations=result.iterations, solver_iterations=result.solver_iterations,
                     max_overlap=result.max_overlap))
    colony = outcome.colony
memory = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # MiB
memories = [memory] if comm is None else comm.gather(memory, root=0)
if comm is None or comm.Get_rank() == 0:
    c = colony.cells
    np.savez(ends, ids=colony.ids, tips=np.concatenate([c.centers + 0.5 * c.lengths[:, None] * c.axes,
                                                        c.centers - 0.5 * c.lengths[:, None] * c.axes]),
             diameter=2.0 * float(np.median(c.radii)))
    print(json.dumps(dict(rows=rows, memory=memories)))
"""


def environment() -> dict[str, str]:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    if os.geteuid() == 0:  # Open MPI refuses root unless told
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def measure(state: Path, steps: int, solver: str, processes: int, ends: Path) -> dict:
    """One child: its timed steps and each process's peak memory."""
    command = [sys.executable, "-c", CHILD, str(state), str(steps), solver, str(ends)]
    if solver != "ipm":
        command = ["mpiexec", "-n", str(processes), *command]
    done = subprocess.run(command, capture_output=True, text=True, check=False, env=environment())
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command[:4])} ... on {state} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def apart(one: Path, two: Path) -> tuple[bool, float]:
    """Whether two runs' end states have the same ids, and how far apart their tips are [diameters]."""
    import numpy as np

    a, b = np.load(one), np.load(two)
    same = a["ids"].shape == b["ids"].shape and bool(np.array_equal(a["ids"], b["ids"]))
    return same, float(np.max(np.abs(a["tips"] - b["tips"]))) / float(a["diameter"]) if same else float("nan")


def alike(cells: int, scratch: Path) -> list[str]:
    """Whole runs from one cell to ``cells`` (2D, ``simulate``'s defaults) in one process and on
    two: their wall time, steps, time to size, largest overlap and radial pressure profile."""
    import numpy as np

    from qpcontact.io import load_snapshot
    from qpcontact.io.runs import latest_snapshot
    from qpcontact.timestep.mechanics import radial_profile

    runs = {}
    for label, processes in (("one process (ipm)", 1), ("2 MPI processes (ipm-petsc)", 2)):
        folder = scratch / f"grow-{processes}"
        command = [sys.executable, "-m", "qpcontact", "simulate", "--quiet", "--cells", str(cells), "--out", str(folder)]
        if processes > 1:
            command = ["mpiexec", "-n", str(processes), *command]
        t = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, check=False, env=environment())
        wall = time.perf_counter() - t
        if done.returncode != 0:
            raise SystemExit(f"the run to {cells} cells on {processes} failed:\n{done.stderr[-3000:]}")
        snapshot = load_snapshot(latest_snapshot(folder))
        history = np.genfromtxt(folder / "history.csv", delimiter=",", names=True)
        assert snapshot.mechanics is not None
        profile = radial_profile(snapshot.colony.cells, snapshot.mechanics.pressure, bins=10)
        runs[label] = (wall, snapshot, float(np.max(history["max_overlap"])), profile)
        print(f"grown to {cells} on {processes}: {wall:.0f} s", file=sys.stderr)
    lines = [f"Whole runs, one cell to {cells:,} (2D, simulate's defaults), one process against two:\n",
             "| run on | wall [s] | steps | cells | time [doubling times] | largest overlap | "
             "mean pressure by tenth of the radius, centre to edge |", "|---|---:|---:|---:|---:|---:|---|"]
    for label, (wall, snapshot, overlap, profile) in runs.items():
        lines.append(f"| {label} | {wall:.1f} | {snapshot.step} | {snapshot.colony.cells.n:,} | "
                     f"{snapshot.colony.time:.3f} | {overlap:.4f} | " + ", ".join(f"{m:.3g}" for m in profile.mean) + " |")
    return lines


CONFIGURATIONS = (("one process, ipm", "ipm", 1), ("1 MPI process, ipm-petsc", "ipm-petsc", 1),
                  ("2 MPI processes, ipm-petsc", "ipm-petsc", 2),
                  ("2 MPI processes, ipm-petsc, detection in each", "repeated", 2))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--states", type=Path, required=True, help="folder of grown colonies (bench-grown's cache)")
    parser.add_argument("--steps", type=int, default=3, help="steps timed per measurement, median kept (default: 3)")
    parser.add_argument("--grow", type=int, default=0,
                        help="also grow a 2D colony from one cell to this many cells in one process and on two, "
                             "and compare the runs (default: 0, not run)")
    parser.add_argument("--out", type=Path, default=Path("mpi-scaling.md"),
                        help="the Markdown table written (default: ./mpi-scaling.md)")
    args = parser.parse_args(argv)
    if args.steps < 1:
        parser.error("--steps: expected an integer >= 1")
    if not args.states.is_dir():
        parser.error(f"--states: no such folder: {args.states}")
    started, measured_on = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"), machine()
    scratch = Path(tempfile.mkdtemp(prefix="mpi-scaling-"))
    lines = [f"# One colony over MPI processes\n\n{started}, qpcontact {version()}, {measured_on} at the start; median of {args.steps} "
             "steps per line, each from the last, after one untimed step; memory: each process's peak resident "
             "set.\n",
             "| state | cells | run on | step [s] | detection [s] | assembly [s] | contact solve [s] | speed-up (to one "
             "process) | speed-up (to 1 MPI process) | IPM iterations | largest overlap | peak memory per process [MiB] |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    steps: dict[tuple[str, str], float] = {}
    for name in ("2d-20000", "3d-5000", "2d-10000"):
        state = args.states / f"{name}.npz"
        if not state.is_file():
            print(f"{state}: missing, left out", file=sys.stderr)
            continue
        for label, solver, processes in CONFIGURATIONS:
            if name == "2d-10000" and processes == 2:
                continue  # the weak scaling's one-process half
            t = time.perf_counter()
            result = measure(state, args.steps, solver, processes, scratch / f"{name}-{solver}-{processes}.npz")
            rows = result["rows"]
            step, solve = median(r["total"] for r in rows), median(r["solve"] for r in rows)
            steps[(name, label)] = step
            first = steps.get((name, CONFIGURATIONS[0][0]), float("nan"))
            petsc_one = steps.get((name, CONFIGURATIONS[1][0]), float("nan"))
            detect, assemble = median(r["detect"] for r in rows), median(r["assemble"] for r in rows)
            lines.append(f"| {name} | {rows[0]['cells']:,} | {label} | {step:.2f} | {detect:.2f} | {assemble:.2f} | "
                         f"{solve:.2f} | {first / step:.2f} | "
                         f"{petsc_one / step:.2f} | {median(r['solver_iterations'] for r in rows):g} | "
                         f"{max(r['max_overlap'] for r in rows):.4f} | "
                         + ", ".join(f"{m:.0f}" for m in result["memory"]) + " |")
            print(f"{name}, {label}: {time.perf_counter() - t:.0f} s", file=sys.stderr)
    weak = [(f"{n} on {label}", steps[(n, label)]) for n, label in
            (("2d-10000", CONFIGURATIONS[0][0]), ("2d-10000", CONFIGURATIONS[1][0]), ("2d-20000", CONFIGURATIONS[2][0]))
            if (n, label) in steps]
    if len(weak) == 3:
        lines.append(f"\nWeak scaling (2D, N = 10⁴ on one process, 2N on two): {weak[2][1]:.2f} s against "
                     f"{weak[0][1]:.2f} s (ipm) and {weak[1][1]:.2f} s (ipm-petsc on one): "
                     f"{weak[2][1] / weak[0][1]:.2f}× and {weak[2][1] / weak[1][1]:.2f}× the time per step.")
    agreement = []
    for name in ("2d-3000", "3d-1000"):
        state = args.states / f"{name}.npz"
        if not state.is_file():
            print(f"{state}: missing, left out", file=sys.stderr)
            continue
        one, two = scratch / f"{name}-one.npz", scratch / f"{name}-two.npz"
        measure(state, args.steps, "ipm", 1, one)
        measure(state, args.steps, "ipm-petsc", 2, two)
        same, distance = apart(one, two)
        agreement.append(f"| {name} | {args.steps + 1} | {'yes' if same else 'NO'} | {distance:.2e} |")
    if agreement:
        lines += ["\nAgreement, from the same state, steps on 2 MPI processes (ipm-petsc) against one process (ipm):\n",
                  "| state | steps | same cells and ids | largest tip distance [diameters] |", "|---|---:|---|---:|",
                  *agreement]
    if args.grow:
        lines += ["", *alike(args.grow, scratch)]
    text = "\n".join(lines) + "\n"
    print(text)
    args.out.write_text(text)


if __name__ == "__main__":
    main()
