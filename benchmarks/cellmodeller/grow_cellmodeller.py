"""Grow CellModeller's ex1_simpleGrowth headless and time it, step by step, for the side-by-side
comparison with qpcontact (``qpcontact bench-grown --peer-log``).

Runs in a virtual environment of its own with CellModeller's requirements (pyopencl and an
OpenCL driver; README.md beside this file) and qpcontact (for the overlap measure, the same as
bench-grown's). CellModeller is not installed: ``--cellmodeller`` names its checkout (at commit
1382c975, with ``headless-ex1.patch`` applied), which goes on ``sys.path``.

What it writes into ``--out``:

- ``steps.json``: ``{"harness": ..., "args": {...}, "log": [row, ...]}``, one row per step:
  ``step`` (steps taken), ``n`` (cells after the step), ``n_before``, ``t_sim`` (wall seconds of
  ``Simulator.step``: the model's update, divisions, the physics, and CellModeller's own pickle
  every ``pickleSteps`` steps), ``t_phys`` (the physics, ``CLBacterium.step``), ``t_cg`` and
  ``solves`` (its conjugate-gradient solves), ``cg_iterations``, ``cg_residuals``, ``contacts``;
  every ``--overlap-every`` steps and at each target also ``max_overlap`` and ``p99_overlap``
  [µm] and ``overlapping_contacts`` (qpcontact's capsule distances, ``qpcontact.find_contacts``).
  ``bench-grown --peer-log`` sums ``t_sim`` up to the first row with ``n`` at least each size.
- ``data/<run>/step-NNNNN.pickle``: CellModeller's own saved states (every ``pickleSteps``
  steps, 100 in ex1, or ``--pickle-every``; and at each target), which
  ``qpcontact import-cellmodeller`` reads;
- ``cellmodeller_<N>.npz`` at each target N: CellModeller's own arrays at that step, by cell
  (``ids``, ``parent_ids``, ``cell_types``, ``centers``, ``axes``, ``lengths`` — the cylinder
  between the cap centres, as in ``qpcontact.Cells`` — ``radii``, ``growth_rates`` (dL/dt of the
  next step), ``step``, ``time``, ``pickle``).

Usage (README.md): ``python grow_cellmodeller.py --cellmodeller CellModeller --targets 1000,10000``.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import time
from pathlib import Path
from typing import Any

# Without it PoCL compiles every kernel again whenever the number of cells changes (about 1 s a
# step instead of 0.03 s at 34 cells). Set before pyopencl is imported.
os.environ.setdefault("POCL_WORK_GROUP_SPECIALIZATION", "0")

import numpy as np  # noqa: E402

EXAMPLE = "Examples/ex1_simpleGrowth.py"


def arguments(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--cellmodeller", type=Path, default=Path(os.environ.get("CELLMODELLER_SRC", "CellModeller")),
                        help="CellModeller's checkout (default: $CELLMODELLER_SRC or ./CellModeller)")
    parser.add_argument("--model", type=Path, help=f"the model file (default: {EXAMPLE} of the checkout)")
    parser.add_argument("--dt", type=float, default=0.025,
                        help="CellModeller's time step (default: 0.025, as its Scripts/batch.py)")
    parser.add_argument("--seed", type=int, default=1, help="seed of Python's and NumPy's random numbers (default: 1)")
    parser.add_argument("--targets", default="1000,10000",
                        help="cell counts at which the state is saved, comma-separated (default: 1000,10000)")
    parser.add_argument("--after", type=int, default=6, help="steps timed after the last target (default: 6)")
    parser.add_argument("--time-limit", type=float, default=1800.0, help="stop after this many wall seconds (default: 1800)")
    parser.add_argument("--overlap-every", type=int, default=10,
                        help="measure the overlaps every this many steps (and at each target; default: 10)")
    parser.add_argument("--pickle-every", type=int,
                        help="CellModeller saves its state every this many steps (default: the model's, 100 in ex1)")
    parser.add_argument("--out", type=Path, default=Path("cellmodeller-out"),
                        help="output folder (default: ./cellmodeller-out); must not hold an earlier run")
    args = parser.parse_args(argv)
    args.targets = sorted(int(t) for t in args.targets.split(","))
    args.cellmodeller = args.cellmodeller.resolve()
    args.model = (args.model or args.cellmodeller / EXAMPLE).resolve()
    args.out = args.out.resolve()
    if not (args.cellmodeller / "CellModeller" / "Simulator.py").is_file():
        parser.error(f"{args.cellmodeller}: not a CellModeller checkout (no CellModeller/Simulator.py); see README.md")
    if (args.out / "steps.json").exists():
        parser.error(f"{args.out} holds an earlier run (steps.json); choose another --out")
    return args


class Timers:
    """Wall time of CellModeller's physics step and of each of its conjugate-gradient solves,
    by wrapping the two methods of the physics object (the physics itself is untouched)."""

    def __init__(self, physics: Any) -> None:
        self.physics = physics
        self.reset()
        step, solve = physics.step, physics.CGSSolve

        def timed_step(dt: float) -> Any:
            start = time.perf_counter()
            try:
                return step(dt)
            finally:
                self.physics_seconds += time.perf_counter() - start

        def timed_solve(dt: float, alpha: float, substep: bool = False) -> Any:
            start = time.perf_counter()
            iterations, residual = solve(dt, alpha, substep)
            self.solves.append((int(iterations), float(residual), time.perf_counter() - start))
            return iterations, residual

        physics.step, physics.CGSSolve = timed_step, timed_solve

    def reset(self) -> None:
        self.physics_seconds = 0.0
        self.solves: list[tuple[int, float, float]] = []


def step_row(step: int, n: int, n_before: int, t_sim: float, timers: Timers, contacts: int) -> dict[str, Any]:
    """One row of the step log (module docstring)."""
    return dict(step=step, n=n, n_before=n_before, t_sim=t_sim, t_phys=timers.physics_seconds,
                t_cg=sum(s[2] for s in timers.solves), solves=len(timers.solves),
                cg_iterations=[s[0] for s in timers.solves], cg_residuals=[s[1] for s in timers.solves],
                contacts=contacts)


def write_log(path: Path, args: argparse.Namespace, log: list[dict[str, Any]]) -> None:
    """``steps.json``: the harness, its arguments and the step log (what ``bench-grown
    --peer-log`` reads)."""
    path.write_text(json.dumps(dict(
        harness="benchmarks/cellmodeller/grow_cellmodeller.py",
        args={k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()}, log=log)))


def cell_arrays(sim: Any) -> dict[str, np.ndarray]:
    """CellModeller's own arrays of the current state, in the order of its cells' ids."""
    physics = sim.phys
    states = sorted(sim.cellStates.values(), key=lambda s: s.id)
    index = np.array([s.idx for s in states], dtype=np.intp)

    def xyz(array: Any) -> np.ndarray:  # float4 records (x, y, z, w) -> (N, 3)
        return np.asarray(array[: physics.n_cells].view(np.float32).reshape(-1, 4)[index, :3], dtype=np.float64)

    ids = np.array([s.id for s in states], dtype=np.int64)
    return dict(ids=ids, parent_ids=np.array([sim.lineage.get(int(i), -1) for i in ids], dtype=np.int64),
                cell_types=np.array([s.cellType for s in states], dtype=np.int64),
                centers=xyz(physics.cell_centers), axes=xyz(physics.cell_dirs),
                lengths=physics.cell_lens[index].astype(np.float64), radii=physics.cell_rads[index].astype(np.float64),
                growth_rates=physics.cell_growth_rates[index].astype(np.float64))


def overlaps(arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """Overlap statistics of the capsules [µm], with qpcontact's capsule distances."""
    import qpcontact as qc

    cells = qc.Cells(centers=arrays["centers"], axes=arrays["axes"], lengths=arrays["lengths"], radii=arrays["radii"],
                     normalize_axes=True)
    depth = np.maximum(0.0, -qc.find_contacts(cells).separation)
    depth = depth[depth > 0]
    return dict(max_overlap=float(depth.max(initial=0.0)), overlapping_contacts=int(depth.size),
                p99_overlap=float(np.percentile(depth, 99)) if depth.size else 0.0)


def save_pickle(sim: Any) -> Path:
    """CellModeller's own ``writePickle`` of the state now, named and numbered as the pickles it
    writes inside ``Simulator.step`` (``step-NNNNN.pickle`` holds the state after step NNNNN,
    counted from 0, i.e. after NNNNN + 1 steps)."""
    sim.stepNum -= 1
    try:
        sim.writePickle()
        return Path(sim.outputDirPath) / f"step-{sim.stepNum:05d}.pickle"
    finally:
        sim.stepNum += 1


def main(argv: list[str] | None = None) -> int:
    args = arguments(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    random.seed(args.seed)  # the model's targetVol draws
    np.random.seed(args.seed)  # CLBacterium's division jitter
    sys.path.insert(0, str(args.cellmodeller))
    os.environ["CMPATH"] = str(args.out)  # CellModeller writes data/<run>/ under it
    (args.out / "data").mkdir(exist_ok=True)
    os.chdir(args.out)
    from CellModeller.Simulator import Simulator

    sim = Simulator(str(args.model), args.dt, saveOutput=True, outputDirName=f"{args.model.stem}_seed{args.seed}")
    if args.pickle_every:
        sim.pickleSteps = args.pickle_every
    physics = sim.phys
    print(f"CellModeller {args.model.name}: dt {args.dt}, seed {args.seed}, max_substeps {physics.max_substeps}, "
          f"cgs_tol {physics.cgs_tol}, gamma {physics.gamma}; run folder {sim.outputDirPath}", flush=True)
    timers = Timers(physics)
    log: list[dict[str, Any]] = []
    targets, after = list(args.targets), None
    started = time.perf_counter()
    while True:
        timers.reset()
        n_before = len(sim.cellStates)
        t0 = time.perf_counter()
        sim.step()
        t_sim = time.perf_counter() - t0
        row = step_row(sim.stepNum, int(physics.n_cells), n_before, t_sim, timers, int(physics.n_cts))
        reached = bool(targets) and row["n"] >= targets[0]
        if reached or sim.stepNum % args.overlap_every == 0:
            arrays = cell_arrays(sim)
            row.update(overlaps(arrays))
        if reached:
            target = targets.pop(0)
            pickle = save_pickle(sim)
            np.savez(args.out / f"cellmodeller_{target}.npz", **arrays, step=sim.stepNum, time=sim.stepNum * args.dt,
                     pickle=str(pickle.relative_to(args.out)))
            row["state"] = str(pickle.relative_to(args.out))
            print(f"target {target}: {row['n']} cells at step {sim.stepNum}, saved {row['state']}", flush=True)
            after = args.after if not targets else None
        log.append(row)
        wall = time.perf_counter() - started
        if sim.stepNum % 10 == 0:
            print(f"step {sim.stepNum:5d}  {row['n']:6d} cells  physics {row['t_phys']:.3f} s ({row['solves']} CG solves, "
                  f"{sum(row['cg_iterations'])} iterations)  contacts {row['contacts']}  largest overlap "
                  f"{row.get('max_overlap', float('nan')):.4f} µm  wall {wall:.0f} s", flush=True)
        if after is not None:
            after -= 1
            if after < 0:
                break
        if wall > args.time_limit:
            print(f"time limit: stopped at {row['n']} cells, step {sim.stepNum}", flush=True)
            break
    write_log(args.out / "steps.json", args, log)
    print(f"wrote {args.out / 'steps.json'}: {len(log)} steps, CellModeller's time {sum(r['t_sim'] for r in log):.1f} s",
          flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
