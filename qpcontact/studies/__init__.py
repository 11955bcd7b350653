"""Studies: the measurements around the per-step path, and the commands that run them.

Nothing in the other wings imports from here.

- :mod:`.scenes`: the one scene registry (:data:`SCENES`, :class:`Scene`, :func:`make_scene`)
  with the colony snapshots and hand-made scenes; :mod:`.catalogue` adds the stiff and extreme
  cases of the stability report (:data:`CATALOGUE`);
- :mod:`.harness`: what the comparison and the stability report share (:func:`prepare`,
  :func:`guarded`);
- commands: :mod:`.demo`, :mod:`.compare`, :mod:`.stability`, :mod:`.bench`, :mod:`.grown`,
  :mod:`.convergence` (``qpcontact COMMAND``); ``compare`` and ``stability`` hand their runs to Dask with
  ``--scheduler``/``--workers`` (:mod:`qpcontact.ensembles.cluster`).

``qpcontact sweep`` (a user feature, not a study) is :mod:`qpcontact.ensembles.sweep`; the
developer's measurements (a sweep against its runs one after the other, before/after timings)
are scripts in the repository's ``benchmarks/`` folder, not installed.
"""

# isort: off
from . import scenes  # the registry first: the catalogue registers into it
from . import catalogue
# isort: on
from .catalogue import CATALOGUE
from .harness import Prepared, guarded, prepare
from .scenes import SCENES, Scene, make_scene, register_scene

__all__ = ["CATALOGUE", "SCENES", "Prepared", "Scene", "catalogue", "guarded", "make_scene", "prepare",
           "register_scene", "scenes"]
