"""The radial pressure profile of a grown 2D colony against the continuum model of a growing
colony with friction (docs/mechanics.md).

From a snapshot of a 2D colony (``qpcontact simulate --cells 5000``), takes one growth step as
``qpcontact simulate`` takes it (the snapshot's settings, else the defaults) and measures:

- each cell's 2D pressure over the step (:func:`qpcontact.cell_pressure` of the step's contact
  forces) against its distance r from the colony's centre, and the least-squares parabola
  ``p = a (R² − r²)``;
- the continuum prediction. Cells drag on the substrate (overdamped: a cell of "mass" m moving at
  v feels −m v), so per unit area the friction is ``ξ v`` with ``ξ = φ Σm/ΣA`` (φ the area
  fraction, A the footprints); force balance ``−∇P = ξ v`` with the colony's stress
  ``P = φ p̄`` (the mean of the cells' virial pressures over their footprints), and with
  uniform growth at the areal rate g, ``∇·v = g``: ``v = g r/2`` and
  ``p(r) = (Σm/ΣA) (g/4) (R² − r²)``: φ cancels. ``a`` is predicted with g from the cells'
  growth over the step and, without the continuity assumption, from the measured slope of the
  radial velocity (``v_r = s r``, ``a = (Σm/ΣA) s/2``);
- the radial and hoop stresses ``σ_rr``, ``σ_θθ`` (an isotropic pressure has them equal);
- how far the contact forces, reported at the end positions of the step, balance each cell's
  momenta of the step (net force against the step's impulses), and how much the pressures
  change with the contacts evaluated at the start positions instead.

    python -m qpcontact.studies.pressure_profile SNAPSHOT.npz --out DIR

writes ``DIR/pressure_profile.png`` (profile, velocity, stresses), ``DIR/pressure_map.png``
(the colony coloured by pressure) and ``DIR/pressure_profile.md`` (the numbers).
"""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..cli import add_output_arguments, positive_int, run_standalone
from ..colony import Colony
from ..colony.growth import growth_step
from ..errors import InvalidArgumentError
from ..geometry import capsule_footprint, evaluate_contacts
from ..io import load_snapshot
from ..io.outputs import describe_written, prepare_folder, write_text
from ..simulation import Settings
from ..simulation.steps import step_function, step_mechanics
from ..timestep import CellMechanics, cell_forces, cell_pressure, fit_parabola, radial_profile
from ..timestep.mechanics import radial_distances
from ..timestep.position import PositionStepResult

OUTPUTS = ("pressure_profile.png", "pressure_map.png", "pressure_profile.md")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("snapshot", type=Path, help="a snapshot (.npz) of a 2D colony")
    parser.add_argument("--bins", type=positive_int, default=20, help="rings of the profile (default: 20)")
    add_output_arguments(parser, "pressure_profile", "the pictures and pressure_profile.md")


def main(argv: list[str] | None = None) -> int:
    return run_standalone("python -m qpcontact.studies.pressure_profile", add_arguments, run_command, argv,
                          (__doc__ or "").split("\n\n")[0])


def measure(colony: Colony, settings: Settings, bins: int = 20) -> dict[str, Any]:
    """One step of ``colony`` and what the module docstring lists, as numbers and arrays."""
    if settings.run.dimensions != 2 or not np.all(colony.cells.centers[:, 2] == colony.cells.centers[0, 2]):
        raise InvalidArgumentError("pressure_profile: the colony must be a 2D monolayer (dimensions = 2)")
    if settings.run.step != "position":
        raise InvalidArgumentError("pressure_profile: measures the position-level step (step = position)")
    before = colony.cells
    dt = settings.time_step_of(colony)
    increase, _ = growth_step(colony, dt)
    outcome = step_function(settings, {})(colony, dt, drive=None)
    after, result = outcome.colony.cells, outcome.result
    assert isinstance(result, PositionStepResult)
    mechanics: CellMechanics = step_mechanics(outcome, settings)
    r, center = radial_distances(after)  # the positions the contacts (and so the stresses) are of
    outward = (after.centers[:, :2] - center) / np.maximum(r, 1e-300)[:, None]
    velocity = (after.centers[:, :2] - before.centers[:, :2]) / outcome.dt
    radial_velocity = np.einsum("ij,ij->i", velocity, outward)
    footprint = capsule_footprint(before.lengths, before.radii)
    drag_per_area = float(before.masses.sum() / footprint.sum())
    grown = float((2 * before.radii * (after.lengths - before.lengths)).sum() / footprint.sum() / outcome.dt)
    driven = float((2 * before.radii * increase).sum() / footprint.sum() / outcome.dt)
    slope = float(np.sum(radial_velocity * r) / np.sum(r * r))
    fit = fit_parabola(r, mechanics.pressure)
    hoop = np.c_[-outward[:, 1], outward[:, 0], np.zeros(before.n)]
    radial = np.c_[outward, np.zeros(before.n)]
    sigma_rr = np.einsum("ni,nij,nj->n", radial, mechanics.stress, radial)
    sigma_tt = np.einsum("ni,nij,nj->n", hoop, mechanics.stress, hoop)
    contacts, forces = result.contacts, result.contact_forces
    net, _ = cell_forces(after, contacts, forces)
    moved = result.impulses[:, :3]
    at_start = evaluate_contacts(before, contacts.cell_a, contacts.cell_b, contacts.kind, planar=True)
    pressure_at_start = cell_pressure(before, at_start, forces, planar=True)
    outer = float(np.max(r + after.lengths / 2 + after.radii))
    return {
        "cells": before.n, "contacts": len(contacts), "dt": outcome.dt, "time": colony.time,
        "linearizations": result.iterations, "turn_limited": result.turn_limited,
        "r": r, "pressure": mechanics.pressure, "radial_velocity": radial_velocity,
        "sigma_rr": sigma_rr, "sigma_tt": sigma_tt,
        "fit_amplitude": fit.amplitude, "fit_radius": fit.radius, "fit_rms": fit.rms, "outer_radius": outer,
        "area_fraction": float(footprint.sum() / (np.pi * outer**2)),
        "drag_per_area": drag_per_area, "growth_rate_cells": grown, "growth_rate_driven": driven,
        "velocity_slope": slope,
        "predicted_amplitude_growth": drag_per_area * grown / 4, "predicted_amplitude_velocity": drag_per_area * slope / 2,
        "net_force_error": float(np.linalg.norm(net - moved) / np.linalg.norm(moved)),
        "median_net_force": float(np.median(np.linalg.norm(moved, axis=1))),
        "median_contact_force": float(np.median(forces[forces > 0])) if np.any(forces > 0) else 0.0,
        "pressure_change_at_start": float(np.linalg.norm(pressure_at_start - mechanics.pressure)
                                          / np.linalg.norm(mechanics.pressure)),
        "negative_pressures": int(np.sum(mechanics.pressure < 0)),
        "profile": radial_profile(after, mechanics.pressure, bins=bins),
        "velocity_profile": radial_profile(after, radial_velocity, bins=bins),
        "rr_profile": radial_profile(after, -sigma_rr, bins=bins),
        "tt_profile": radial_profile(after, -sigma_tt, bins=bins),
        "cells_after": after,
    }


def draw(measured: dict[str, Any], path: Path, title: str) -> Path:
    """The three panels: pressure with fit and predictions, radial velocity, radial and hoop stress."""
    from matplotlib.figure import Figure

    from ..io.plots import pressure_label

    r = measured["r"]
    grid = np.linspace(0.0, float(r.max()), 200)
    radius = measured["fit_radius"]
    fig = Figure(figsize=(13, 4.4), dpi=110, layout="constrained")
    ax = fig.subplots(1, 3)
    profile = measured["profile"]
    kept = profile.counts > 0
    ax[0].plot(r, measured["pressure"], ".", ms=1, color="0.7", alpha=0.5, label="cells")
    ax[0].errorbar(profile.radius[kept], profile.mean[kept], yerr=profile.std[kept], fmt="o", ms=3, capsize=2,
                   color="C0", label="mean in rings (± std)")
    ax[0].plot(grid, measured["fit_amplitude"] * (radius**2 - grid**2), "-", color="C3",
               label=f"fit a(R² − r²): a = {measured['fit_amplitude']:.3f}, R = {radius:.1f} µm")
    for key, style, what in (("predicted_amplitude_growth", "--", "g from the cells' growth"),
                             ("predicted_amplitude_velocity", ":", "g from the radial velocity")):
        ax[0].plot(grid, measured[key] * (radius**2 - grid**2), style, color="k",
                   label=f"continuum, {what}: a = {measured[key]:.3f}")
    ax[0].set_ylim(bottom=-0.05 * float(np.percentile(measured["pressure"], 99.5)),
                   top=float(np.percentile(measured["pressure"], 99.5)))
    ax[0].set_ylabel(pressure_label(True))
    ax[0].legend(fontsize=7)
    velocity = measured["velocity_profile"]
    ax[1].plot(r, measured["radial_velocity"], ".", ms=1, color="0.7", alpha=0.5)
    ax[1].errorbar(velocity.radius[kept], velocity.mean[kept], yerr=velocity.std[kept], fmt="o", ms=3, capsize=2,
                   color="C0", label="mean in rings (± std)")
    ax[1].plot(grid, measured["velocity_slope"] * grid, "-", color="C3",
               label=f"v = s r, s = {measured['velocity_slope']:.3f} /doubling time")
    ax[1].plot(grid, measured["growth_rate_cells"] / 2 * grid, "--", color="k",
               label=f"g r/2, g = {measured['growth_rate_cells']:.3f} (the cells' growth)")
    ax[1].set_ylabel("radial velocity [µm/doubling time]")
    ax[1].legend(fontsize=7)
    for key, label, colour in (("rr_profile", "−σ_rr (radial)", "C0"), ("tt_profile", "−σ_θθ (hoop)", "C1")):
        ring = measured[key]
        ax[2].plot(ring.radius[kept], ring.mean[kept], "o-", ms=3, color=colour, label=label)
    ax[2].set_ylabel("normal stress, compressive positive [F/µm]")
    ax[2].legend(fontsize=8)
    for axis in ax:
        axis.set_xlabel("distance from the colony's centre r [µm]")
        axis.axhline(0.0, color="0.3", lw=0.5)
    fig.suptitle(title, fontsize=10)
    fig.savefig(path)
    return path


def report(measured: dict[str, Any], source: str) -> str:
    """``pressure_profile.md``: the measured numbers."""
    m = measured
    ratio_growth = m["fit_amplitude"] / m["predicted_amplitude_growth"]
    ratio_velocity = m["fit_amplitude"] / m["predicted_amplitude_velocity"]
    rows = [
        ("cells, contacts", f"{m['cells']}, {m['contacts']}"),
        ("step dt [doubling times], linearizations, cells on a turning bound",
         f"{m['dt']:.4f}, {m['linearizations']}, {m['turn_limited']}"),
        ("fitted a [F/µm³], R [µm], rms residual [F/µm]",
         f"{m['fit_amplitude']:.4f}, {m['fit_radius']:.1f}, {m['fit_rms']:.1f}"),
        ("outermost cell tip [µm]; area fraction to it", f"{m['outer_radius']:.1f}; {m['area_fraction']:.2f}"),
        ("Σm/ΣA [mass/µm²]", f"{m['drag_per_area']:.4f}"),
        ("areal growth rate g: cells' growth over the step, growth driven [1/doubling time]",
         f"{m['growth_rate_cells']:.4f}, {m['growth_rate_driven']:.4f}"),
        ("radial velocity slope s [1/doubling time] (continuum: g/2)", f"{m['velocity_slope']:.4f}"),
        ("continuum a from g (cells' growth); fitted/predicted", f"{m['predicted_amplitude_growth']:.4f}; {ratio_growth:.2f}"),
        ("continuum a from s (measured velocity); fitted/predicted",
         f"{m['predicted_amplitude_velocity']:.4f}; {ratio_velocity:.2f}"),
        ("cells with negative pressure", f"{m['negative_pressures']}"),
        ("net contact force vs the step's momenta (relative error)", f"{m['net_force_error']:.2f}"),
        ("median net force per cell; median contact force [F]", f"{m['median_net_force']:.1f}; {m['median_contact_force']:.1f}"),
        ("pressure with contacts at the start of the step (relative change)", f"{m['pressure_change_at_start']:.3f}"),
    ]
    rings = m["profile"]
    ring_rows = "\n".join(
        f"| {r:.1f} | {n} | {p:.1f} | {s:.1f} | {rr:.1f} | {tt:.1f} | {v:.2f} |"
        for r, n, p, s, rr, tt, v in zip(rings.radius, rings.counts, rings.mean, rings.std, m["rr_profile"].mean,
                                         m["tt_profile"].mean, m["velocity_profile"].mean, strict=True) if n)
    return (f"# Pressure profile of {source}\n\n{datetime.now(UTC):%Y-%m-%d %H:%M} UTC; one position step of "
            f"`qpcontact simulate`'s settings from the snapshot (t = {m['time']:.3f} doubling times).\n\n"
            "| measure | value |\n|---|---|\n" + "\n".join(f"| {k} | {v} |" for k, v in rows)
            + "\n\n| ring r [µm] | cells | mean p [F/µm] | std | −σ_rr | −σ_θθ | v_r [µm/doubling time] |\n"
            "|---|---|---|---|---|---|---|\n" + ring_rows + "\n\n```json\n"
            + json.dumps({k: v for k, v in m.items() if isinstance(v, (int, float, str))}, indent=1) + "\n```\n")


def run_command(args: argparse.Namespace) -> int:
    from ..io.plots import pressure_label, save_colony_picture

    folder = prepare_folder(args.out, OUTPUTS, overwrite=args.overwrite)
    snapshot = load_snapshot(args.snapshot)
    settings = (Settings() if snapshot.settings is None
                else Settings.from_stored(snapshot.settings, f"{args.snapshot} (settings)"))
    measured = measure(snapshot.colony, settings, bins=args.bins)
    title = (f"{measured['cells']} cells (t = {measured['time']:.2f} doubling times): one step of qpcontact simulate "
             f"from {args.snapshot.name}")
    written = [draw(measured, folder / "pressure_profile.png", title)]
    written.append(save_colony_picture(folder / "pressure_map.png", measured["cells_after"],
                                       f"{measured['cells']} cells coloured by their pressure over one step",
                                       values=measured["pressure"], value_label=pressure_label(True)))
    written.append(write_text(folder / "pressure_profile.md", report(measured, args.snapshot.name)))
    print(describe_written(written))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
