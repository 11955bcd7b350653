"""Shared scene builders for the tests (small, seeded, fast)."""

from __future__ import annotations

import numpy as np
import pytest

import qpcontact as qc


def random_scene(
    seed: int,
    n: int = 30,
    *,
    planar: bool = False,
    box: float = 5.0,
    converging: float = 1.0,
    mass_spread: float = 4.0,
    growing: bool = True,
    unit_length: float = 1.0,
    unit_mass: float = 1.0,
) -> qc.Cells:
    """Rods of random length and orientation in a box, moving towards the box centre (so most
    contacts approach), with random extra momenta and growth. ``unit_length``/``unit_mass``
    express the same scene in other units (time unit unchanged)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.0, box, (n, 3))
    axes = rng.normal(size=(n, 3))
    if planar:
        centres[:, 2] = 0.0
        axes[:, 2] = 0.0
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    lengths = rng.uniform(0.5, 2.5, n)
    radii = rng.uniform(0.3, 0.6, n)
    masses = rng.uniform(1.0, mass_spread, n)
    velocity = -converging * (centres - centres.mean(axis=0)) + rng.normal(0, 0.3, (n, 3))
    omega = rng.normal(0, 0.3, (n, 3))
    if planar:
        velocity[:, 2] = 0.0
        omega[:, :2] = 0.0
    cells = qc.Cells(centres, axes, lengths, radii, masses=masses, growth_inertia=masses if growing else np.inf)
    momenta = masses[:, None] * velocity
    # L = I ω via the inverse: solve per cell with the axisymmetric inverse (I = inverse of I⁻¹).
    inv_par, inv_perp = cells.inverse_inertia_parallel, cells.inverse_inertia_perpendicular
    along = np.einsum("ij,ij->i", axes, omega)[:, None] * axes
    angular = along / inv_par[:, None] + (omega - along) / inv_perp[:, None]
    growth = (masses * rng.uniform(0.0, 0.5, n)) if growing else np.zeros(n)
    return qc.Cells(
        centres * unit_length, axes, lengths * unit_length, radii * unit_length,
        masses=masses * unit_mass, growth_inertia=(masses if growing else np.full(n, np.inf)) * unit_mass,
        momenta=momenta * unit_mass * unit_length, angular_momenta=angular * unit_mass * unit_length**2,
        growth_momenta=growth * unit_mass * unit_length,
    )


def two_rods(gap: float = -0.1, *, angle: float = np.pi / 2, speed: float = 1.0) -> qc.Cells:
    """Two rods along x, one above the other (or crossed by ``angle``), approaching along y."""
    axes = np.array([[1.0, 0.0, 0.0], [np.cos(angle), np.sin(angle) * 0, np.sin(angle)]])
    centres = np.array([[0.0, 1.0 + gap, 0.0], [0.3, 0.0, 0.0]])
    return qc.Cells(centres, axes, [2.0, 3.0], 0.5, masses=[1.0, 2.0], growth_inertia=[1.5, 0.7],
                    momenta=[[0.0, -speed, 0.0], [0.0, 2.0 * speed * 0.5, 0.0]])


@pytest.fixture
def scene():
    return random_scene(0)
