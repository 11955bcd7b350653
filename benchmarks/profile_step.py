"""Where one position step of a grown colony goes, phase by phase.

Usage (from the repository root; the states are those ``qpcontact bench-grown`` caches)::

    python benchmarks/profile_step.py ~/.cache/qpcontact-grown/2d-10000.npz \\
        ~/.cache/qpcontact-grown/2d-50000.npz ~/.cache/qpcontact-grown/3d-5000.npz \\
        --steps 3 --out profile-step.md

Each state runs in a child process of its own. The child takes one step from the state with
``qpcontact simulate``'s settings (2D or 3D as the state is; the 3D sink drive as the run has it)
to set up what a run carries from step to step (the cells' motion, the warm start), then times
``--steps`` further steps, each from the last one's colony, as a run takes them. The phases of a
step:

- ``factorization``: numeric Cholesky factorizations (CHOLMOD's ``numeric`` or PARDISO's phase 22);
- ``solves``: triangular solves with them;
- ``set-up``: the pattern, ordering and symbolic analysis of a new matrix (once per contact set);
- ``refill``: the matrix values for each iteration's weights;
- ``vector work``: the rest of the solve phase (residuals, step lengths, the Newton directions'
  elimination, the acceptance checks of the answer);
- ``detection``: finding and evaluating contacts (the step's own ``times["detect"]``);
- ``assembly``: the linearized systems (``times["assemble"]``);
- ``other``: the rest of the step (moving cells, division, growth).

The factorization library's functions are wrapped in the child (not the package's own counters),
so the same script measures older versions of the package too ("before" columns: run it from a
checkout of the older commit). Writes a Markdown table (``--out``) with the date, the machine and
its load, and the package version (git commit) measured.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

from numpy import median

from qpcontact.errors import InvalidArgumentError
from qpcontact.simulation import Settings
from qpcontact.studies.grown import machine

CHILD = r"""
import json, sys, time
import numpy as np
import qpcontact.solvers.cholesky as cholesky
try:
    from qpcontact.io import load_colony
    from qpcontact.simulation.settings import Settings
    from qpcontact.simulation.steps import step_function
except ImportError:  # a version before the wings of issue 28
    from qpcontact.colony import load_colony
    from qpcontact.simulation.settings import Settings
    from qpcontact.simulation.simulate import step_function

spent = dict(setup=0.0, refill=0.0, factor=0.0, solve=0.0)
counts = dict(setup=0, refill=0, factor=0, solve=0)

def timed(part, function):
    def wrapper(*args, **kwargs):
        t = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            spent[part] += time.perf_counter() - t
            counts[part] += 1
    return wrapper

cholmod = cholesky.cholmod
cholmod.numeric = timed("factor", cholmod.numeric)
cholmod.solve = timed("solve", cholmod.solve)
cholmod.symbolic = timed("setup", cholmod.symbolic)
cholesky.GramMatrix.__init__ = timed("setup", cholesky.GramMatrix.__init__)
cholesky.GramMatrix.values = timed("refill", cholesky.GramMatrix.values)
if hasattr(cholesky.GramMatrix, "_call"):
    call = cholesky.GramMatrix._call
    def pardiso_call(self, phase, upper, v):
        part = {11: "setup", 22: "factor", 33: "solve"}[phase]
        return timed(part, call)(self, phase, upper, v)
    cholesky.GramMatrix._call = pardiso_call

colony, _ = load_colony(sys.argv[1])
steps = int(sys.argv[2])
three_d = bool(np.any(colony.cells.centers[:, 2] != 0))
settings = Settings().updated({"dimensions": 3 if three_d else 2, **json.loads(sys.argv[3])}, "profile-step")
extra = {}
take_step = step_function(settings, extra)

def drive_of(colony):
    if not (three_d and settings.model.sink_speed):
        return None
    drive = np.zeros((colony.cells.n, 7))
    drive[:, 2] = -settings.model.sink_speed * colony.cells.masses
    return drive

colony = take_step(colony, settings.time_step_of(colony), drive=drive_of(colony)).colony
rows = []
for _ in range(steps):
    for part in spent:
        spent[part], counts[part] = 0.0, 0
    dt = settings.time_step_of(colony)
    t = time.perf_counter()
    outcome = take_step(colony, dt, drive=drive_of(colony))
    total = time.perf_counter() - t
    result = outcome.result
    rows.append(dict(cells=colony.cells.n, total=total, detect=result.times["detect"],
                     assemble=result.times["assemble"], solver=result.times["solve"], **spent,
                     factorizations=counts["factor"], solve_calls=counts["solve"],
                     linearizations=result.iterations, solver_iterations=result.solver_iterations,
                     contacts=len(result.contacts), max_overlap=result.max_overlap,
                     backend=cholesky.BACKEND))
    colony = outcome.colony
print(json.dumps(dict(three_d=three_d, rows=rows)))
"""

PHASES = (("factorization", "factor"), ("solves", "solve"), ("set-up", "setup"), ("refill", "refill"),
          ("vector work", None), ("detection", "detect"), ("assembly", "assemble"), ("other", None))


def profile(state: Path, steps: int, changes: dict | None = None) -> dict:
    """One child process: the rows of its timed steps, with ``changes`` to the run's settings."""
    done = subprocess.run([sys.executable, "-c", CHILD, str(state), str(steps), json.dumps(changes or {})],
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"profile of {state} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def phases(row: dict) -> dict[str, float]:
    """Seconds per phase of one step (the solver's own parts out of its ``solve`` time)."""
    inside = row["factor"] + row["solve"] + row["setup"] + row["refill"]
    out = {name: row[key] for name, key in PHASES if key is not None}
    out["vector work"] = max(row["solver"] - inside, 0.0)
    out["other"] = max(row["total"] - row["detect"] - row["assemble"] - row["solver"], 0.0)
    return out


def version() -> str:
    """The commit of the qpcontact the children import (the checkout in the working folder, or
    the installed one), not this script's."""
    where = subprocess.run([sys.executable, "-c", "import os, qpcontact; print(os.path.dirname(qpcontact.__file__))"],
                           capture_output=True, text=True, check=False).stdout.strip()
    done = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True, text=True, check=False,
                          cwd=where or None)
    return done.stdout.strip() or "unknown"


def table(results: dict[str, dict]) -> str:
    """The Markdown table: the median step of each state and its phases (seconds and share)."""
    lines = ["| state | cells | step [s] | " + " | ".join(name for name, _ in PHASES)
             + " | linearizations | IPM iterations | factorizations | solves | largest overlap |",
             "|---|---:|---:|" + "---:|" * len(PHASES) + "---:|---:|---:|---:|---:|"]
    for name, result in results.items():
        rows = result["rows"]
        split = [phases(row) for row in rows]
        total = median([row["total"] for row in rows])
        cells = [f"{median([s[p] for s in split]):.3f} ({100 * median([s[p] / r['total'] for s, r in zip(split, rows, strict=True)]):.0f} %)"
                 for p, _ in PHASES]
        lines.append(f"| {name} | {rows[0]['cells']:,} | {total:.2f} | " + " | ".join(cells)
                     + f" | {median([r['linearizations'] for r in rows]):g}"
                     + f" | {median([r['solver_iterations'] for r in rows]):g}"
                     + f" | {median([r['factorizations'] for r in rows]):g} | {median([r['solve_calls'] for r in rows]):g}"
                     + f" | {max(r['max_overlap'] for r in rows):.4f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("states", nargs="+", type=Path, help="saved colonies (qpcontact bench-grown's cache)")
    parser.add_argument("--steps", type=int, default=3, help="steps timed per state, median kept (default: 3)")
    parser.add_argument("--out", type=Path, default=Path("profile-step.md"),
                        help="the Markdown table written (default: ./profile-step.md)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=JSON",
                        help="a change to the run's settings, e.g. position_early_tolerance=null (repeatable)")
    args = parser.parse_args(argv)
    try:
        changes = {name: json.loads(value) for name, _, value in (item.partition("=") for item in args.set)}
    except json.JSONDecodeError as error:
        parser.error(f"--set: expected NAME=JSON: {error}")
    try:  # checked here, not only in the child: a bad name or value exits 2 with the setting's own message
        Settings().updated(changes, "--set")
    except InvalidArgumentError as error:
        parser.error(str(error))
    if args.steps < 1:
        parser.error("--steps: expected an integer >= 1")
    for state in args.states:
        if not state.is_file():
            parser.error(f"no such state: {state}")
    started, measured_on = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"), machine()
    results = {}
    for state in args.states:
        t = time.perf_counter()
        result = profile(state, args.steps, changes)
        results[state.name] = result
        print(f"{state.name}: {time.perf_counter() - t:.0f} s", file=sys.stderr)
    text = (f"# One position step, phase by phase\n\n{started}, qpcontact {version()}, "
            f"{measured_on} at the start, settings changed: {changes or 'none'}, "
            f"factorization {results[next(iter(results))]['rows'][0]['backend']}; "
            f"median of {args.steps} steps per state, each from the last (seconds, share of the step).\n\n"
            + table(results) + "\n")
    print(text)
    args.out.write_text(text)


if __name__ == "__main__":
    main()
