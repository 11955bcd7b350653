"""Assembly: the contact system handed to the solvers.

:func:`build_system` turns the colliding contacts into the sparse, reduced (only the unknowns
the scene needs), scaled (unit-free) :class:`ContactSystem` ``B̃ ỹ ≥ b̃`` and translates its
answers back to physical impulses. Imports only :mod:`qpcontact.geometry` (and the errors).
"""

from .system import PLANAR_TOLERANCE, SLOTS, ContactSystem, build_system, contact_jacobian, is_planar, slot_directions

__all__ = ["PLANAR_TOLERANCE", "SLOTS", "ContactSystem", "build_system", "contact_jacobian", "is_planar",
           "slot_directions"]
