"""How many linearizations, and how many interior-point iterations, a step's settings cost.

Usage (from the repository root)::

    python benchmarks/linearization_counts.py RUN/snapshots/step_000300.npz --steps 5 \\
        --variant "before:position_early_tolerance=none" --variant "adopted:" --out counts.md

From a saved state, each variant runs ``--steps`` steps of ``qpcontact simulate`` (2D or 3D as the
state is, its defaults changed by the variant's ``name=value`` pairs, the names of
``Settings.updated``: ``position_trust_rounds``, ``position_early_tolerance``, ...) and counts, for
every solve of the position step, the overlap beyond its target before it, the tolerance it was
solved to and its interior-point iterations. Counts do not depend on the machine's load, so
variants may run beside other work; the table says which states and commits they come from.
Printed and written as Markdown (``--out``).
"""

from __future__ import annotations

import argparse
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import qpcontact.timestep.position as position
from qpcontact.io.snapshots import load_snapshot
from qpcontact.simulation import Settings, run_colony


@dataclass
class Counts:
    """What the solves of one variant's steps were."""

    steps: int = 0
    excess: list[float] = field(default_factory=list)  # before each solve [diameters]
    tolerance: list[float] = field(default_factory=list)  # each solve's
    iterations: list[int] = field(default_factory=list)  # each solve's interior-point iterations


def value(text: str) -> object:
    """A setting's value from the command line: none, a number or a word."""
    if text.lower() == "none":
        return None
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def count(state: Path, steps: int, changes: dict[str, object]) -> Counts:
    """Run ``steps`` steps from ``state`` with ``changes`` and count each solve."""
    snapshot = load_snapshot(state)
    dimensions = 2 if snapshot.colony.cells.is_monolayer() else 3
    settings = Settings().updated({"dimensions": dimensions, "cells": 10**9, "max_steps": snapshot.step + steps,
                                   **changes}, "linearization_counts")
    counts = Counts()
    tolerance_of, solve = position._tolerance, position.solve

    def recorded_tolerance(excess, step_settings):
        counts.excess.append(excess)
        counts.tolerance.append(tolerance_of(excess, step_settings))
        return counts.tolerance[-1]

    def recorded_solve(*args, **kwargs):
        out = solve(*args, **kwargs)
        counts.iterations.append(out.iterations or 0)
        return out

    position._tolerance, position.solve = recorded_tolerance, recorded_solve
    try:
        run = run_colony(settings, start=snapshot, progress=False)
    finally:
        position._tolerance, position.solve = tolerance_of, solve
    counts.steps = run.steps - run.first_step
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("states", nargs="+", type=Path, help="saved snapshots to start from")
    parser.add_argument("--steps", type=int, default=5, help="steps per state and variant (default: 5)")
    parser.add_argument("--variant", action="append", default=[],
                        help="NAME:setting=value,setting=value (repeatable; 'NAME:' for the defaults)")
    parser.add_argument("--out", type=Path, default=Path("linearization-counts.md"), help="the table's file")
    args = parser.parse_args()
    variants = {}
    for text in args.variant or ["defaults:"]:
        name, _, pairs = text.partition(":")
        variants[name] = {key: value(v) for key, v in (pair.split("=", 1) for pair in pairs.split(",") if pair)}
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    lines = [f"Linearization counts, commit {commit or 'unknown'}, {args.steps} steps from each state.", "",
             "| state | variant | steps | solves | of them loose | interior-point iterations | per solve |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for state in args.states:
        for name, changes in variants.items():
            c = count(state, args.steps, changes)
            loose = sum(t > min(c.tolerance, default=0.0) for t in c.tolerance)
            per = sum(c.iterations) / max(len(c.iterations), 1)
            lines.append(f"| {state.name} | {name} | {c.steps} | {len(c.iterations)} | {loose} | "
                         f"{sum(c.iterations)} | {per:.1f} |")
            print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    args.out.write_text(text)


if __name__ == "__main__":
    main()
