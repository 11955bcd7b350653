"""One colony over MPI processes, measured per process: CPU seconds of each phase, MUMPS's flops and
factor, bytes sent, peak memory, at P = 1, 2, 4, 8, and agreement with one process.

    python benchmarks/mpi_scaling.py --states DIR [--steps 2] [--processes 1,2,4,8] [--folder OUT] [--profile]

Run with the distributed stack's Python (``scripts/install-mpi VENV``; ``VENV/bin/python``). DIR holds
grown colonies as ``qpcontact bench-grown`` caches them (``--names``, default ``2d-20000`` and
``3d-5000``; missing ones are left out and said). Each measurement is a child, in one process with
``ipm`` (CHOLMOD, the default) or under ``mpiexec -n P`` with ``ipm-petsc`` (MUMPS), that takes one
step from the state untimed (its warm start and predictor), then ``--steps`` steps of the run's own
step function (``simulate``'s), each from the last; every process reports its own numbers:

- CPU seconds (``time.process_time``) of the step, of detection, assembly and the solve, and of
  MUMPS's factorizations within it;
- MUMPS's flops of elimination on that process (RINFO(3)) and its factor entries (INFO(9));
- the bytes it sent (qpcontact's collectives, the halo of the products with ``B̃``, the gathered
  answer);
- its peak resident memory (``ru_maxrss``);
- *counts*, the inputs of ``benchmarks/mpi_model.py``: the number and CPU seconds of its
  collectives, of MUMPS's triangular solves, of the products with ``B̃`` and of the normal matrix, the factorizations
  and the first of each problem (its analysis), the factor entries its solves read, the rows and
  unknowns it owns times the iterations, and its own work (the step's CPU seconds less all of
  those, each of which includes waiting for other processes);
- *agreement*: the end positions on P processes against one process's, in diameters, and the ids;
- *alike runs* (``--grow N``): whole 2D runs from one cell to N cells in one process and on two.

Prints a Markdown table and writes it, with every process's numbers as JSON, under ``--folder``
(default ``./mpi-scaling``), with the date, the commit, the machine and its load.
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
import cProfile, io, json, pstats, resource, sys, time
import numpy as np
from qpcontact.geometry import regions
from qpcontact.io import load_colony
from qpcontact.simulation import Settings
from qpcontact.simulation.steps import sink_drive, step_function

state, steps, how, ends, profile_to = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5]
solver = "ipm" if how == "ipm" else "ipm-petsc"
comm = petsc = None
if solver == "ipm-petsc":
    from qpcontact.solvers import petsc
    from qpcontact.solvers.petsc import world
    comm = world()
colony, _ = load_colony(state)
three_d = bool(np.any(colony.cells.centers[:, 2] != 0))
settings = Settings().updated({"dimensions": 3 if three_d else 2, "position.solver": solver}, "mpi-scaling")
take_step = step_function(settings, {}, comm)

colony = take_step(colony, settings.time_step_of(colony), drive=sink_drive(settings, colony)).colony
rows = []
profiler = cProfile.Profile() if profile_to and (comm is None or comm.Get_rank() == 0) else None
if profiler is not None:
    profiler.enable()
for _ in range(steps):
    if comm is not None:
        comm.Barrier()
        petsc.reset_counters()
    regions.SENT.update(bytes=0, collectives=0, collective_cpu=0.0)
    t, cpu = time.perf_counter(), time.process_time()
    outcome = take_step(colony, settings.time_step_of(colony), drive=sink_drive(settings, colony))
    total, total_cpu = time.perf_counter() - t, time.process_time() - cpu
    times, counters = outcome.result.times, dict(petsc.COUNTERS) if petsc else {}
    sent = regions.SENT["bytes"] + counters.get("halo_bytes", 0.0) + counters.get("gathered_bytes", 0.0)
    nan = float("nan")
    counts = {key: counters.get(key, nan) for key in ("first_factor_cpu", "problems", "factorizations", "normal_cpu",
                                                       "entry_solves",
                                                       "solves", "solve_cpu", "products", "product_cpu",
                                                       "owned_iterations")}
    collective_cpu = regions.SENT["collective_cpu"] + counters.get("collective_cpu", 0.0)
    # this process's own work: what is left when the factorizations, the triangular solves, the
    # products with B̃, the normal matrix and the collectives (each with its waiting) are taken out
    own = total_cpu - collective_cpu - sum(counters.get(k, 0.0) for k in ("factor_cpu", "solve_cpu", "product_cpu",
                                                                          "normal_cpu"))
    rows.append(dict(cells=colony.cells.n, total=total, cpu=total_cpu, detect=times["detect_cpu"],
                     assemble=times["assemble_cpu"], solve=times["solve_cpu"],
                     factor=counters.get("factor_cpu", float("nan")), flops=counters.get("factor_flops", float("nan")),
                     entries=counters.get("factor_entries", float("nan")),
                     mumps_mb=counters.get("factor_memory_mb", float("nan")), sent=sent, own=own,
                     collective_cpu=collective_cpu,
                     collectives=regions.SENT["collectives"] + counters.get("collectives", 0.0), **counts,
                     linearizations=outcome.result.iterations, solver_iterations=outcome.result.solver_iterations,
                     max_overlap=outcome.result.max_overlap))
    colony = outcome.colony
if profiler is not None:
    profiler.disable()
    text = io.StringIO()
    pstats.Stats(profiler, stream=text).sort_stats("tottime").print_stats(80)
    open(profile_to, "w").write(text.getvalue())
memory = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # MiB
mine = dict(rows=rows, memory=memory)
every = [mine] if comm is None else comm.gather(mine, root=0)
if comm is None or comm.Get_rank() == 0:
    c = colony.cells
    np.savez(ends, ids=colony.ids, tips=np.concatenate([c.centers + 0.5 * c.lengths[:, None] * c.axes,
                                                        c.centers - 0.5 * c.lengths[:, None] * c.axes]),
             diameter=2.0 * float(np.median(c.radii)))
    print(json.dumps(every))
"""


def environment() -> dict[str, str]:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    if os.geteuid() == 0:  # Open MPI refuses root unless told
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def measure(state: Path, steps: int, solver: str, processes: int, ends: Path, profile: Path | None = None) -> list[dict]:
    """One child: each process's timed steps and peak memory, in the order of the processes;
    with ``profile``, process 0's timed steps profiled (cProfile, written there)."""
    command = [sys.executable, "-c", CHILD, str(state), str(steps), solver, str(ends), str(profile or "")]
    if solver != "ipm":
        command = ["mpiexec", "-n", str(processes), *command]
    done = subprocess.run(command, capture_output=True, text=True, check=False, env=environment())
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command[:4])} ... on {state} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def per_process(processes: list[dict]) -> dict[str, list[float]]:
    """Each quantity, one value per process: the median over the timed steps (the peak memory)."""
    keys = [k for k in processes[0]["rows"][0] if k not in ("cells",)]
    out = {k: [median(r[k] for r in p["rows"]) for p in processes] for k in keys}
    out["memory"] = [p["memory"] for p in processes]
    out["other"] = [c - f for c, f in zip(out["cpu"], out["factor"], strict=True)]  # NaN for ipm
    return out


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


HEADER = ("| state | cells | run on | step, wall [s] | CPU s per process, largest | CPU s summed | CPU s other than "
          "factorization, largest (ratio to 1 MPI process) | factorization CPU s, largest | detection, assembly, solve "
          "CPU s, largest | MUMPS Gflop per process, largest (summed) | factor entries per process, largest [10⁶] | "
          "MB sent per process, largest | peak memory per process, largest [MiB] | linearizations | largest overlap |",
          "|---|---:|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|")


def row(name: str, label: str, values: dict[str, list[float]], cells: int, reference: float) -> str:
    """One line of the per-process table."""
    big = lambda k: max(values[k])  # noqa: E731
    other = big("other")
    ratio = f" ({other / reference:.2f})" if reference == reference and other == other else ""
    flops = f"{big('flops') / 1e9:.1f} ({sum(values['flops']) / 1e9:.1f})" if big("flops") == big("flops") else "–"
    entries = f"{big('entries') / 1e6:.2f}" if big("entries") == big("entries") else "–"
    return (f"| {name} | {cells:,} | {label} | {big('total'):.2f} | {big('cpu'):.2f} | {sum(values['cpu']):.2f} | "
            f"{other:.2f}{ratio} | {big('factor'):.2f} | {big('detect'):.2f}, {big('assemble'):.2f}, "
            f"{big('solve'):.2f} | {flops} | {entries} | {big('sent') / 1e6:.2f} | {big('memory'):.0f} | "
            f"{median(values['linearizations']):g} | {max(values['max_overlap']):.4f} |")


COUNTS = ("| state | run on | own work CPU s, largest (summed) | collectives: number, CPU s | triangular solves: "
          "number, CPU s | products with B̃: number, CPU s | normal matrix CPU s | factorizations: number (problems), CPU s of the first "
          "of each problem | factor entries read by the solves [10⁹] | owned rows and unknowns × iterations [10⁶] |",
          "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")


def counts_row(name: str, label: str, values: dict[str, list[float]]) -> str:
    """One line of the table of counts: each the largest over the processes (the own work's sum too)."""
    big = lambda k: max(values[k])  # noqa: E731
    if big("solves") != big("solves"):  # one process with ipm: no MPI, no MUMPS
        return f"| {name} | {label} | {big('own'):.2f} ({sum(values['own']):.2f}) | – | – | – | – | – | – | – |"
    return (f"| {name} | {label} | {big('own'):.2f} ({sum(values['own']):.2f}) | {big('collectives'):.0f}, "
            f"{big('collective_cpu'):.2f} | {big('solves'):.0f}, {big('solve_cpu'):.2f} | {big('products'):.0f}, "
            f"{big('product_cpu'):.2f} | {big('normal_cpu'):.2f} | {big('factorizations'):.0f} ({big('problems'):.0f}), "
            f"{big('first_factor_cpu'):.2f} | {big('entry_solves') / 1e9:.2f} | {big('owned_iterations') / 1e6:.2f} |")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--states", type=Path, required=True, help="folder of grown colonies (bench-grown's cache)")
    parser.add_argument("--steps", type=int, default=2, help="steps timed per measurement, median kept (default: 2)")
    parser.add_argument("--processes", default="1,2,4,8",
                        help="the numbers of MPI processes, comma-separated (default: 1,2,4,8; oversubscribed "
                             "where the machine has fewer cores)")
    parser.add_argument("--names", default="2d-20000,3d-5000",
                        help="the states of --states measured, comma-separated (default: 2d-20000,3d-5000)")
    parser.add_argument("--grow", type=int, default=0,
                        help="also grow a 2D colony from one cell to this many cells in one process and on two, "
                             "and compare the runs (default: 0, not run)")
    parser.add_argument("--profile", action="store_true",
                        help="profile process 0's timed steps (cProfile; its times are then inflated) and write the 80 "
                             "functions of most own time of each run beside the table, profile-NAME-SOLVER-P.txt")
    parser.add_argument("--folder", type=Path, default=Path("mpi-scaling"),
                        help="where the table (mpi-scaling.md) and every process's numbers (mpi-scaling.json) are "
                             "written (default: ./mpi-scaling)")
    args = parser.parse_args(argv)
    if args.steps < 1:
        parser.error("--steps: expected an integer >= 1")
    if not args.states.is_dir():
        parser.error(f"--states: no such folder: {args.states}")
    try:
        counts = [int(p) for p in args.processes.split(",")]
    except ValueError:
        parser.error(f"--processes: expected integers separated by commas, got {args.processes!r}")
    if any(p < 1 for p in counts):
        parser.error(f"--processes: expected integers >= 1, got {args.processes!r}")
    args.folder.mkdir(parents=True, exist_ok=True)
    started, measured_on = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"), machine()
    scratch = Path(tempfile.mkdtemp(prefix="mpi-scaling-"))
    lines = [f"# One colony over MPI processes, per process\n\n{started}, qpcontact {version()}, {measured_on} at the "
             f"start; {os.cpu_count()} cores (more processes are oversubscribed); median of {args.steps} steps per "
             "process, each from the last, after one untimed step. CPU seconds: time.process_time of each process "
             "(a process waiting in a collective polls, and that counts); factorization: MUMPS's analysis and "
             "numeric factorizations; MUMPS Gflop: RINFO(3), elimination on that process; factor entries: INFO(9); "
             "MB sent: what qpcontact's collectives send plus the halo of the products with B̃ and the gathered "
             "answer (MUMPS's own messages not counted); memory: peak resident set (ru_maxrss).\n", *HEADER]
    raw: dict[str, dict] = {}
    counted = ["\nCounts per process, the same runs (benchmarks/mpi_model.py builds its model from them). Own work: "
               "the CPU seconds of the step less those of the factorizations, the triangular solves, the products "
               "with B̃, the normal matrix and the collectives, each of which includes its waiting; what is left is work no process "
               "waits in.\n", *COUNTS]
    for name in args.names.split(","):
        state = args.states / f"{name}.npz"
        if not state.is_file():
            print(f"{state}: missing, left out", file=sys.stderr)
            continue
        reference = float("nan")
        for label, solver, processes in [("one process, ipm", "ipm", 1),
                                         *((f"{p} MPI process{'es' if p > 1 else ''}, ipm-petsc", "ipm-petsc", p)
                                           for p in counts)]:
            t = time.perf_counter()
            profile = args.folder / f"profile-{name}-{solver}-{processes}.txt" if args.profile else None
            result = measure(state, args.steps, solver, processes, scratch / f"{name}-{solver}-{processes}.npz", profile)
            values = per_process(result)
            values["cells"] = [float(result[0]["rows"][0]["cells"])]
            if solver == "ipm-petsc" and processes == 1:
                reference = values["other"][0]
            raw[f"{name}, {label}"] = values
            lines.append(row(name, label, values, int(result[0]["rows"][0]["cells"]), reference))
            counted.append(counts_row(name, label, values))
            print(lines[-1], f"({time.perf_counter() - t:.0f} s)", file=sys.stderr)
    lines += counted
    agreement = []
    for name in args.names.split(","):
        state = args.states / f"{name}.npz"
        one = scratch / f"{name}-ipm-1.npz"
        for processes in (p for p in counts if p > 1):
            other = scratch / f"{name}-ipm-petsc-{processes}.npz"
            if state.is_file() and one.is_file() and other.is_file():
                same, distance = apart(one, other)
                agreement.append(f"| {name} | {processes} | {args.steps + 1} | {'yes' if same else 'NO'} | {distance:.2e} |")
    if agreement:
        lines += ["\nAgreement, from the same state, the steps above on P MPI processes (ipm-petsc) against one "
                  "process (ipm):\n", "| state | P | steps | same cells and ids | largest tip distance [diameters] |",
                  "|---|---:|---:|---|---:|", *agreement]
    if args.grow:
        lines += ["", *alike(args.grow, scratch)]
    text = "\n".join(lines) + "\n"
    print(text)
    (args.folder / "mpi-scaling.md").write_text(text)
    (args.folder / "mpi-scaling.json").write_text(json.dumps(dict(date=started, machine=measured_on, per_process=raw),
                                                             indent=1))


if __name__ == "__main__":
    main()
