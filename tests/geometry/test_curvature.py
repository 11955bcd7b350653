"""The separation Hessians of qpcontact.geometry.curvature against second differences of the
true separation (evaluate_contacts) at moved cells."""

import numpy as np
import pytest

from qpcontact.geometry.cells import Cells
from qpcontact.geometry.contacts import evaluate_contacts
from qpcontact.geometry.curvature import separation_hessians
from qpcontact.geometry.motion import rotate


def _pairs(planar: bool, k: int = 150, seed: int = 3):
    rng = np.random.default_rng(seed)

    def axes(m):
        v = rng.standard_normal((m, 3))
        if planar:
            v[:, 2] = 0.0
        return v / np.linalg.norm(v, axis=1)[:, None]

    centres = np.empty((2 * k, 3))
    centres[0::2] = rng.standard_normal((k, 3)) * 0.3
    centres[1::2] = centres[0::2] + axes(k) * rng.uniform(0.9, 1.6, (k, 1))
    if planar:
        centres[:, 2] = 0.0
    cells = Cells(centres, axes(2 * k), rng.uniform(0.5, 3.0, 2 * k), rng.uniform(0.4, 0.6, 2 * k))
    return cells, np.arange(0, 2 * k, 2), np.arange(1, 2 * k, 2), rng.integers(0, 5, k)


def _moved(cells: Cells, change: np.ndarray) -> Cells:
    """Each pair's cells moved by the (K, 14) coordinates (centre, turn, length of a, then b)."""
    centres, axes, lengths = cells.centers.copy(), cells.axes.copy(), cells.lengths.copy()
    for side, at in ((0, 0), (1, 7)):
        index = np.arange(side, cells.n, 2)
        centres[index] += change[:, at:at + 3]
        axes[index] = rotate(axes[index], change[:, at + 3:at + 6])
        lengths[index] += change[:, at + 6]
    return cells.replace(centers=centres, axes=axes, lengths=lengths)


@pytest.mark.parametrize("planar", [False, True])
def test_the_hessian_is_that_of_the_true_separation(planar):
    cells, a, b, kind = _pairs(planar)
    contacts = evaluate_contacts(cells, a, b, kind, planar=planar, velocities=False)
    hessians = separation_hessians(cells, contacts)
    h, eye, k = 1e-4, np.eye(14), a.size

    def separation(change):
        return evaluate_contacts(_moved(cells, np.broadcast_to(change, (k, 14))), a, b, kind, planar=planar,
                                 velocities=False).separation

    numeric = np.zeros((k, 14, 14))
    for i in range(14):
        for j in range(i, 14):
            value = (separation(h * (eye[i] + eye[j])) - separation(h * (eye[i] - eye[j]))
                     - separation(h * (eye[j] - eye[i])) + separation(-h * (eye[i] + eye[j]))) / (4 * h * h)
            numeric[:, i, j] = numeric[:, j, i] = value
    # In a monolayer, the coordinates it moves in (centre x, y, the turn about z, the length).
    used = np.array([0, 1, 5, 6, 7, 8, 12, 13]) if planar else np.arange(14)
    error = np.abs(numeric - hessians)[:, used][:, :, used].max(axis=(1, 2))
    # Axes that cross (distance 0, a monolayer's degenerate contact) have no normal to turn.
    apart = contacts.separation + cells.radii[a] + cells.radii[b] > 0.3
    # Pairs whose closest points sit where they switch (an end just reached) have no Hessian:
    # a few; every other agrees to the second differences' own error.
    assert apart.sum() > 100 and np.mean(error[apart] < 1e-5) >= 0.97
    assert np.abs(hessians).max() < 100.0  # no blow-up at crossing or parallel axes
    # and the slide matters: a free closest point's pair has concave directions
    assert np.any(np.linalg.eigvalsh(hessians)[:, 0] < -0.1)
