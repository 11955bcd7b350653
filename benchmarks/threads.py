"""Does the position step gain from both cores? One and two threads, each factorization, interleaved.

Usage (from the repository root; the states are those ``qpcontact bench-grown`` caches)::

    python benchmarks/threads.py ~/.cache/qpcontact-grown/2d-10000.npz \\
        ~/.cache/qpcontact-grown/3d-5000.npz --repeats 3

The multithreaded part of a step is the factorization: CHOLMOD's supernodal Cholesky with the
BLAS it was built with, or MKL's PARDISO (``qpcontact[pardiso]``), threaded itself. Thread counts
are fixed when the libraries load, so each measurement is a child process with
``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS`` set. For each state and each
installed factorization (``qpcontact.solvers.cholesky.BACKEND``, set in the child), one position
step from the state (``qpcontact simulate``'s defaults) is timed with 1 and with 2 threads,
alternately, ``--repeats`` times; the table gives the median wall seconds of the step and of its
factorizations.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

CHILD = r"""
import json, sys, time
import numpy as np
import qpcontact.solvers.cholesky as cholesky
from qpcontact.io import load_colony
from qpcontact.simulation.settings import Settings
from qpcontact.simulation.steps import step_function
factor_seconds = []
real = cholesky.GramMatrix.factor
def timed(self, *args):
    t = time.perf_counter(); out = real(self, *args); factor_seconds.append(time.perf_counter() - t); return out
cholesky.GramMatrix.factor = timed
cholesky.BACKEND = sys.argv[2]
colony, _ = load_colony(sys.argv[1])
three_d = bool(np.any(colony.cells.centers[:, 2] != 0))
settings = Settings().updated({"dimensions": 3 if three_d else 2}, "threads")
drive = None
if three_d and settings.model.sink_speed:
    drive = np.zeros((colony.cells.n, 7)); drive[:, 2] = -settings.model.sink_speed * colony.cells.masses
t = time.perf_counter()
step_function(settings, {})(colony, settings.time_step_of(colony), drive=drive)
print(json.dumps(dict(step=time.perf_counter() - t, factor=sum(factor_seconds), count=len(factor_seconds))))
"""


def measure(state: Path, backend: str, threads: int) -> dict[str, float]:
    environment = dict(os.environ, OPENBLAS_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads),
                       MKL_NUM_THREADS=str(threads))
    done = subprocess.run([sys.executable, "-c", CHILD, str(state), backend], capture_output=True, text=True,
                          env=environment, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("states", nargs="+", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, help="also write the table to this file")
    args = parser.parse_args()
    from qpcontact.solvers import cholesky

    backends = ["cholmod"] + (["pardiso"] if cholesky.pypardiso is not None else [])
    lines = [f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load average "
             f"{os.getloadavg()[0]:.2f}; medians of {args.repeats} steps each, interleaved.", "",
             "| state | factorization | threads | step [s] | factorizations [s] | factorizations |",
             "|---|---|---|---|---|---|"]
    print("\n".join(lines), flush=True)
    for state in args.states:
        runs: dict[tuple[str, int], list[dict[str, float]]] = {(b, t): [] for b in backends for t in (1, 2)}
        for _ in range(args.repeats):
            for key in runs:
                runs[key].append(measure(state, *key))
        for (backend, threads), rows in runs.items():
            lines.append(f"| {state.name} | {backend} | {threads} | {np.median([r['step'] for r in rows]):.2f} | "
                         f"{np.median([r['factor'] for r in rows]):.2f} | {int(rows[0]['count'])} |")
            print(lines[-1], flush=True)
    if args.out is not None:
        args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
