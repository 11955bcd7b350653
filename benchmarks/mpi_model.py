"""The paper model of a distributed run at 10⁶ cells, built from the counts that
``benchmarks/mpi_scaling.py`` measured per process (its ``mpi-scaling.json``), not from assumed
speed-ups and not from CPU seconds that hold waiting.

    python benchmarks/mpi_model.py MEASURED/mpi-scaling.json --state 2d-20000 [--out model.md]

Why counts: on a machine with fewer cores than processes, a process waiting in a collective polls,
and its CPU seconds hold that waiting; fitted as ``r + d/P``, the waiting looked like work every
process repeats (the model of 2026-12-05 put 622 s a step at 10⁶ cells there). So each phase of a
step is modelled from what it does, with the rates of one MPI process (which never waits):

- *own work* (the step's CPU seconds less the factorizations, the triangular solves, the products
  with ``B̃``, the normal matrix and the collectives: work no process waits in), largest per process, fitted as
  ``r + d/P`` over the runs: ``r`` what every process repeats for the whole colony, ``d`` what is
  divided; both scaled linearly with the cells;
- *MUMPS's analysis* (its ordering on one process, ICNTL(28) = 1, PETSc's default): the first
  factorization of each problem less a numeric one, on one MPI process; not divided, scaled linearly;
- *numeric factorizations*: MUMPS's flops (RINFO(3)) summed over the processes, scaled as a nested
  dissection's (``N^1.5`` in 2D, ``N^2`` in 3D, ``--flops-exponent``), times the busiest process's
  share at the largest P measured (its imbalance), over P, at one MPI process's rate of flops;
- *triangular solves*: the factor entries the solves read, scaled as the factor (``N log N`` in 2D,
  ``N^(4/3)`` in 3D), likewise shared, at one MPI process's rate; and each solve's ``2 log₂P`` hops
  of the link's latency (down and up the tree of fronts);
- *products with B̃* and *the normal matrix* (PETSc's product of the row-scaled ``B̃`` with itself,
  each process forming its own rows): one MPI process's CPU seconds, scaled linearly, over P; a
  product one hop of latency, a normal matrix two (the rows of ``B̃`` it needs from its neighbours);
- *collectives*: their number a step, each ``2 log₂P`` hops (a reduction, then a broadcast), and
  the bytes every process receives (the gathers to all: the sum of what the processes send at the
  largest P, scaled linearly) over the link's bandwidth.

The counts a step (interior-point iterations, solves, products, collectives) are the measured
step's, scaled by ``--linearizations`` (a step's linearizations at the sizes modelled, the mean of
the run that grew the state past 10⁴ cells, say) over the measured step's: a step of N cells is taken
to need as many as the run's steps did. The time to grow
from one cell sums the step's time over the steps, the colony growing by e in
``--steps-per-efold`` steps (measured on the run that grew the state), from 100 cells up.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path

import numpy as np


def fit(processes: np.ndarray, seconds: np.ndarray) -> tuple[float, float]:
    """``(r, d)`` of ``seconds ≈ r + d/P``, least squares, both kept ≥ 0."""
    design = np.column_stack([np.ones_like(processes), 1.0 / processes])
    (r, d), *_ = np.linalg.lstsq(design, seconds, rcond=None)
    if r < 0:
        r, d = 0.0, float(np.mean(seconds * processes))
    return float(r), max(float(d), 0.0)


@dataclass(frozen=True)
class Counts:
    """What one step of the measured state (``cells``) did, as the model uses it (seconds are CPU
    seconds of one MPI process unless said)."""

    cells: float
    repeated: float  #: own work every process repeats [s]
    divided: float  #: own work divided among the processes [s]
    analysis: float  #: MUMPS's analyses [s]
    numeric: float  #: numeric factorizations [s]
    solve: float  #: triangular solves [s]
    product: float  #: products with B̃ [s]
    normal: float  #: refills of the normal matrix [s]
    flops_share: float  #: the busiest process's flops over the mean, at the largest P measured
    entries_share: float  #: likewise, the factor entries
    solves: float  #: triangular solves a step
    products: float  #: products a step
    factorizations: float  #: factorizations (refills of the normal matrix) a step
    collectives: float  #: collectives a step (qpcontact's and the solver's)
    received: float  #: bytes every process receives a step (what all processes send, at the largest P)
    linearizations: float  #: of the measured step


def counts_of(runs: dict[int, dict[str, list[float]]]) -> Counts:
    """:class:`Counts` from the runs of one state on P = 1, 2, ... MPI processes (P = 1 needed)."""
    if 1 not in runs or len(runs) < 2:
        raise SystemExit("the model needs the state's runs on 1 MPI process and at least one more P")
    one, widest = runs[1], runs[max(runs)]
    p = np.array(sorted(runs), dtype=float)
    repeated, divided = fit(p, np.array([max(runs[int(k)]["own"]) for k in p]))
    numeric_each = (one["factor"][0] - one["first_factor_cpu"][0]) / max(one["factorizations"][0] - one["problems"][0], 1)
    analysis = max(one["first_factor_cpu"][0] - one["problems"][0] * numeric_each, 0.0)
    share = lambda key: max(widest[key]) / float(np.mean(widest[key]))  # noqa: E731
    return Counts(cells=float(one["cells"][0]), repeated=repeated, divided=divided, analysis=analysis,
                  numeric=one["factor"][0] - analysis, solve=one["solve_cpu"][0], product=one["product_cpu"][0],
                  normal=one["normal_cpu"][0], factorizations=max(widest["factorizations"]),
                  flops_share=share("flops"), entries_share=share("entry_solves"), solves=max(widest["solves"]),
                  products=max(widest["products"]), collectives=max(widest["collectives"]),
                  received=float(sum(widest["sent"])), linearizations=float(np.median(widest["linearizations"])))


def growths(dimensions: int, flops_exponent: float | None, base: float
            ) -> tuple[Callable[[float], float], Callable[[float], float]]:
    """How the factorization's flops and its entries grow from ``base`` cells to N (as ratios, by N):
    nested dissection's, ``N^1.5`` and ``N log N`` in 2D, ``N^2`` and ``N^(4/3)`` in 3D."""
    alpha = flops_exponent if flops_exponent is not None else (2.0 if dimensions == 3 else 1.5)
    if dimensions == 3:
        return (lambda n: (n / base) ** alpha), (lambda n: (n / base) ** (4.0 / 3.0))
    return (lambda n: (n / base) ** alpha), (lambda n: n * math.log(n) / (base * math.log(base)))


def step_parts(c: Counts, cells: float, processes: float, latency: float, bandwidth: float,
               flops: Callable[[float], float], entries: Callable[[float], float], divide: Collection[str] = (),
               analysis_flops: float = 1.0) -> dict[str, float]:
    """The seconds of one step of ``cells`` on ``processes``, phase by phase; ``divide``: what
    is taken as divided among the processes beyond what is now (``"repeated"``: the own work
    every process repeats; ``"analysis"``: MUMPS's analysis, whose parallel orderings make
    ``analysis_flops`` times the numeric factorization's flops)."""
    x = cells / c.cells
    hops = math.log2(processes) if processes > 1 else 0.0
    analysis = "analysis" in divide
    return {"own, repeated": c.repeated * x / (processes if "repeated" in divide else 1.0),
            "own, divided": c.divided * x / processes,
            "analysis (one process)": c.analysis * x / (processes if analysis else 1.0),
            "numeric factorization": c.numeric * flops(cells) * c.flops_share / processes
            * (analysis_flops if analysis else 1.0),
            "triangular solves": c.solve * entries(cells) * c.entries_share / processes + c.solves * 2 * hops * latency,
            "products": c.product * x / processes + c.products * latency * (processes > 1),
            "normal matrix": c.normal * x / processes + c.factorizations * 2 * latency * (processes > 1),
            "collectives": c.collectives * 2 * hops * latency + (c.received * x / bandwidth if processes > 1 else 0.0)}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("measured", type=Path, help="mpi-scaling.json of benchmarks/mpi_scaling.py")
    parser.add_argument("--state", required=True, help="the state whose runs are modelled, e.g. 2d-20000")
    parser.add_argument("--cells", type=float, default=1e6, help="the colony modelled (default: 10⁶)")
    parser.add_argument("--processes", default="64,256", help="processes of the cluster (default: 64,256)")
    parser.add_argument("--latency", type=float, default=2e-6, help="the link's latency [s] (default: 2 µs)")
    parser.add_argument("--bandwidth", type=float, default=25e9,
                        help="the link's bandwidth per process [bytes/s] (default: 25·10⁹, InfiniBand HDR's 200 Gb/s)")
    parser.add_argument("--steps-per-efold", type=float, default=41.5,
                        help="steps a colony takes to grow by e (default: 41.5, measured on the 2D run to 2·10⁴)")
    parser.add_argument("--flops-exponent", type=float, default=None,
                        help="how the factorization's flops grow with the cells (default: 1.5 for a 2d state, 2 for 3d: "
                             "nested dissection's)")
    parser.add_argument("--linearizations", type=float, default=None,
                        help="linearizations a step at the sizes modelled (default: the measured step's); every count "
                             "of a step scales with them")
    parser.add_argument("--divide", default="",
                        help="also model these divided among the processes, comma-separated: repeated (the own work "
                             "every process repeats), analysis (MUMPS's analysis; its parallel orderings' extra flops: "
                             "--analysis-flops); rows for each alone and for all together (default: none)")
    parser.add_argument("--analysis-flops", type=float, default=1.22,
                        help="the numeric factorization's flops with a parallel analysis, over the sequential one's "
                             "(default: 1.22, PT-Scotch on 4 processes, docs/distributed.md)")
    parser.add_argument("--out", type=Path, default=None, help="also write the table here")
    args = parser.parse_args(argv)
    for name in ("cells", "latency", "bandwidth", "steps_per_efold", "linearizations", "analysis_flops"):
        value = getattr(args, name)
        if value is not None and not (value > 0 and math.isfinite(value)):
            parser.error(f"--{name.replace('_', '-')}: expected a finite number > 0, got {value!r}")
    if args.cells < 100:
        parser.error(f"--cells: expected at least 100 (the growth is summed from 100 cells), got {args.cells:g}")
    try:
        processes = [float(x) for x in args.processes.split(",")]
    except ValueError:
        parser.error(f"--processes: expected numbers separated by commas, got {args.processes!r}")
    if any(p < 1 for p in processes):
        parser.error(f"--processes: expected numbers >= 1, got {args.processes!r}")
    data = json.loads(args.measured.read_text())["per_process"]
    runs = {int(k.split(", ")[1].split()[0]): v for k, v in data.items()
            if k.startswith(f"{args.state}, ") and "ipm-petsc" in k}
    c = counts_of(runs)
    flops, entries = growths(3 if args.state.startswith("3d") else 2, args.flops_exponent, c.cells)
    per_step = (c.linearizations if args.linearizations is None else args.linearizations) / c.linearizations
    g = 1.0 / args.steps_per_efold  # growth of ln N a step
    sizes = args.cells * np.exp(-g * np.arange(int(math.log(args.cells / 100.0) / g) + 1))
    names = list(step_parts(c, args.cells, 2.0, args.latency, args.bandwidth, flops, entries))
    lines = [f"Model of {args.cells:.3g} cells from {args.state} ({c.cells:,.0f} cells; the runs on P = "
             f"{', '.join(str(k) for k in sorted(runs))}): own work {c.repeated:.3f} + {c.divided:.3f}/P s, MUMPS's "
             f"analysis {c.analysis:.3f} s, numeric factorizations {c.numeric:.3f} s (busiest process × "
             f"{c.flops_share:.2f}), triangular solves {c.solve:.3f} s ({c.solves:g}; × {c.entries_share:.2f}), products "
             f"{c.product:.3f} s ({c.products:g}), normal matrix {c.normal:.3f} s, {c.collectives:g} collectives and {c.received / 1e6:.1f} MB received "
             f"a step of {c.linearizations:g} linearizations, scaled to {c.linearizations * per_step:g}; link {args.latency * 1e6:g} µs, {args.bandwidth / 1e9:g} GB/s; {args.steps_per_efold:g} steps to "
             "grow by e.\n",
             "| P | " + " [s] | ".join(names) + " [s] | one step [s] | one cell to N [h] |",
             "|---:|" + "---:|" * (len(names) + 2)]
    asked = [w for w in args.divide.split(",") if w]
    if any(w not in ("repeated", "analysis") for w in asked):
        parser.error(f"--divide: expected repeated and/or analysis, got {args.divide!r}")
    variants = [()] + [(w,) for w in asked] + ([tuple(asked)] if len(asked) > 1 else [])
    for divide in variants:
        for p in processes:
            at = functools.partial(step_parts, c, processes=p, latency=args.latency, bandwidth=args.bandwidth,
                                   flops=flops, entries=entries, divide=divide, analysis_flops=args.analysis_flops)
            parts = {k: v * per_step for k, v in at(args.cells).items()}
            grow = per_step * sum(sum(at(n).values()) for n in sizes)
            label = f"{p:g}" + (f", {' and '.join(divide)} divided" if divide else "")
            lines.append(f"| {label} | " + " | ".join(f"{v:.2f}" for v in parts.values())
                         + f" | {sum(parts.values()):.1f} | {grow / 3600:.2f} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
