"""SIGINT (Ctrl-C) and SIGTERM stop a colony run cleanly (:class:`Interrupt`).

A signal that arrives during a step abandons that step (nothing of it is applied, the random
generator is put back: :func:`~qpcontact.simulation.loop.attempt_step`) and the run ends with
the state reached, which is saved; one that arrives between steps ends the run after the step.
A second Ctrl-C while the outputs are written does not stop the saving. Over MPI processes every
process stops at the same step (:class:`~qpcontact.simulation.ranks.CollectiveInterrupt`).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any

__all__ = ["Interrupt"]


class Interrupt:
    """Stop a run cleanly on SIGINT (Ctrl-C) or SIGTERM (module docstring).

    Use as a context manager around the loop; run each step inside :meth:`armed`. A signal that
    arrives while armed raises ``KeyboardInterrupt`` there (the caller abandons the step); at any
    other time it only sets :attr:`signal`, and the caller stops after what it is doing. Outside
    the main thread the handlers cannot be installed, and Python's own ``KeyboardInterrupt``
    takes their place.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.signal: int | None = None
        self._armed = False
        self._previous: dict[int, Any] = {}

    @property
    def requested(self) -> bool:
        return self.signal is not None

    def __enter__(self) -> Interrupt:
        if threading.current_thread() is threading.main_thread():
            for number in self.SIGNALS:
                self._previous[number] = signal.signal(number, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        self._previous.clear()

    def _handle(self, number: int, frame: FrameType | None) -> None:
        self.signal = number
        if self._armed:
            self._armed = False
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def armed(self) -> Iterator[None]:
        self._armed = True
        try:
            yield
        finally:
            self._armed = False

    def exit_status(self) -> int:
        """128 + the signal's number (130 for Ctrl-C), the shell's convention."""
        return 128 + (self.signal or signal.SIGINT)

