"""Time per step and overlap for a 10,000-cell 2D colony, OSQP against Clarabel.

Starts from a grown colony snapshot (``qpcontact simulate --cells 10000``), and from that same
state takes --steps growth steps with each solver (``qpcontact simulate`` settings otherwise).
Records per step: cells, contacts in the system, unknowns, wall time of the step, contact-solve
time (setup + solve), and the largest and mean overlap (fraction of the diameter) of the state
the step starts from; and the overlaps of the final state. Medians over the steps.

    flock /tmp/qpcontact-bench.lock python docs/data/colony_10k.py SNAPSHOT.npz
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

from qpcontact.contacts import find_contacts
from qpcontact.growth import divide, expansion_time_step, grow
from qpcontact.simulate import Settings
from qpcontact.snapshots import load_colony
from qpcontact.step import overlap_fractions

HERE = Path(__file__).resolve().parent
CONFIGS = [("osqp", 1e-3), ("osqp", 1e-4), ("clarabel", 1e-6)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("snapshot", type=Path)
    parser.add_argument("--steps", type=int, default=5)
    args = parser.parse_args()
    start, _ = load_colony(args.snapshot)
    s = Settings()
    lines = [
        f"Measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} on {platform.machine()} (2 cores shared with "
        f"other jobs); {args.steps} steps from the same {start.cells.n}-cell 2D colony grown by `qpcontact simulate` "
        f"(t = {start.time:.3f} doubling times); medians over the steps.",
        "",
        "| solver | tolerance | contacts in system | unknowns | dt | step wall [s] | contact solve [s] | largest overlap (per step, max) | mean overlap | largest overlap after the steps | note |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for solver, tolerance in CONFIGS:
        colony = start
        rng = np.random.default_rng(0)
        rows, error = [], ""
        for _ in range(args.steps):
            dt = expansion_time_step(colony, max_dt=s.max_dt, cfl=s.cfl)
            t0 = time.perf_counter()
            try:
                colony, out = grow(colony, dt, planar=True, solver=solver, tolerance=tolerance, margin=s.margin,
                                   position_correction=s.position_correction)
            except Exception as exc:  # reported in the table, never applied
                error = f"{type(exc).__name__}: {exc}"[:160]
                break
            wall = time.perf_counter() - t0
            colony = divide(colony, s.division_length, rng, axis_noise=s.axis_noise, rate_noise=s.rate_noise,
                            base_rate=s.rate, planar=True)
            r = out.result
            rows.append((len(r.contacts), r.n_unknowns, dt, wall, r.times["setup"] + r.times["solve"],
                         out.max_overlap, out.mean_overlap))
            print(solver, tolerance, rows[-1], flush=True)
        final = overlap_fractions(colony.cells, find_contacts(colony.cells, 0.0, planar=True))
        if rows:
            a = np.array(rows)
            med = np.median(a, axis=0)
            lines.append(f"| {solver} | {tolerance:g} | {med[0]:.0f} | {med[1]:.0f} | {med[2]:.4f} | {med[3]:.2f} | "
                         f"{med[4]:.2f} | {a[:, 5].max():.4f} | {med[6]:.5f} | {final.max(initial=0.0):.4f} | {error} |")
        else:
            lines.append(f"| {solver} | {tolerance:g} | | | | | | | | | {error} |")
    (HERE / "colony_10k.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
