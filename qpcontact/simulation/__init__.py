"""The run of a colony and its settings: ``qpcontact simulate`` and ``qpcontact plot``.

- :mod:`.settings`: the settings of a run, one table per concern (:class:`Settings`:
  :class:`ModelSettings`, :class:`RunSettings`, :class:`OutputSettings`,
  :class:`~qpcontact.timestep.PositionSettings`, :class:`~qpcontact.timestep.VelocitySettings`),
  each described once; the one merge of their sources;
- :mod:`.steps`: the step policy: the run's step function and its retries, what a step adds
  (sinking) and measures (mechanics);
- :mod:`.loop`: :func:`run_colony`, the loop as named phases;
- :mod:`.recording`: what a run records as it goes (history rows, snapshots, frames);
- :mod:`.signals`: the clean stop on Ctrl-C and SIGTERM;
- :mod:`.ranks`: one run over several MPI processes;
- :mod:`.simulate`: the command ``qpcontact simulate``;
- :mod:`.picture`: a run's pictures, and ``qpcontact plot``, a snapshot drawn again as its run
  drew it.

Imports the colony model, the per-timestep calls and what a run writes and reads
(docs/architecture.md).
"""

from typing import Any

from .. import moved
from .loop import Run, run_colony
from .settings import ModelSettings, OutputSettings, RunSettings, Settings
from .steps import StepOutcome


def __getattr__(name: str) -> Any:
    """The names that moved out of this package (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])


__all__ = ["ModelSettings", "OutputSettings", "Run", "RunSettings", "Settings", "StepOutcome", "run_colony"]
