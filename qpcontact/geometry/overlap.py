"""How much cells overlap, as a fraction of the diameter: each contact's
(:func:`overlap_fractions`) and the largest of a scene's (:func:`largest_overlap`), the
measures the steps report and a run's retries read."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .cells import Cells
from .contacts import Contacts, concatenate, find_contacts
from .surfaces import plane_contacts

__all__ = ["largest_overlap", "overlap_fractions"]


def overlap_fractions(cells: Cells, contacts: Contacts) -> np.ndarray:
    """(K,) ``max(0, −d)/(ρ_a + ρ_b)``: each contact's overlap as a fraction of its diameter
    (``ρ_b = ρ_a`` for a static body)."""
    radius_b = np.where(contacts.cell_b >= 0, cells.radii[np.maximum(contacts.cell_b, 0)], cells.radii[contacts.cell_a])
    return np.maximum(0.0, -contacts.separation) / (cells.radii[contacts.cell_a] + radius_b)


def largest_overlap(cells: Cells, planes: Sequence[Any] = ()) -> float:
    """Largest overlap of two cells, or of a cell and a plane (:mod:`qpcontact.geometry.surfaces`), as a
    fraction of the diameter (:func:`overlap_fractions`; 0 when nothing overlaps)."""
    contacts = concatenate([find_contacts(cells), plane_contacts(cells, planes, 0.0)])
    return float(overlap_fractions(cells, contacts).max(initial=0.0))

