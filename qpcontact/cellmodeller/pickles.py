"""Pickles in CellModeller's layout: :class:`PickleWriter`.

``step-NNNNN.pickle``, as CellModeller's ``Simulator.writePickle`` writes it: a dict with
``cellStates`` (cell id → :class:`~qpcontact.cellmodeller.state.CellState`, with CellModeller's
attribute names), ``stepNum`` (the file's ``NNNNN``: the state after step ``NNNNN``'s physics,
counted from 0), ``lineage`` (daughter id → mother id, the whole run), ``moduleName`` and
``moduleStr`` (the model's name and source). An analysis script written for CellModeller's
pickles (load, walk ``cellStates``, read ``pos``, ``dir``, ``length``, ``cellType``, ``color``)
runs on them with qpcontact installed; ``qpcontact import-cellmodeller`` reads them back.
"""

from __future__ import annotations

import os
import pickle
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..io.cellmodeller import load_pickle, run_pickles
from .state import CellState


class PickleWriter:
    """Writes a run's pickles into ``folder`` (created if needed).

    Attributes:
        folder: where the pickles go.
        written: the files written, in order.
    """

    def __init__(self, folder: str | Path, model_name: str, model_source: str) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.model_name, self.model_source = model_name, model_source
        self.written: list[Path] = []

    def __call__(self, step_num: int, states: Sequence[CellState], lineage: Mapping[int, int]) -> Path:
        """Write ``step-{step_num:05d}.pickle`` atomically (a killed run leaves no half file)."""
        data = {"cellStates": {state.id: state for state in states}, "stepNum": int(step_num),
                "lineage": dict(lineage), "moduleStr": self.model_source, "moduleName": self.model_name}
        path = self.folder / f"step-{step_num:05d}.pickle"
        handle, temporary = tempfile.mkstemp(dir=self.folder, prefix=f".{path.name}.", suffix=".tmp")
        try:
            with os.fdopen(handle, "wb") as fh:
                pickle.dump(data, fh, protocol=pickle.HIGHEST_PROTOCOL)
            os.replace(temporary, path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise
        if path not in self.written:
            self.written.append(path)
        return path

    def drop_after(self, step_num: int) -> None:
        """Remove the pickles of steps after ``step_num`` (a run resumed from an earlier state)."""
        for number, path in run_pickles(self.folder).items():
            if number > step_num:
                path.unlink()

    def lineage(self) -> dict[int, int]:
        """The lineage of the latest pickle in the folder (empty if there is none): a resumed
        run's, so that its pickles keep the whole run's."""
        found = run_pickles(self.folder)
        if not found:
            return {}
        data = load_pickle(found[max(found)])
        lineage = data.get("lineage", {}) if isinstance(data, dict) else {}
        return {int(k): int(v) for k, v in lineage.items()}
