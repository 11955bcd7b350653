"""The run loop of a colony and its settings: ``qpcontact simulate`` and ``qpcontact plot``.

- :mod:`.settings`: the settings of a run, one table per concern (:class:`Settings`:
  :class:`ModelSettings`, :class:`RunSettings`, :class:`OutputSettings`,
  :class:`~qpcontact.timestep.PositionSettings`, :class:`VelocitySettings`), each described
  once; the one merge of their sources;
- :mod:`.simulate`: ``qpcontact simulate`` (:func:`run_colony` with :class:`Settings`), the
  loop as named phases;
- :mod:`.picture`: ``qpcontact plot``, a snapshot drawn again as its run drew it.

Imports the colony model, the per-timestep calls and what a run writes and reads
(docs/architecture.md).
"""

from .settings import ModelSettings, OutputSettings, RunSettings, Settings, VelocitySettings
from .simulate import Run, StepOutcome, run_colony

__all__ = ["ModelSettings", "OutputSettings", "Run", "RunSettings", "Settings", "StepOutcome", "VelocitySettings",
           "run_colony"]
