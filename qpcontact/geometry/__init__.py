"""Geometry: the cells, the contacts between them and with static planes.

The lowest wing: it imports nothing of qpcontact but :mod:`qpcontact.errors`.

- :mod:`.cells`: :class:`Cells`, N capsules as arrays (positions, shapes, masses, momenta);
- :mod:`.shapes`: the capsule volume (and mass), footprint and inertia tensor, one formula each;
- :mod:`.contacts`: :func:`find_contacts` (KD-tree broad phase, vectorized segment narrow
  phase: :func:`select_contacts` then :func:`evaluate_contacts`), :class:`Contacts`,
  :func:`colliding` (the contacts to resolve and their ``b``);
- :mod:`.surfaces`: static planes (:class:`Plane`, :func:`substrate`, :func:`channel`) as
  one-sided contacts (:func:`plane_contacts`);
- :mod:`.overlap`: how much cells overlap (:func:`overlap_fractions`, :func:`largest_overlap`);
- :mod:`.motion`: exact rotations and :func:`move`, the cells at the end of a step;
- :mod:`.regions`: the split of a scene into regions, for contact detection shared by processes.
"""

from .cells import Cells, perpendicular_basis
from .contacts import (
    Contacts,
    candidate_pairs,
    colliding,
    concatenate,
    evaluate_contacts,
    find_contacts,
    narrow_phase,
    relative_normal_velocity,
    required_velocity_change,
    select_contacts,
)
from .motion import move, rotate
from .overlap import largest_overlap, overlap_fractions
from .shapes import capsule_footprint, capsule_mass, capsule_volume, inertia_times
from .surfaces import Plane, channel, evaluate_plane_contacts, plane_contacts, substrate

__all__ = [
    "Cells", "Contacts", "Plane", "candidate_pairs", "capsule_footprint", "capsule_mass", "capsule_volume", "channel", "evaluate_plane_contacts", "colliding",
    "concatenate", "evaluate_contacts", "find_contacts", "inertia_times", "largest_overlap", "move", "narrow_phase",
    "overlap_fractions", "perpendicular_basis", "rotate",
    "plane_contacts", "relative_normal_velocity", "required_velocity_change", "select_contacts", "substrate",
]
