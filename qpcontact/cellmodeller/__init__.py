"""CellModeller's model scripts, unchanged, on qpcontact's physics.

- :mod:`.run`: the command ``qpcontact cellmodeller MODEL.py --cells N --out FOLDER`` and the
  library call :func:`run_model`;
- :mod:`.model`: loading a model and running its ``setup(sim)`` (:func:`load_model`), with the
  refusals of what qpcontact does not run;
- :mod:`.standins`: the names ``CellModeller.*`` a model imports, served only while it runs;
- :mod:`.state`: :class:`CellState`, a cell with CellModeller's attribute names;
- :mod:`.bridge`: the model as a qpcontact model hook (:class:`ModelHook`);
- :mod:`.pickles`: pickles in CellModeller's layout (:class:`PickleWriter`).

Above the colony model, the run loop and what a run writes (it drives
:func:`qpcontact.simulation.run_colony`). The guide: docs/cellmodeller.md.
"""

from .bridge import ModelHook, rates_of
from .model import Model, Simulation, load_model
from .pickles import PickleWriter
from .run import ModelRun, run_model
from .standins import ModelRefused
from .state import CellState

__all__ = ["CellState", "Model", "ModelHook", "ModelRefused", "ModelRun", "PickleWriter", "Simulation", "load_model",
           "rates_of", "run_model"]
