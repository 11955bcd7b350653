"""Model hooks: your own biology in a colony run, as CellModeller's model scripts do.

A hook is a function ``hook(colony, step)`` that :func:`qpcontact.simulation.run_colony` calls at
the start of every step, before the time step is chosen, with the colony (a
:class:`~qpcontact.Colony`: ``cells``, ``ids``, ``parent_ids``, ``rates``, ``owed``, ``time``,
``cell_types``, ``cell_data``) and the step index. It returns

- ``None``: nothing changes;
- a :class:`~qpcontact.Colony`: the colony to step from, e.g. with other growth rates
  (``colony.replace(rates=...)``), other cell types (``colony.replace(cell_types=...)``), its
  own per-cell arrays (``colony.replace(cell_data={**colony.cell_data, "signal": s})``), or
  with some cells removed (``colony.subset(keep)``, which keeps every per-cell field aligned);
- a :class:`StepControl`, which may also give extra momenta per cell (forces) and the division
  rule of this step.

On the command line: ``qpcontact simulate --hook my_model.py``, where ``my_model.py`` defines
``hook`` (:func:`load_hook`); ``examples/model_hook.py`` is a complete example.

A hook with a parameter named ``mechanics``, ``hook(colony, step, mechanics)``, is also given
the cells' mechanics over the step that led to the colony (a
:class:`~qpcontact.timestep.CellMechanics`: ``pressure`` (N,), ``stress`` (N, 3, 3), one per cell
of ``colony``: cells divide at the start of a step, so each has its own; zero before the first
step): growth that slows under pressure is
``colony.replace(rates=pressure_growth_rate(base, mechanics.pressure, ...))``
(:func:`qpcontact.colony.pressure_growth_rate`; ``examples/pressure_growth.py``). The colony's
``rates`` are what the next step grows with and what it keeps: compute them from a base rate
each step, not from the rates the hook set the step before, or the slowing compounds. A cell that
divides at the start of the step does not pass the rate the hook gave it on: its daughters grow
that step at the rate division draws for newborns (the run's ``rate``, with ``rate_noise``), and
the hook sets theirs from the next step on. (The same laws without a hook: the model settings
``pressure_growth`` and ``stall_pressure``, ``qpcontact simulate --pressure-growth linear``,
under which a newborn's first step is slowed by her mother's pressure.)

**Division and birth.** ``StepControl.dividing`` marks the cells that divide at the start of the
step whatever their length (a model's own rule, CellModeller's ``divideFlag``), and
``StepControl.division_length`` gives each cell its own length to divide at. A hook with an
attribute ``divided``, a function ``divided(before, after, born)`` (in a model file: a top-level
function ``divided``, which :func:`load_hook` attaches), is called after every division with
the colony before and after it and ``born = (mothers, first, second)``, the rows of the mothers in
``before`` and of their daughters in ``after`` (:func:`qpcontact.colony.growth.births`): it
returns None or the colony to step from, e.g. with the daughters' own numbers drawn at birth
(``cell_data``, ``rates``, ``owed``), as CellModeller's ``divide(parent, d1, d2)`` does. It must
keep the cells and their ids. ``StepControl.dt`` sets the step's time step (a fixed step, as
CellModeller's ``sim.dt``); a step that fails is still retried with half of it. Several
founders, without a snapshot: the hook returns at step 0 a colony of its own cells (any number,
their types and arrays), or a library run starts from one (``run_colony(settings, start=colony)``).

A model's per-cell state belongs in the colony: ``cell_types`` (an integer per cell, e.g.
CellModeller's ``cellType``) and ``cell_data`` (arrays by name, e.g. a ``targetVol`` or a
signal). Both daughters inherit their mother's rows at division, and the snapshots save them,
so a run resumed from one has them back. A hook that depends only on what it is given (the
colony with its types and arrays, the step, the mechanics, which the snapshots keep) continues
exactly when a run is resumed from a snapshot. A hook that needs random numbers can draw them
from a generator seeded by the cell id (``np.random.default_rng([seed, id])``) so that they do
not depend on the order of the calls. State a hook keeps elsewhere (a dictionary of its own,
a global) is not saved and is lost on ``--resume``. With per-type growth rates (the model
setting ``type_rates``) a cell whose type the hook changes keeps her rate; her daughters get
their type's.
"""

from __future__ import annotations

import importlib.util
import inspect
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InvalidArgumentError, ModelHookError
from ..timestep.mechanics import CellMechanics
from .growth import Colony, births, check_division_length


@dataclass
class StepControl:
    """What a hook sets for one step.

    Attributes:
        colony: the colony to step from (None: the one the hook was given).
        drive: (N, 7) generalized momenta ``(p, L, g)`` per cell added to the run's own drive
            (the sink towards the substrate in 3D), in momentum units [mass·µm/doubling time].
            In the overdamped dynamics of ``qpcontact simulate`` a cell without contacts then
            moves at ``p/m``: to push cell i at velocity v, ``drive[i, :3] = masses[i] * v``
            (:func:`push`). The growth column is ignored (growth is set by ``rates``). A cell
            that divides at the start of this step gives each daughter half of its row (as its
            momenta and mass: a pushed mother's daughters move at her velocity).
        division_length: the length [µm] at which each cell of the colony given divides, at the
            start of this step (before it moves: the step's contact solve then clears the
            daughters' overlap): a number or an (N,) array (None: the run's
            ``division_length``). Daughters need ``l/2 > radius``.
        dividing: an (N,) boolean mask of the cells of the colony given that divide at the start
            of this step, whatever their length (``division_length`` is then not used; None: the
            length rule).
        dt: the time step of this step [the run's time unit] (None: the run's rule).
    """

    colony: Colony | None = None
    drive: np.ndarray | None = None
    division_length: float | np.ndarray | None = None
    dividing: np.ndarray | None = None
    dt: float | None = None


#: A model hook: ``hook(colony, step) -> None | Colony | StepControl`` (or
#: ``hook(colony, step, mechanics)``: module docstring).
Hook = Callable[..., Colony | StepControl | None]


def wants_mechanics(hook: Hook) -> bool:
    """Whether ``hook`` takes a parameter named ``mechanics`` (module docstring)."""
    try:
        return "mechanics" in inspect.signature(hook).parameters
    except (TypeError, ValueError):  # a callable without a signature (some builtins)
        return False


def push(colony: Colony, velocities: Any) -> np.ndarray:
    """The (N, 7) drive that moves free cells at ``velocities`` ((N, 3) or (3,)) [µm/doubling
    time] in the overdamped dynamics: ``p = m v`` (fixed cells, ``m = inf``, get 0)."""
    masses = colony.cells.masses
    drive = np.zeros((colony.cells.n, 7))
    drive[:, :3] = np.where(np.isfinite(masses), masses, 0.0)[:, None] * np.broadcast_to(velocities, (colony.cells.n, 3))
    return drive


def apply_hook(hook: Hook | None, colony: Colony, step: int, mechanics: CellMechanics | None = None) -> StepControl:
    """Call ``hook`` (with ``mechanics`` if it takes them, :func:`wants_mechanics`) and check
    what it returns. The result always has ``colony`` set.

    Raises:
        ModelHookError: the hook raised (its exception is the cause), or returned something
            else than None, a Colony or a StepControl, or a drive or division length of the
            wrong shape or value.
    """
    try:
        if hook is None:
            answer = None
        elif wants_mechanics(hook):
            answer = hook(colony, step, mechanics=CellMechanics.zero(colony.cells.n, False) if mechanics is None
                          else mechanics)
        else:
            answer = hook(colony, step)
    except Exception as exc:  # the model's own code: reported with its traceback as the cause
        raise ModelHookError(f"model hook at step {step} raised {type(exc).__name__}: {exc}") from exc
    if answer is None:
        return StepControl(colony)
    if isinstance(answer, Colony):
        return StepControl(answer)
    if not isinstance(answer, StepControl):
        raise ModelHookError(f"model hook at step {step}: returned {type(answer).__name__}; expected None, a "
                                   "Colony or a StepControl")
    control = StepControl(colony if answer.colony is None else answer.colony, answer.drive, answer.division_length,
                          answer.dividing, answer.dt)
    if not isinstance(control.colony, Colony):
        raise ModelHookError(f"model hook at step {step}: StepControl.colony must be a Colony")
    n = control.colony.cells.n
    if control.drive is not None:
        control.drive = np.asarray(control.drive, dtype=float)
        if control.drive.shape != (n, 7) or not np.all(np.isfinite(control.drive)):
            raise ModelHookError(f"model hook at step {step}: drive must be a finite ({n}, 7) array, got shape "
                                       f"{control.drive.shape}")
    if control.division_length is not None:
        length = np.asarray(control.division_length, dtype=float)
        if length.shape not in ((), (n,)) or not np.all(np.isfinite(length) & (length > 0)):
            raise ModelHookError(f"model hook at step {step}: division_length must be a number or an ({n},) "
                                       "array, finite and > 0")
        try:  # the check of divide and of simulate's settings: daughters of a positive length
            check_division_length(length, control.colony.cells.radii)
        except InvalidArgumentError as exc:
            raise ModelHookError(f"model hook at step {step}: {exc}") from None
        control.division_length = length
    _check_division_and_dt(control, step, n)
    return control


def _check_division_and_dt(control: StepControl, step: int, n: int) -> None:
    """``StepControl.dividing`` (an (n,) boolean mask) and ``dt`` (finite, > 0) checked."""
    if control.dividing is not None:
        mask = np.asarray(control.dividing)
        if mask.dtype.kind != "b" or mask.shape != (n,):
            raise ModelHookError(f"model hook at step {step}: dividing must be an ({n},) boolean mask, got "
                                 f"{mask.dtype} values of shape {mask.shape}")
        if control.division_length is not None:
            raise ModelHookError(f"model hook at step {step}: give dividing or division_length, not both")
        control.dividing = mask
    if control.dt is not None:
        if isinstance(control.dt, bool) or not isinstance(control.dt, (int, float, np.number)) \
                or not (np.isfinite(control.dt) and control.dt > 0):
            raise ModelHookError(f"model hook at step {step}: dt must be a finite number > 0, got {control.dt!r}")
        control.dt = float(control.dt)


def apply_divided(hook: Hook | None, before: Colony, after: Colony, step: int) -> Colony:
    """The colony after a division (``after = divide(before, ...)``) as the hook's divide
    callback ``hook.divided(before, after, born)`` leaves it (module docstring), or ``after``
    when the hook has none or nobody divided.

    Raises:
        ModelHookError: the callback raised (its exception is the cause), or returned something
            else than None or a Colony of the same cells (same ids, in order).
    """
    callback = getattr(hook, "divided", None)
    if callback is None or after is before:
        return after
    try:
        answer = callback(before, after, births(before, after))
    except Exception as exc:  # the model's own code
        raise ModelHookError(f"model hook's divided at step {step} raised {type(exc).__name__}: {exc}") from exc
    if answer is None:
        return after
    if not isinstance(answer, Colony) or not np.array_equal(answer.ids, after.ids):
        raise ModelHookError(f"model hook's divided at step {step}: must return None or the colony it was given "
                             "with the same cells (ids, in order), changed only in their numbers")
    return answer


def _where(exc: Exception, path: Path) -> str:
    """``"line 3: SyntaxError: '(' was never closed"``: the error and the line of ``path`` (the
    model file) where it happened, when known."""
    line = exc.lineno if isinstance(exc, SyntaxError) and exc.filename == str(path) else None
    if line is None:
        frames = [f for f in traceback.extract_tb(exc.__traceback__) if f.filename == str(path)]
        line = frames[-1].lineno if frames else None
    text = exc.msg if isinstance(exc, SyntaxError) else str(exc)
    return f"{'' if line is None else f'line {line}: '}{type(exc).__name__}: {text}"


def load_hook(path: str | Path) -> Hook:
    """The function ``hook`` of a Python file (a model script).

    Raises:
        InvalidArgumentError: the file is missing, does not load (a SyntaxError, an ImportError
            or any other error while its top level runs: the message names the file, the line
            and the error, in one line; the error is the ``__cause__``), or defines no callable
            ``hook``. A command says this in one line, exit status 2, before the run starts.
    """
    path = Path(path)
    if not path.is_file():
        raise InvalidArgumentError(f"model {path}: no such file")
    spec = importlib.util.spec_from_file_location(f"qpcontact_model_{path.stem}", path)
    if spec is None or spec.loader is None:
        raise InvalidArgumentError(f"model {path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # the model's own error, but it stops the run before it starts
        raise InvalidArgumentError(f"model {path}: does not load: {_where(exc, path)}") from exc
    hook = getattr(module, "hook", None)
    if not callable(hook):
        raise InvalidArgumentError(f"model {path}: defines no function hook(colony, step)")
    divided = getattr(module, "divided", None)
    if divided is not None:
        if not callable(divided):
            raise InvalidArgumentError(f"model {path}: divided is not a function divided(before, after, born)")
        hook.divided = divided
    return hook
