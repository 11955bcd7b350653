"""``qpcontact bench``: time each phase of a contact step at colony scale.

For each colony snapshot (2D monolayer and 3D biofilm from :mod:`qpcontact.studies.scenes`, 10³–10⁵
cells by default) the benchmark times, with repeats (median, min, max):

- *detect*: :func:`~qpcontact.geometry.find_contacts` + :func:`~qpcontact.geometry.colliding`;
- *assemble*: :func:`~qpcontact.assembly.build_system`;
- *solve*, per solver, every one through :func:`~qpcontact.resolve.solve_system` (setup +
  solve, the acceptance checks included): the plain linear solve (the floor; ``linear/primal``
  is its LSMR route), the QP backends, the built-in matrix-free QP solver ``mprgp``
  (:mod:`qpcontact.solvers.mprgp`) and the field's baselines from
  :mod:`qpcontact.solvers.baselines`: ``cg`` (conjugate gradient on the normal equations from
  zero, as in CellModeller) and ``bbpgd`` (projected gradient on the contact-space
  complementarity QP);
- *check*: the error measures of :mod:`qpcontact.resolve.metrics` on one answer.

Every answer is verified, untimed, against a high-accuracy reference: the QP answers against
:func:`~qpcontact.resolve.reference_solution` (relative error ``‖x − x*‖_W/‖x*‖_W``, target
1e-6), the answers of the plain solvers (linear, CG) against the linear solve at 1e-12. Each snapshot runs in its own
subprocess, so its peak resident memory (``ru_maxrss``, taken after the timed phases and before
the verification) is that of one step (with every solver). The scaling exponent of detection + assembly is the slope
of a least-squares line through (log cells, log seconds).

Output: a Markdown table and a log–log plot of time against cell count. The table is written
between the markers ``<!-- bench:start -->`` / ``<!-- bench:end -->`` of the Markdown file (the
rest of the file, e.g. the analysis in docs/performance.md, is kept), the raw numbers to JSON.
``--profile`` writes a cProfile of one step of the largest snapshot.

Outputs go to ``--out`` (default ``./bench-out``): ``performance.md``, ``img/performance.png``,
``data/performance.json``. Example: ``flock /tmp/qpcontact-bench.lock qpcontact bench --out docs
--overwrite`` (full run, several minutes, updates the project's docs); ``qpcontact bench --quick``
(seconds).
"""

from __future__ import annotations

import argparse
import cProfile
import datetime
import io
import json
import os
import platform
import pstats
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from ..assembly import ContactSystem, build_system
from ..cli import add_output_arguments, comma_list, non_negative_int, positive_float, positive_int, run_standalone
from ..cli import tolerance as tolerance_type
from ..errors import OutputFolderError
from ..geometry import Cells, colliding, find_contacts
from ..io.outputs import describe_written, prepare_folder, write_text
from ..io.snapshots import load_cells, save_cells
from ..resolve import active_set_polish, metrics, reference_solution, solve_system
from ..solvers import available_solvers, get_solver, solve_min_norm
from . import scenes

#: Solver specs ``name[/form][@tolerance]`` timed by default: the floor (LU and LSMR), the
#: baseline, and the QP solvers. MPRGP at 1e-7: at 1e-6 its answer on the 3D 300-cell snapshot
#: (rods side by side with two contacts each since issue 13) is 1.0e-6 from the reference, on
#: the edge of the target.
DEFAULT_SOLVERS = ("linear", "linear/primal", "cg@1e-8", "mprgp@1e-7", "osqp/contact", "osqp/primal",
                   "clarabel/primal@1e-9")
#: The relative error every answer must reach (issue 6).
TARGET_ERROR = 1e-6
MARK_START, MARK_END = "<!-- bench:start -->", "<!-- bench:end -->"
GENERATORS: dict[int, Callable[[int, int], Cells]] = {2: scenes.colony_2d, 3: scenes.colony_3d}


# ------------------------------------------------------------------------------------------
# Scenes (cached: a 10⁵-cell snapshot takes longer to build than to solve)
# ------------------------------------------------------------------------------------------
def load_scene(dimensions: int, n_cells: int, seed: int, cache_dir: Path | None) -> Cells:
    """The colony snapshot ``colony_{dimensions}d(n_cells, seed)``, from ``cache_dir`` if built
    before (:func:`qpcontact.io.snapshots.save_cells`)."""
    path = None if cache_dir is None else cache_dir / f"colony_{dimensions}d_{n_cells}_{seed}.npz"
    if path is not None and path.exists():
        return load_cells(path)
    cells = GENERATORS[dimensions](n_cells, seed)
    if path is not None:
        save_cells(path, cells)
    return cells


# ------------------------------------------------------------------------------------------
# One snapshot (runs in a subprocess)
# ------------------------------------------------------------------------------------------
#: A phase is not repeated once its repeats so far took longer than this [s] (keeps a full run short).
REPEAT_BUDGET = 30.0


def _timed(fn: Callable[[], Any], repeats: int) -> tuple[Any, list[float]]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
        if sum(times) > REPEAT_BUDGET:
            break
    return out, times


def _stats(times: list[float]) -> dict[str, float]:
    return {"median": float(np.median(times)), "min": float(min(times)), "max": float(max(times)), "repeats": len(times)}


def _parse_solver(spec: str) -> tuple[str, str, float | None]:
    """``name[/form][@tolerance]`` → (name, form, tolerance or None for the default)."""
    spec, _, tol = spec.partition("@")
    name, _, form = spec.partition("/")
    return name, form or "auto", float(tol) if tol else None


def _detect(cells: Cells, planar: bool):
    return colliding(find_contacts(cells, planar=planar))


def _measures(cells: Cells, system: ContactSystem, y: np.ndarray, lam: np.ndarray) -> tuple[Any, ...]:
    """The error measures of one answer (what *check* times)."""
    return (metrics.penetration(system, y), metrics.complementarity_residual(system, y, lam),
            metrics.multiplier_consistency(system, y, lam),
            metrics.physics(cells, system, system.to_impulses(y), system.to_contact_impulses(lam)))


def run_snapshot(dimensions: int, n_cells: int, *, seed: int, repeats: int, solvers: list[str], tolerance: float,
                 time_limit: float | None, cache_dir: Path | None) -> dict[str, Any]:
    """Time and verify one step on one snapshot; returns a JSON-ready record."""
    cells = load_scene(dimensions, n_cells, seed, cache_dir)
    planar = dimensions == 2
    (active, b), t_detect = _timed(lambda: _detect(cells, planar), repeats)
    system, t_assemble = _timed(lambda: build_system(cells, active, b), repeats)
    record: dict[str, Any] = {
        "dimensions": dimensions, "cells": cells.n, "contacts": len(active), "unknowns": system.shape[1],
        "detect": _stats(t_detect), "assemble": _stats(t_assemble), "solvers": {},
    }
    answers: dict[str, np.ndarray | None] = {}
    guesses: dict[str, np.ndarray] = {}  # contact impulses of the QP answers
    for spec in solvers:
        name, form, tol = _parse_solver(spec)
        tol = tol or tolerance
        row: dict[str, Any] = {"tolerance": tol}

        def call(name: str = name, form: str = form, tol: float = tol):
            return solve_system(system, solver=name, form=form, tolerance=tol, time_limit=time_limit)
        solution, times = _timed(call, repeats)
        y, lam = solution.y, solution.lam
        row.update(converged=solution.converged, status=solution.status, iterations=solution.iterations,
                   form=solution.form, message=solution.message)
        if not get_solver(name).plain and y is not None and lam is not None:
            guesses[spec] = lam
            (_, t_check) = _timed(partial(_measures, cells, system, y, lam), 1)
            row["check"] = _stats(t_check)
        row["solve"] = _stats(times)
        answers[spec] = y
        record["solvers"][spec] = row
    record["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    # Verification (untimed): the QPs against the complementarity reference, the linear solve and CG
    # against the linear solve at 1e-12.
    t0 = time.perf_counter()
    # The plain solvers' reference: the LU solve at 1e-12 where a plain solver factorized (so it
    # will finish), else LSMR to an optimality of 1e-10.
    plain_run = any(_plain(spec) for spec in answers)
    lu_ran = any(_plain(spec) and not _matrix_free(spec) for spec in answers)
    linear_ref = None
    if plain_run:
        linear = solve_min_norm(system.matrix, system.rhs, tolerance=1e-12 if lu_ran else 1e-10,
                                method="auto" if lu_ran else "lsmr")
        linear_ref = linear.y
        record["linear_reference"] = f"{linear.method} (optimality {linear.optimality:.1e})"
        if lu_ran:
            record["linear_inactive"] = int(np.sum(linear.lam <= 0))
    # The QP reference: the exact optimum on the active set of some solver's answer, kept only if
    # it verifies the KKT conditions to 1e-12 (then it is the unique optimum, whatever solver
    # guessed the set); otherwise validation.reference_solution's Clarabel solve at 1e-10.
    qp_ref, record["reference_method"] = None, "none (no QP answer)"
    for spec, lam in guesses.items():
        qp_ref = active_set_polish(system, lam)
        if qp_ref is not None:
            record["reference_method"] = f"exact KKT point on the active set of {spec}"
            break
    if qp_ref is None and guesses:
        qp_ref, record["reference_method"] = reference_solution(system, "complementarity"), "clarabel 1e-10 + polish"
    record["reference_seconds"] = time.perf_counter() - t0
    for spec, y in answers.items():
        plain = _plain(spec)
        ref = linear_ref if plain else qp_ref
        row = record["solvers"][spec]
        row["reference"] = "linear" if plain else "complementarity"
        row["error"] = None if y is None or ref is None else metrics.distance(y, ref)
        row["penetration"] = None if y is None else metrics.penetration(system, y)
        row["verified"] = bool(row["converged"] and row["error"] is not None and row["error"] <= TARGET_ERROR)
    return record


# ------------------------------------------------------------------------------------------
# Report
# ------------------------------------------------------------------------------------------
def scaling_exponent(cells: list[int], seconds: list[float]) -> float | None:
    """Slope of the least-squares line through ``(log cells, log seconds)``."""
    if len(cells) < 2:
        return None
    return float(np.polyfit(np.log(cells), np.log(seconds), 1)[0])


def _fmt(s: dict[str, float]) -> str:
    return f"{s['median']:.3g} ({s['min']:.3g}–{s['max']:.3g})"


def machine_description() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, {platform.system()}"


def _plain(spec: str) -> bool:
    """The solver of ``name[/form][@tolerance]`` solves the plain problem ``Mx = b``."""
    return get_solver(_parse_solver(spec)[0]).plain


def _matrix_free(spec: str) -> bool:
    """The solver of ``name[/form][@tolerance]`` solves that form without a factorization."""
    name, form, _ = _parse_solver(spec)
    solver = get_solver(name)
    return solver.plan("complementarity", form)[1] in solver.matrix_free


def _floor(spec: str) -> bool:
    """A plain solve that is not a baseline: the linear-solve floor of the tables."""
    solver = get_solver(_parse_solver(spec)[0])
    return solver.plain and not solver.baseline


def best_qp(record: dict[str, Any]) -> tuple[str, dict[str, Any]] | None:
    """The fastest verified QP solver of a snapshot (median setup+solve)."""
    rows = [(s, r) for s, r in record["solvers"].items() if not _plain(s) and r["verified"]]
    return min(rows, key=lambda sr: sr[1]["solve"]["median"]) if rows else None


def _step(record: dict[str, Any]) -> tuple[float | None, float | None, float]:
    """(step seconds with the best verified QP, QP/linear ratio, detect+assemble seconds)."""
    da = record["detect"]["median"] + record["assemble"]["median"]
    best = best_qp(record)
    floors = [row["solve"]["median"] for spec, row in record["solvers"].items() if _floor(spec) and row["verified"]]
    if best is None:
        return None, None, da
    qp = best[1]["solve"]["median"]
    return da + qp, (qp / min(floors) if floors else None), da


def target_lines(records: list[dict[str, Any]]) -> list[str]:
    """Each target of issue 6 against this run: met, missed, or not measured."""
    def find(dimensions: int, n: int) -> dict[str, Any] | None:
        return next((r for r in records if r["dimensions"] == dimensions and r["cells"] == n), None)

    def verdict(ok: bool | None) -> str:
        return "not measured" if ok is None else ("**met**" if ok else "**missed**")

    lines = ["| target | measured | verdict |", "|---|---|---|"]
    for dimensions, n, limit in ((2, 100000, 5.0), (2, 10000, 0.5), (3, 100000, 20.0)):
        r = find(dimensions, n)
        step = _step(r)[0] if r else None
        text = "–" if r is None else ("no verified QP answer" if step is None else f"{step:.3g} s")
        lines.append(f"| {dimensions}D, {n} cells: full step ≤ {limit:g} s | {text} | "
                     f"{verdict(None if r is None else (step is not None and step <= limit))} |")
    for dimensions in (2, 3):
        r = find(dimensions, 100000)
        if r is None:
            continue
        step, ratio, da = _step(r)
        lines.append(f"| {dimensions}D, 10⁵ cells: QP ≤ 3× linear solve | "
                     + ("–" if ratio is None else f"{ratio:.2f}×") + f" | {verdict(None if ratio is None else ratio <= 3)} |")
        lines.append(f"| {dimensions}D, 10⁵ cells: detect + assemble < 20 % of the step | "
                     + ("–" if step is None else f"{100 * da / step:.0f} % ({da:.3g} s)")
                     + f" | {verdict(None if step is None else da < 0.2 * step)} |")
        lines.append(f"| {dimensions}D, 10⁵ cells: peak memory < 4 GiB | {r['peak_rss_mib'] / 1024:.2f} GiB | "
                     f"{verdict(r['peak_rss_mib'] < 4096)} |")
    for dimensions in sorted({r["dimensions"] for r in records}):
        rs = [r for r in records if r["dimensions"] == dimensions]
        exp = scaling_exponent([r["cells"] for r in rs], [r["detect"]["median"] + r["assemble"]["median"] for r in rs])
        lines.append(f"| {dimensions}D: detect + assemble exponent ≤ 1.15 ({rs[0]['cells']}–{rs[-1]['cells']} cells) | "
                     + ("–" if exp is None else f"{exp:.2f}") + f" | {verdict(None if exp is None else exp <= 1.15)} |")
    return lines


def markdown(records: list[dict[str, Any]], meta: dict[str, Any]) -> str:
    """The results as Markdown: a phase table, a per-solver table, and the scaling exponents."""
    lines = [
        f"Run {meta['date']} on {meta['machine']}; `{meta['command']}`. Times in seconds: median (min–max) of "
        f"{meta['repeats']} repeats. Error: relative W-norm distance to the reference; verified = converged and "
        f"error ≤ {TARGET_ERROR:g}.", "",
        "| scene | cells | contacts | unknowns | detect | assemble | best QP (verified) | step = detect+assemble+QP | "
        "linear floor (LU or LSMR) | QP / linear | (detect+assemble) / step | peak RSS MiB |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        best = best_qp(r)
        floors = [row for spec, row in r["solvers"].items() if _floor(spec) and row["verified"]]
        lin = min(floors, key=lambda row: row["solve"]["median"]) if floors else None
        da = r["detect"]["median"] + r["assemble"]["median"]
        if best:
            step = da + best[1]["solve"]["median"]
            qp = f"{best[0]} {best[1]['solve']['median']:.3g}"
            ratio = f"{best[1]['solve']['median'] / lin['solve']['median']:.2f}" if lin else "–"
            share = f"{100 * da / step:.0f} %"
            step_s = f"{step:.3g}"
        else:
            qp, ratio, share, step_s = "none verified", "–", "–", "–"
        lines.append(
            f"| {r['dimensions']}D | {r['cells']} | {r['contacts']} | {r['unknowns']} | {_fmt(r['detect'])} | {_fmt(r['assemble'])} | "
            f"{qp} | {step_s} | {lin['solve']['median']:.3g} | {ratio} | {share} | {r['peak_rss_mib']:.0f} |"
            if lin else
            f"| {r['dimensions']}D | {r['cells']} | {r['contacts']} | {r['unknowns']} | {_fmt(r['detect'])} | {_fmt(r['assemble'])} | "
            f"{qp} | {step_s} | – | – | {share} | {r['peak_rss_mib']:.0f} |"
        )
    lines += ["", "Targets of issue 6 in this run (step = detect + assemble + the fastest verified QP solve):", "",
              *target_lines(records)]
    lines += ["", "Per solver (solve = setup + solve through `solve_system`; check = the error measures on that answer):", "",
              "| scene | cells | solver | solve | check | iterations | status | error | penetration | verified |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in records:
        for spec, s in r["solvers"].items():
            err = "–" if s.get("error") is None else f"{s['error']:.1e}"
            pen = "–" if s.get("penetration") is None else f"{s['penetration']:.1e}"
            check = _fmt(s["check"]) if "check" in s else "–"
            lines.append(f"| {r['dimensions']}D | {r['cells']} | {spec} | {_fmt(s['solve'])} | {check} | {s.get('iterations')} | "
                         f"{s['status']} | {err} | {pen} | {'yes' if s['verified'] else '**no**'} |")
    skipped = [f"{r['dimensions']}D {r['cells']}: {spec} ({why})" for r in records for spec, why in r.get("skipped", {}).items()]
    if skipped:
        lines += ["", "Not run (too slow, see `--slow-limit`): " + "; ".join(skipped) + "."]
    lines += ["", "QP references: " + "; ".join(f"{r['dimensions']}D {r['cells']}: {r['reference_method']} "
                                             f"({r['reference_seconds']:.3g} s)" for r in records) + "."]
    lines += ["", "Fitted scaling exponent of detect + assemble (slope of log time against log cells):", ""]
    for dimensions in sorted({r["dimensions"] for r in records}):
        rs = [r for r in records if r["dimensions"] == dimensions]
        exp = scaling_exponent([r["cells"] for r in rs], [r["detect"]["median"] + r["assemble"]["median"] for r in rs])
        lines.append(f"- {dimensions}D, {rs[0]['cells']}–{rs[-1]['cells']} cells: "
                     + ("–" if exp is None else f"**{exp:.2f}**"))
    return "\n".join(lines) + "\n"


def plot(records: list[dict[str, Any]], path: Path) -> None:
    """Log–log plot of time against cell count: detect, assemble and each solver, per dimension."""
    from matplotlib.figure import Figure

    all_dimensions = sorted({r["dimensions"] for r in records})
    fig = Figure(figsize=(6 * len(all_dimensions), 4.5))
    axes = fig.subplots(1, len(all_dimensions), squeeze=False)
    for ax, dimensions in zip(axes[0], all_dimensions, strict=True):
        rs = [r for r in records if r["dimensions"] == dimensions]
        n = [r["cells"] for r in rs]
        ax.loglog(n, [r["detect"]["median"] for r in rs], "k--o", label="detect")
        ax.loglog(n, [r["assemble"]["median"] for r in rs], "k:s", label="assemble")
        for spec in dict.fromkeys(spec for r in rs for spec in r["solvers"]):
            done = [(r["cells"], r["solvers"][spec]["solve"]["median"]) for r in rs if spec in r["solvers"]]
            ax.loglog(*zip(*done, strict=True), "-o", label=spec)
        ax.loglog(n, [n_i * 1e-5 for n_i in n], color="0.8", lw=4, zorder=0, label="∝ cells")
        ax.set(xlabel="cells", ylabel="seconds (median)", title=f"{dimensions}D colony")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def write_markdown(path: Path, table: str, image: Path) -> None:
    """Replace the text between the bench markers of ``path`` (create the file if needed)."""
    rel = os.path.relpath(image, path.parent)
    block = f"{MARK_START}\n{table}\n![time against cell count]({rel})\n{MARK_END}"
    text = path.read_text() if path.exists() else "# Performance\n\n"
    if MARK_START in text and MARK_END in text:
        head, rest = text.split(MARK_START, 1)
        text = head + block + rest.split(MARK_END, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    write_text(path, text)


def profile_step(dimensions: int, n_cells: int, seed: int, solver: str, tolerance: float, cache_dir: Path | None, out: Path) -> str:
    """cProfile of one step (detect, assemble, solve); writes ``out`` (pstats) and returns the top
    functions by cumulative time as text."""
    cells = load_scene(dimensions, n_cells, seed, cache_dir)
    name, form, tol = _parse_solver(solver)

    def step() -> None:
        active, b = _detect(cells, dimensions == 2)
        solve_system(build_system(cells, active, b), solver=name, form=form, tolerance=tol or tolerance)

    prof = cProfile.Profile()
    prof.runcall(step)
    out.parent.mkdir(parents=True, exist_ok=True)
    prof.dump_stats(str(out))
    text = io.StringIO()
    pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(30)
    return text.getvalue()


# ------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------
#: Exponents used to extrapolate a solve time to the next size: iterative solvers, and sparse
#: factorizations (LU, OSQP, interior point) of 2D and 3D contact graphs. Measured here: LU of
#: the 3D Delassus operator 0.5 s at 10⁴ cells and more than 8 minutes at 10⁵ (exponent > 3);
#: a factorization cannot be interrupted, so the benchmark must not start one it cannot finish.
EXTRAPOLATION_EXPONENT = {"iterative": 1.5, 2: 2.0, 3: 3.0}


def _too_slow(previous: dict[str, Any] | None, n_cells: int, solvers: list[str], limit: float) -> dict[str, str]:
    """Solvers not to run at ``n_cells`` cells: those skipped before, or whose time at the previous size,
    extrapolated with :data:`EXTRAPOLATION_EXPONENT`, exceeds ``limit`` seconds."""
    if previous is None:
        return {}
    out = {}
    for spec in solvers:
        if spec in previous.get("skipped", {}):
            out[spec] = previous["skipped"][spec]
            continue
        row = previous["solvers"].get(spec)
        if row is None:
            continue
        kind = "iterative" if _matrix_free(spec) else previous["dimensions"]
        guess = row["solve"]["median"] * (n_cells / previous["cells"]) ** EXTRAPOLATION_EXPONENT[kind]
        if guess > limit:
            out[spec] = f"{row['solve']['median']:.3g} s at {previous['cells']} cells, extrapolated {guess:.3g} s > {limit:g} s"
    return out


def solver_spec(text: str) -> str:
    """A ``--solvers`` item ``name[/form][@tolerance]``, checked: an installed solver (or baseline),
    a form it takes, a tolerance in (0, 1)."""
    head, at, tolerance = text.partition("@")
    name, _, form = head.partition("/")
    if at:
        tolerance_type(tolerance)
    if name not in available_solvers(include_baselines=True):
        raise argparse.ArgumentTypeError(f"unknown or uninstalled solver {name!r}; known: "
                                         f"{', '.join(available_solvers(include_baselines=True))}")
    if form and form not in get_solver(name).forms:
        raise argparse.ArgumentTypeError(f"solver {name!r} takes the forms {', '.join(get_solver(name).forms)}, not {form!r}")
    return text


#: The files ``qpcontact bench`` writes, relative to ``--out``.
OUTPUTS = ("performance.md", "img/performance.png", "data/performance.json")
PROFILE_OUTPUTS = ("data/performance-profile.prof", "data/performance-profile.txt")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact bench``."""
    p.description = ("Time each phase of a contact step (detection, assembly, each solver, the checks) on 2D and 3D "
                     "colony snapshots, verify every answer, and write performance.md (the table between the markers "
                     "<!-- bench:start --> and <!-- bench:end --> of an existing file, the rest kept), "
                     "img/performance.png and data/performance.json into --out. --out docs --overwrite updates the "
                     "project's docs/performance.md.")
    p.add_argument("--sizes", type=comma_list(positive_int), default=[1000, 10000, 100000], metavar="LIST",
                   help="comma-separated cell counts (default: 1000,10000,100000; --quick: 300,1000)")
    p.add_argument("--dimensions", type=comma_list(int, choices=("2", "3")), default=[2, 3], metavar="LIST",
                   help="2 (monolayers), 3 (biofilms) or 2,3 (default: 2,3)")
    p.add_argument("--repeats", type=positive_int, default=3, help="timed repeats of each phase; median, min and max "
                   "are reported (default: 3; --quick: 2)")
    p.add_argument("--solvers", type=comma_list(solver_spec), default=list(DEFAULT_SOLVERS), metavar="LIST",
                   help="comma-separated solvers, each name[/FORM][@TOL]: FORM picks a form (linear/primal: LSMR "
                        "instead of Cholesky; osqp/contact), TOL that solver's tolerance (clarabel/primal@1e-9) "
                        f"(default: {','.join(DEFAULT_SOLVERS)}; installed: "
                        f"{', '.join(available_solvers(include_baselines=True))})")
    p.add_argument("--tolerance", type=tolerance_type, default=TARGET_ERROR,
                   help=f"tolerance handed to the solvers [dimensionless, scaled units] (default: {TARGET_ERROR:g})")
    p.add_argument("--time-limit", type=positive_float, default=120.0,
                   help="time limit per QP solve [s], where the backend takes one (default: 120)")
    p.add_argument("--slow-limit", type=positive_float, default=120.0,
                   help="skip a solver at the next size when its extrapolated time exceeds this [s] (exponent 1.5 for "
                        "iterative solvers, 2 for factorizations in 2D, 3 in 3D) (default: 120)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="random seed of the snapshots (default: 0)")
    p.add_argument("--quick", action="store_true", help="tiny sizes (300, 1000), 2 repeats: a smoke test in seconds")
    add_output_arguments(p, "bench", "performance.md, img/performance.png and data/performance.json")
    p.add_argument("--cache-dir", type=Path, default=Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "qpcontact-bench",
                   metavar="FOLDER", help="where colony snapshots are cached ('none' to disable) (default: %(default)s)")
    p.add_argument("--profile", action="store_true",
                   help="also write a cProfile of one step of the largest 2D snapshot (data/performance-profile.*)")
    p.add_argument("--profile-solver", type=solver_spec, default="osqp/contact",
                   help="the solver of --profile (default: osqp/contact)")
    p.add_argument("--worker", nargs=2, type=positive_int, metavar=("DIMENSIONS", "N_CELLS"), help=argparse.SUPPRESS)


def run_command(args: argparse.Namespace) -> int:
    """``qpcontact bench``."""
    cache = None if str(args.cache_dir) == "none" else args.cache_dir
    if args.quick:
        args.sizes, args.repeats = [300, 1000], 2
    if args.worker:  # one snapshot in this process; JSON on stdout
        dimensions, n = args.worker
        record = run_snapshot(dimensions, n, seed=args.seed, repeats=args.repeats, solvers=args.solvers,
                              tolerance=args.tolerance, time_limit=args.time_limit, cache_dir=cache)
        print(json.dumps(record))
        return 0
    out = args.out
    outputs = OUTPUTS + (PROFILE_OUTPUTS if args.profile else ())
    # performance.md keeps everything but its table: an existing one is updated, not replaced.
    prepare_folder(out, [name for name in outputs if name != "performance.md"], overwrite=args.overwrite)
    if (out / "performance.md").exists() and not args.overwrite:
        raise OutputFolderError(f"{out} holds performance.md of an earlier run; pass --overwrite to update its "
                                "table, or choose another output folder")
    records = []
    common = ["--repeats", str(args.repeats), "--seed", str(args.seed), "--tolerance", repr(args.tolerance),
              "--time-limit", repr(args.time_limit), "--cache-dir", str(args.cache_dir)]
    for dimensions in args.dimensions:
        previous: dict[str, Any] | None = None
        for n in sorted(args.sizes):
            print(f"bench: {dimensions}D, {n} cells ...", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            skipped = _too_slow(previous, n, args.solvers, args.slow_limit)
            run = [spec for spec in args.solvers if spec not in skipped]
            proc = subprocess.run([sys.executable, "-m", "qpcontact.studies.bench", "--worker", str(dimensions), str(n), *common,
                                   "--solvers", ",".join(run)], capture_output=True, text=True)
            if proc.returncode != 0:
                print(proc.stderr, file=sys.stderr)
                print(f"bench: worker for {dimensions}D, {n} cells failed (exit {proc.returncode})", file=sys.stderr)
                return 1
            previous = json.loads(proc.stdout.strip().splitlines()[-1])
            previous["skipped"] = skipped
            records.append(previous)
            print(f"bench: {dimensions}D, {n} cells done in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    meta = {
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": machine_description(),
        "command": (f"qpcontact bench --sizes {','.join(map(str, args.sizes))} --dimensions "
                    f"{','.join(map(str, args.dimensions))} --repeats {args.repeats} --solvers {','.join(args.solvers)}"),
        "repeats": args.repeats,
    }
    table = markdown(records, meta)
    image = out / "img" / "performance.png"
    plot(records, image)
    write_markdown(out / "performance.md", table, image)
    write_text(out / "data" / "performance.json", json.dumps({"meta": meta, "records": records}, indent=1))
    if args.profile:
        dimensions = 2 if 2 in args.dimensions else args.dimensions[0]
        text = profile_step(dimensions, max(args.sizes), args.seed, args.profile_solver, args.tolerance, cache,
                            out / "data" / "performance-profile.prof")
        write_text(out / "data" / "performance-profile.txt", text)
    print(table)
    print(describe_written(out / name for name in outputs))
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact bench", add_arguments, run_command, argv)


if __name__ == "__main__":
    sys.exit(main())
