"""Studies: the measurements around the per-step path, and the commands that run them.

Nothing in the other wings imports from here.

- :mod:`.scenes`: the one scene registry (:data:`SCENES`, :class:`Scene`, :func:`make_scene`)
  with the colony snapshots and hand-made scenes; :mod:`.catalogue` adds the stiff and extreme
  cases of the stability report (:data:`CATALOGUE`);
- :mod:`.harness`: what the comparison and the stability report share (:func:`prepare`,
  :func:`guarded`, :func:`write_csv`);
- commands: :mod:`.demo`, :mod:`.compare`, :mod:`.stability`, :mod:`.bench`, :mod:`.sweep`
  (``qpcontact COMMAND``); :mod:`.cluster`: Dask for the sweep, compare and stability (extra
  ``qpcontact[sweep]``, imported only by them);
- longer measurements run as modules: :mod:`.colony_benchmark` (error against run time over
  whole colony runs), :mod:`.colony_10k` (steps of a 10⁴-cell colony) and
  :mod:`.sweep_benchmark` (a sweep on Dask against its runs one after the other, a killed worker).
"""

# isort: off
from . import scenes  # the registry first: the catalogue registers into it
from . import catalogue
# isort: on
from .catalogue import CATALOGUE
from .harness import Prepared, guarded, prepare, write_csv
from .scenes import SCENES, Scene, make_scene, register_scene

__all__ = ["CATALOGUE", "SCENES", "Prepared", "Scene", "catalogue", "guarded", "make_scene", "prepare",
           "register_scene", "scenes", "write_csv"]
