"""The shape of a capsule cell: its volume, its footprint in a plane, and its inertia tensor
applied to a vector.

One formula each, used everywhere a volume, a mass from a density, or an angular momentum from
an angular velocity is needed (growth, simulate, the scenes and the catalogue).
:class:`qpcontact.geometry.Cells` holds the inverse inertia (``1/I∥``, ``1/I⊥``) the contact
system uses.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def capsule_mass(lengths: Any, radii: Any, density: Any = 1.0) -> Any:
    """Mass of capsules of constant ``density``: ``density · (π ρ² l + 4/3 π ρ³)`` (a cylinder
    of length ``l`` and two hemispherical caps of radius ``ρ``) [mass]. Arrays broadcast;
    Python floats give a float."""
    return density * np.pi * radii**2 * (lengths + 4.0 / 3.0 * radii)


def capsule_volume(lengths: Any, radii: Any) -> Any:
    """Volume of capsules: ``π ρ² l + 4/3 π ρ³`` [length³] (:func:`capsule_mass` at density 1)."""
    return capsule_mass(lengths, radii, 1.0)


def capsule_footprint(lengths: Any, radii: Any) -> Any:
    """Area of a capsule lying in a plane, seen from above (a monolayer cell's footprint):
    ``2ρ l + π ρ²`` [length²] (a rectangle and two half discs). Arrays broadcast."""
    return 2.0 * radii * lengths + np.pi * radii**2


def inertia_times(axes: np.ndarray, lengths: np.ndarray, radii: np.ndarray, masses: np.ndarray,
                  vectors: np.ndarray) -> np.ndarray:
    """``I w`` for one (N, 3) vector per cell (e.g. the angular momentum ``L = I ω``), with the
    axisymmetric inertia tensor of model.md: ``I∥ = mρ²/2`` about the axis ``â`` and
    ``I⊥ = m(3ρ² + l²)/12`` about any axis normal to it, ``I = I∥ ââᵀ + I⊥(Id − ââᵀ)``."""
    along = np.einsum("ij,ij->i", axes, vectors)[:, None] * axes
    i_par = masses * radii**2 / 2.0
    i_perp = masses * (3.0 * radii**2 + lengths**2) / 12.0
    return i_par[:, None] * along + i_perp[:, None] * (vectors - along)
