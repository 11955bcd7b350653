"""The one capsule volume and the one inertia tensor, against independent constructions."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

import qpcontact as qc
from qpcontact.geometry import capsule_mass, capsule_volume, inertia_times


@pytest.mark.parametrize("length, radius", [(0.0, 0.5), (2.0, 0.5), (3.7, 0.2), (1e-3, 2.0)])
def test_capsule_volume_is_the_integral_of_its_cross_sections(length, radius):
    def area(s):  # a disc of the radius at axial coordinate s (the caps shrink it)
        cap = max(0.0, abs(s) - length / 2)
        return np.pi * (radius**2 - cap**2)

    half = length / 2 + radius
    integral, _ = quad(area, -half, half, points=[-length / 2, length / 2], epsabs=1e-13, epsrel=1e-13)
    assert capsule_volume(length, radius) == pytest.approx(integral, rel=1e-12)
    assert capsule_mass(length, radius, 1.1) == pytest.approx(1.1 * integral, rel=1e-12)


def test_volume_broadcasts_over_arrays():
    lengths, radii = np.array([0.0, 1.0, 2.0]), np.array([0.5, 0.5, 0.25])
    np.testing.assert_allclose(capsule_volume(lengths, radii), [capsule_volume(l_, r) for l_, r in zip(lengths, radii, strict=True)])


def test_inertia_times_is_the_inverse_of_the_cells_inverse_inertia():
    """``I`` here and ``I⁻¹`` in :class:`qpcontact.Cells` are written independently; one undoes
    the other for any vector, and the axis and its normals are the principal directions."""
    rng = np.random.default_rng(0)
    n = 50
    cells = qc.Cells(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.uniform(0.0, 3.0, n),
                     rng.uniform(0.2, 0.8, n), masses=rng.uniform(0.5, 2.0, n), normalize_axes=True)
    w = rng.normal(size=(n, 3))
    L = inertia_times(cells.axes, cells.lengths, cells.radii, cells.masses, w)
    np.testing.assert_allclose(cells.apply_inverse_inertia(L), w, rtol=1e-12, atol=1e-12)
    along = inertia_times(cells.axes, cells.lengths, cells.radii, cells.masses, cells.axes)
    np.testing.assert_allclose(along, (cells.masses * cells.radii**2 / 2)[:, None] * cells.axes, rtol=1e-12)
