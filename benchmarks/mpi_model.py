"""The paper model of a distributed run at 10⁶ cells, from per-process counts measured by
``benchmarks/mpi_scaling.py`` (its ``mpi-scaling.json``), not from assumed speed-ups.

    python benchmarks/mpi_model.py MEASURED/mpi-scaling.json --state 2d-16000 [--out model.md]

From the runs of one state on P = 1, 2, 4, 8 MPI processes (``ipm-petsc``), per step:

- the CPU seconds other than the factorization, largest per process, fitted as ``r + d/P``
  (least squares): ``r`` what every process repeats (it grows with the colony on every process),
  ``d`` what is divided; both scaled linearly with the cells;
- the factorization's CPU seconds, largest per process, fitted as ``s + q/P``: ``s`` what does not
  divide (MUMPS's analysis, its ordering on one process; the top fronts' imbalance), scaled
  linearly, ``q`` what divides, scaled as MUMPS's flops of a nested dissection: ``N^1.5`` in 2D,
  ``N^2`` in 3D (``--flops-exponent``; the default from the state's name);
- the bytes each process sends a step (measured at the largest P), summed over the processes:
  every process receives about that much (the collectives are gathers to all), scaled linearly,
  over the link's bandwidth;
- the collectives a step: ``(IPM iterations × 30 + linearizations × 20)``, each ``log₂P`` hops of
  the link's latency.

The time to grow from one cell is the sum of the step's time over the steps, the colony growing by
the same factor each step (``--steps-per-efold``, measured on the run that grew the state).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np


def fit(processes: np.ndarray, seconds: np.ndarray) -> tuple[float, float]:
    """``(r, d)`` of ``seconds ≈ r + d/P``, least squares, both kept ≥ 0."""
    design = np.column_stack([np.ones_like(processes), 1.0 / processes])
    (r, d), *_ = np.linalg.lstsq(design, seconds, rcond=None)
    if r < 0:
        r, d = 0.0, float(np.mean(seconds * processes))
    return float(r), max(float(d), 0.0)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("measured", type=Path, help="mpi-scaling.json of benchmarks/mpi_scaling.py")
    parser.add_argument("--state", required=True, help="the state whose runs are modelled, e.g. 2d-16000")
    parser.add_argument("--cells", type=float, default=1e6, help="the colony modelled (default: 10⁶)")
    parser.add_argument("--processes", default="64,256", help="processes of the cluster (default: 64,256)")
    parser.add_argument("--latency", type=float, default=2e-6, help="the link's latency [s] (default: 2 µs)")
    parser.add_argument("--bandwidth", type=float, default=25e9,
                        help="the link's bandwidth per process [bytes/s] (default: 25·10⁹, InfiniBand HDR's 200 Gb/s)")
    parser.add_argument("--steps-per-efold", type=float, default=38.5,
                        help="steps a colony takes to grow by e (default: 38.5, measured on the 2D run to 1.6·10⁴)")
    parser.add_argument("--flops-exponent", type=float, default=None,
                        help="how the factorization's flops grow with the cells (default: 1.5 for a 2d state, 2 for 3d: "
                             "nested dissection's)")
    parser.add_argument("--out", type=Path, default=None, help="also write the table here")
    args = parser.parse_args(argv)
    data = json.loads(args.measured.read_text())["per_process"]
    runs = {int(k.split(", ")[1].split()[0]): v for k, v in data.items()
            if k.startswith(f"{args.state}, ") and "ipm-petsc" in k}
    if len(runs) < 2:
        raise SystemExit(f"{args.measured}: fewer than two ipm-petsc runs of {args.state}")
    p = np.array(sorted(runs), dtype=float)
    other = np.array([max(runs[int(k)]["other"]) for k in p])
    factor = np.array([max(runs[int(k)]["factor"]) for k in p])
    r, d = fit(p, other)
    s, q = fit(p, factor)
    widest = runs[int(p[-1])]
    sent_total = float(sum(widest["sent"]))  # bytes a step, all processes
    iterations = float(np.median(widest["solver_iterations"]))
    linearizations = float(np.median(widest["linearizations"]))
    n0 = float(widest["cells"][0]) if "cells" in widest else float(args.state.split("-")[-1])
    scale = args.cells / n0
    exponent = args.flops_exponent if args.flops_exponent is not None else (2.0 if args.state.startswith("3d") else 1.5)
    lines = [f"Model of {args.cells:.3g} cells from {args.state} ({n0:,.0f} cells) on P = {', '.join(f'{x:g}' for x in p)}: "
             f"other than factorization {r:.3f} + {d:.3f}/P s, factorization {s:.3f} + {q:.3f}/P s (largest per "
             f"process); {sent_total / 1e6:.1f} MB sent a step (all processes, P = {p[-1]:g}); {iterations:g} IPM "
             f"iterations, {linearizations:g} linearizations a step; link {args.latency * 1e6:g} µs, "
             f"{args.bandwidth / 1e9:g} GB/s; factorization flops ∝ N^{exponent:g}; {args.steps_per_efold:g} steps to "
             f"grow by e.\n",
             "| P | repeated [s] | divided [s] | factorization, not divided [s] | factorization, divided [s] | "
             "traffic [s] | latency [s] | one step [s] | one cell to N [h] |", "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    g = 1.0 / args.steps_per_efold  # growth of ln N a step
    for processes in (float(x) for x in args.processes.split(",")):
        parts = [r * scale, d * scale / processes, s * scale, q * scale ** exponent / processes,
                 sent_total * scale / args.bandwidth,
                 (iterations * 30 + linearizations * 20) * math.log2(processes) * args.latency]
        step = sum(parts)
        # Σ over the steps of N_k^α, N_k growing by e^g a step to N: N^α / (1 − e^{−αg}).
        linear = (parts[0] + parts[1] + parts[2] + parts[4]) / (1 - math.exp(-g))
        grow = linear + parts[3] / (1 - math.exp(-exponent * g)) + parts[5] * math.log(args.cells) / g
        lines.append(f"| {processes:g} | " + " | ".join(f"{x:.2f}" for x in parts) + f" | {step:.1f} | {grow / 3600:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
