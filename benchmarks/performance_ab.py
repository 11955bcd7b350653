"""Before/after measurements of the speed-ups in docs/performance.md (issue 6).

Usage (under the benchmark lock, from the repository root):

    flock /tmp/qpcontact-bench.lock python benchmarks/performance_ab.py OLD_CHECKOUT [--sizes 10000,100000]

``OLD_CHECKOUT`` is a directory holding the ``qpcontact`` package as it was before the change
(e.g. ``git worktree add /tmp/old 28997b8``... or any copy). For each colony snapshot the script
times, interleaved and with repeats (median), detection and assembly with the old and the new
package (through the top-level names ``Cells``, ``find_contacts``, ``colliding`` and
``build_system``, which both layouts have), then the QP solve of the new package with and
without the split into independent blocks, and checks that old and new give the same contacts
and matrix. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from qpcontact.cli import comma_list, positive_int


def load(root: str | None) -> ModuleType:
    """Import a fresh ``qpcontact`` from ``root`` (None: the installed one)."""
    for name in [m for m in sys.modules if m == "qpcontact" or m.startswith("qpcontact.")]:
        del sys.modules[name]
    if root:
        sys.path.insert(0, root)
    try:
        return importlib.import_module("qpcontact")
    finally:
        if root:
            sys.path.remove(root)


def median_time(fn: Callable[[], Any], repeats: int) -> tuple[Any, float]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, float(np.median(times))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("old", help="a folder holding the qpcontact package as it was before the change")
    p.add_argument("--sizes", type=comma_list(positive_int), default=[10000, 100000], help="cell counts (default: 10000,100000)")
    p.add_argument("--dimensions", type=comma_list(int, choices=("2", "3")), default=[2, 3], help="2, 3 or 2,3 (default)")
    p.add_argument("--repeats", type=positive_int, default=3, help="timed repeats, median kept (default: 3)")
    p.add_argument("--solvers", type=comma_list(), default=["osqp/primal", "osqp/contact"],
                   help="comma-separated solver/form (default: osqp/primal,osqp/contact)")
    p.add_argument("--cache-dir", type=Path, default=Path.home() / ".cache" / "qpcontact-bench",
                   help="where colony snapshots are cached ('none': not cached) (default: %(default)s)")
    args = p.parse_args(argv)
    old, new = load(args.old), load(None)
    from qpcontact.resolve import metrics, reference_solution  # the new package from here on
    from qpcontact.solvers import Problem, solve
    from qpcontact.studies.bench import load_scene

    cache = None if str(args.cache_dir) == "none" else args.cache_dir
    print("| scene | cells | phase | before s | after s | speed-up | same answer |")
    print("|---|---|---|---|---|---|---|")
    for dimensions in args.dimensions:
        for n_cells in args.sizes:
            cells_new = load_scene(dimensions, n_cells, 0, cache)
            fields = {f.name: getattr(cells_new, f.name) for f in dataclasses.fields(cells_new)}
            cells_old = old.Cells(**fields)
            rows = []
            planar = dimensions == 2
            for package, cells in ((old, cells_old), (new, cells_new)):
                (active, b), t_detect = median_time(
                    lambda package=package, cells=cells, planar=planar: package.colliding(
                        package.find_contacts(cells, planar=planar)),
                    args.repeats)
                system, t_assemble = median_time(
                    lambda package=package, cells=cells, active=active, b=b: package.build_system(cells, active, b),
                    args.repeats)
                rows.append((t_detect, t_assemble, active, system))
            (d0, a0, c0, s0), (d1, a1, c1, s1) = rows
            same_contacts = all(np.allclose(getattr(c0, f.name), getattr(c1, f.name), rtol=1e-9, atol=1e-12)
                                for f in dataclasses.fields(c1))
            same_matrix = s0.shape == s1.shape and abs(s0.matrix - s1.matrix).max() <= 1e-12
            print(f"| {dimensions}D | {n_cells} | detect | {d0:.3g} | {d1:.3g} | {d0 / d1:.2f}× | {same_contacts} |")
            print(f"| {dimensions}D | {n_cells} | assemble | {a0:.3g} | {a1:.3g} | {a0 / a1:.2f}× | {same_matrix} |")
            timed = {}
            for spec in args.solvers:
                solver, form = spec.split("/")
                for split in (False, True):
                    timed[spec, split] = median_time(
                        lambda s1=s1, solver=solver, form=form, split=split: solve(
                            Problem.of(s1), solver, "complementarity", form, tolerance=1e-6, split=split),
                        max(1, args.repeats - 1))
            guess = next(out.lam for out, _ in timed.values() if out.lam is not None)
            reference = reference_solution(s1, "complementarity", guess=guess)
            for spec in args.solvers:
                (whole, t0), (split, t1) = timed[spec, False], timed[spec, True]
                e0, e1 = (metrics.distance(o.y, reference) if o.y is not None else float("nan") for o in (whole, split))
                print(f"| {dimensions}D | {n_cells} | {spec} whole → {split.extras.get('blocks')} blocks | {t0:.3g} | "
                      f"{t1:.3g} | {t0 / t1:.2f}× | error {e0:.1e} → {e1:.1e} |")
            sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
