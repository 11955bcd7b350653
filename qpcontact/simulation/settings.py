"""The settings of a colony run (``qpcontact simulate``, ``qpcontact sweep``, :func:`run_colony`),
nested by concern, each described once with its unit (:func:`qpcontact.schema.setting`):

- ``[model]``, :class:`ModelSettings` (flags ``--radius``, ...): the cells and how they grow;
- ``[run]``, :class:`RunSettings` (``--cells``, ...): size, dimensions, seed, the step, the time
  step;
- ``[output]``, :class:`OutputSettings` (``--snapshot-every``, ``--vtk``, ``--gif``,
  ``--color``): what a run writes besides its history and last state;
- ``[position]``, :class:`~qpcontact.timestep.PositionSettings` (``--position-*``): the
  position-level step;
- ``[velocity]``, :class:`~qpcontact.timestep.VelocitySettings` (``--velocity-*``): the
  velocity-level step.

:class:`Settings` holds one of each. Everything users see is generated from the descriptions
(:mod:`qpcontact.schema`): the flags of ``simulate`` and ``sweep`` (:func:`add_setting_flags`),
the TOML tables of ``config.toml`` and ``--config`` (:func:`file_layer`, :meth:`Settings.to_tables`),
the names of ``sweep --vary``, the checks, the help texts and the API reference. Each setting has
one name: its key in its table, with the table's prefix for the two step tables
(``[position] tolerance`` is ``--position-tolerance`` and ``position_tolerance``).

**One merge** (:func:`merge`): the defaults, then each source in order, later winning — a
snapshot's settings (``--start``/``--resume``), a TOML file (``--config``), the flags (and a
sweep's varied values). Then the checks that need the whole run: a setting given (by a flag, a
file or a sweep's grid) that does not apply to the run is refused, naming it and why
(:func:`refuse_unused`; a file's values equal to their defaults are let through, so that older
files listing every setting still load); a run continued from a snapshot refuses changes that
would corrupt it or be ignored (:func:`check_continuation`). Settings files and snapshots of
earlier versions — one flat table, ``n_cells = 2000``, ``solver = "clarabel"`` — load through
:data:`FORMER_NAMES`.

**Units.** Lengths in µm; masses in the units of volume (mass = volume); time in **doubling
times**: one time unit is the time in which a cell's cylinder length doubles when it grows at
the default rate ln 2 (``rate`` is in 1/time unit). A cell is born at ``division_length/2 −
radius`` (plus ``radius/3`` of owed length, :mod:`qpcontact.colony.growth`) and divides at
``division_length``, so a cell growing freely divides every :meth:`ModelSettings.cycle_time` =
1.27 time units at the defaults, and a colony doubles its cell count about every 1.3–1.4 time
units (contacts compress growth a little). To compare with a simulator or experiment whose cells
divide every T minutes: one time unit = T / ``cycle_time()`` minutes (T = 20 min: 15.7 min).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import schema
from ..colony.growth import Colony, check_division_length, expansion_time_step, growth_time_step
from ..colony.pressure import GROWTH_LAWS
from ..errors import InvalidArgumentError
from ..geometry.surfaces import Plane, substrate
from ..io.runs import read_toml
from ..schema import Layer, Setting, check_fields, documented, setting, settings_of, table
from ..solvers import get_solver
from ..timestep.position import PositionSettings, search_margin, uses_second_order
from ..timestep.step import VelocitySettings

__all__ = ["COLORS", "FORMER_NAMES", "ModelSettings", "OutputSettings", "RunSettings", "Settings", "VelocitySettings",
           "add_setting_flags", "check_continuation", "file_layer", "flag_layer", "merge", "refuse_unused",
           "stored_values"]


#: What ``colony.png`` can colour the cells by (``[output] color``; the colourings of
#: :func:`qpcontact.io.plots.colony_colors`).
COLORS = ("orientation", "pressure", "cell_type")
#: The unit of the cells' pressure of a run, and so of ``stall_pressure``: F is the force that moves
#: 1 µm³ of free cell at 1 µm per doubling time (docs/mechanics.md).
PRESSURE_UNITS = {2: "F/µm", 3: "F/µm²"}
#: The growth per step of the growth time step when the setting leaves it to the scene, by the
#: run's dimensions: the largest step whose colony stays within issue 32's targets of the
#: converged one (docs/statistics.md).
GROWTH_PER_STEP = {2: 0.05, 3: 0.00625}


@documented
@dataclass(frozen=True)
class ModelSettings:
    """``[model]``: the cells and how they grow (units: module docstring)."""

    radius: float = setting(0.5, unit="µm", above=0, help="cell radius")
    division_length: float = setting(
        4.0, unit="µm", above=0,
        help="cylinder length at which a cell divides; each daughter is born at division_length/2 − radius, so it "
             "must exceed 2 × radius")
    rate: float = setting(
        float(np.log(2.0)), unit="1/doubling time", at_least=0,
        help="mean elongation rate of a cell's cylinder length (exponential): ln 2, the default, doubles it in one "
             "time unit, and a cell growing freely then divides every 1.27 time units (ModelSettings.cycle_time)")
    rate_noise: float = setting(0.1, unit="dimensionless", at_least=0,
                                help="relative spread (standard deviation) of a newborn's rate around rate (or "
                                     "around her type's rate, type_rates)")
    type_rates: tuple[float, ...] = setting(
        (), unit="1/doubling time", above=0,
        help="per-type growth rates, one per cell type (Colony.cell_types, set by a model hook or a --start "
             "snapshot; daughters inherit their mother's type): a newborn's mean rate is her type's entry, the "
             "founder's that of type 0; replaces rate; none: every cell grows at rate")
    axis_noise: float = setting(0.02, unit="rad", at_least=0,
                                help="standard deviation of the turn of each daughter's axis at division")
    growth_inertia_ratio: float = setting(
        1000.0, unit="dimensionless, G/m", above=0,
        help="each cell's growth inertia G (its resistance to having its growth compressed; Cells.growth_inertia, "
             "a mass) as a multiple of its mass m: at 1 contacts compress growth as readily as they push cells, at "
             "1000 cells keep growing and push their neighbours outwards")
    sink_speed: float = setting(0.5, unit="µm/doubling time", at_least=0,
                                help="3D: every cell is driven towards the substrate at this speed")
    hook: str = setting(
        "", unit="", path=True,
        help="a Python file defining hook(colony, step), called at the start of every step (growth rates, division "
             "lengths, forces; examples/model_hook.py); stored as an absolute path")
    pressure_growth: str = setting(
        "off", unit="", choices=("off", *GROWTH_LAWS),
        help="growth slowed by each cell's pressure of the step before (qpcontact.colony.PressureGrowth): linear, "
             "rate × max(0, 1 − p/stall_pressure), growth stops at the stall pressure; exponential, "
             "rate × exp(−p/stall_pressure); off: growth does not feel pressure (a run is then bit for bit what it "
             "is without this setting)")
    stall_pressure: float = setting(
        100.0, unit="F/µm in 2D, F/µm² in 3D (F: docs/mechanics.md)", above=0,
        help="pressure-dependent growth: the pressure p_s of the growth law (linear: growth stops there; "
             "exponential: it is slowed e-fold there)")

    def __post_init__(self) -> None:
        check_fields(self)
        check_division_length(self.division_length, self.radius)  # the check of divide, too

    def cycle_time(self) -> float:
        """The time a cell growing freely at ``rate`` takes from birth to division [doubling
        times]: from ``a = L/2 − ρ`` with ``ρ/3`` owed, paid at twice its own growth (to ``a +
        2ρ/3``), then to ``L``: ``ln((a + 2ρ/3)/a)/(2r) + ln(L/(a + 2ρ/3))/r`` (1.27 at the
        defaults; infinite at rate 0)."""
        if self.rate == 0:
            return math.inf
        born = self.division_length / 2 - self.radius
        paid = born + 2 * self.radius / 3
        return math.log(paid / born) / (2 * self.rate) + math.log(self.division_length / paid) / self.rate


@documented
@dataclass(frozen=True)
class RunSettings:
    """``[run]``: how big the run grows, in how many dimensions, with which step and time step."""

    cells: int = setting(2000, unit="cells", at_least=1, help="grow until the colony has this many cells")
    dimensions: int = setting(
        2, unit="", choices=(2, 3),
        help="2: a monolayer in the xy-plane (planar unknowns only); 3: a biofilm on a substrate plane z = 0")
    seed: int = setting(1, unit="", at_least=0, help="random seed of the division noise")
    max_steps: int = setting(100_000, unit="steps", at_least=1,
                             help="stop at this step index (counted from the founder, across resumed runs)")
    step: str = setting(
        "position", unit="", choices=("position", "velocity"),
        help="position: no overlap beyond the position step's tolerance at the end of each step "
             "(qpcontact.timestep.position_step); velocity: contacts stop approaching at its start (qpcontact.step; "
             "the earlier step, kept for comparison)")
    time_step: str = setting(
        "auto", unit="", choices=("auto", "growth", "expansion"),
        help="growth: the fastest cell grows growth_per_step of its length per step; expansion: the colony's edge "
             "moves cfl diameters per step (at most max_dt); auto: growth for the position step, expansion for the "
             "velocity step")
    growth_per_step: float | None = setting(
        None, unit="fraction of the cell's length", above=0,
        help="growth time step: growth of the fastest-growing cell per step; none: by the scene, 0.05 in 2D and "
             "0.00625 in 3D (at 0.05 a 3D biofilm spread 9-30 percent less per step than in substeps, and grew "
             "0.6 µm taller by 2,000 cells; in 2D 0.05 is within 1.5 percent per step and within the targets of "
             "the converged colony: docs/model-notes.md)")
    max_dt: float = setting(0.02, unit="doubling times", above=0,
                            help="the longest expansion time step, and the step of a colony in which no cell grows")
    cfl: float = setting(
        0.3, unit="cell diameters", above=0,
        help="expansion time step: the colony's edge moves this far per step; velocity step: a step that turns a "
             "cell's tips further is retried with half the step")
    max_halvings: int = setting(
        3, unit="halvings", at_least=0,
        help="a step that fails (position: misses the overlap tolerance; velocity: turns a cell's tips further than "
             "cfl, or leaves more overlap than the overlap limit) is retried with half the step, at most this many "
             "times")

    def __post_init__(self) -> None:
        check_fields(self)


@documented
@dataclass(frozen=True)
class OutputSettings:
    """``[output]``: what a run writes besides its history and its last state (none of it
    changes the trajectory)."""

    snapshot_every: int = setting(100, unit="steps", at_least=0,
                                  help="save a snapshot every this many steps (0: only the last state)")
    vtk: bool = setting(False, unit="",
                        help="with each snapshot, a ParaView file (vtk/step_N.vtu, listed in colony.pvd with its "
                             "time); needs meshio: pip install 'qpcontact[vtk]'")
    gif: bool = setting(False, unit="", help="also write an animation colony.gif")
    color: str = setting(
        "orientation", unit="", choices=COLORS,
        help="what colony.png colours the cells by: orientation (the angle of each cell's axis), pressure (each "
             "cell's pressure over the last step, with a colour bar in F/µm in 2D, F/µm² in 3D; docs/mechanics.md) or "
             "cell_type (one colour per type)")

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class Settings:
    """Everything that defines a colony run, one table per concern (module docstring). Saved
    with the run (``config.toml``, every snapshot), read back by ``--config``, ``--resume`` and
    ``--start``.

    Make one with the tables (``Settings(run=RunSettings(cells=500))``) or by the settings' names
    (``Settings().updated({"cells": 500, "dimensions": 3})``).

    Attributes:
        model: :class:`ModelSettings`.
        run: :class:`RunSettings`.
        output: :class:`OutputSettings`.
        position: :class:`~qpcontact.timestep.PositionSettings`, the position step.
        velocity: :class:`VelocitySettings`, the velocity step.
    """

    model: ModelSettings = table(ModelSettings, help="the cells and how they grow")
    run: RunSettings = table(RunSettings, help="the run: size, dimensions, seed, the step and the time step")
    output: OutputSettings = table(OutputSettings, help="what the run writes besides its history and last state")
    position: PositionSettings = table(PositionSettings, prefix="position",
                                       help="the position-level step (--step position, the default)")
    velocity: VelocitySettings = table(VelocitySettings, prefix="velocity",
                                       help="the velocity-level step (--step velocity)")

    def __post_init__(self) -> None:
        """Reject settings no run can use, naming the setting."""
        for f in dataclasses.fields(self):
            value, info = getattr(self, f.name), f.metadata["table"]
            if not isinstance(value, f.default_factory):  # type: ignore[arg-type]
                raise InvalidArgumentError(f"{f.name}: expected {f.default_factory.__name__}, got "  # type: ignore[union-attr]
                                           f"{type(value).__name__}")
            try:
                check_fields(value)  # PositionSettings' bounds as described, too
            except InvalidArgumentError as exc:
                raise InvalidArgumentError(f"{info.prefix + '_' if info.prefix else ''}{exc}") from None
        if self.run.step == "position" and self.position.bounded and not get_solver(self.position.solver).bounds:
            raise InvalidArgumentError(f"position_solver: {self.position.solver!r} takes no bounds on the unknowns "
                                       "(use ipm, mprgp or a qpsolvers backend)")
        if self.run.step == "velocity":  # unknown, not installed or unsuitable: a named error now
            get_solver(self.velocity.solver).plan(self.velocity.formulation, self.velocity.form)

    # -- what the run does ------------------------------------------------------------------
    def time_step_rule(self) -> str:
        """``"growth"`` or ``"expansion"`` (``run.time_step``, ``auto`` resolved by the step)."""
        if self.run.time_step != "auto":
            return self.run.time_step
        return "growth" if self.run.step == "position" else "expansion"

    def growth_per_step(self) -> float:
        """The growth time step's growth per step [fraction of the cell's length]: the setting, or
        the scene's (``growth_per_step = none``: :data:`GROWTH_PER_STEP` of the run's dimensions)."""
        if self.run.growth_per_step is not None:
            return self.run.growth_per_step
        return GROWTH_PER_STEP[self.run.dimensions]

    def time_step_of(self, colony: Colony) -> float:
        """The time step of the next step from this colony [doubling times]."""
        if self.time_step_rule() == "growth":
            return growth_time_step(colony, growth_per_step=self.growth_per_step(), still=self.run.max_dt)
        return expansion_time_step(colony, max_dt=self.run.max_dt, cfl=self.run.cfl, dimensions=self.run.dimensions)

    def planes(self) -> list[Plane]:
        """The run's planes: the substrate ``z = 0`` in 3D, none in 2D."""
        return [] if self.run.dimensions == 2 else [substrate(0.0)]

    def step_options(self, dimensions: int | None = None) -> dict[str, Any]:
        """The options a run with ``step = "velocity"`` passes to :func:`qpcontact.colony.grow`
        and so to :func:`qpcontact.step`: solver, formulation, form, tolerance, margin, position
        correction, planes (the substrate in 3D), planar (2D), dynamics (and damping).

        ``step``'s own defaults are those of a single contact solve (no margin, no position
        correction); in your own loop, ``step(cells, dt, **Settings().step_options())`` steps as
        ``qpcontact simulate --step velocity`` does in 2D (a monolayer: ``planar=True``, which
        refuses cells out of the plane), and ``Settings().step_options(dimensions=3)`` (or the
        options of a settings object with ``dimensions = 3``) as it does in 3D (the substrate, no
        planar reduction).

        Args:
            dimensions: 2 or 3, the loop's; default ``run.dimensions`` (2 unless set).
        """
        if dimensions is None:
            dimensions = self.run.dimensions
        if dimensions not in (2, 3) or isinstance(dimensions, bool):
            raise InvalidArgumentError(f"dimensions: expected 2 or 3, got {dimensions!r}")
        v = self.velocity
        planar = dimensions == 2
        options: dict[str, Any] = dict(
            solver=v.solver, formulation=v.formulation, form=v.form, tolerance=v.tolerance, margin=v.margin,
            position_correction=v.position_correction, planes=[] if planar else [substrate(0.0)],
            planar=True if planar else None, dynamics=v.dynamics)
        if v.dynamics == "inertial":
            options["damping"] = v.damping
        return options

    def describe_step(self) -> str:
        """The step that runs, its solver and tolerance, in words (pictures, summaries):
        ``"position step, ipm at tolerance 0.001, overlap ≤ 0.01"``, and the search margin when
        the scene picked it (``margin = none``: ``", search margin 0.75 (by the scene)"``); a cap
        on turning or an aim gap, which change the colony (docs/model-notes.md), when set
        (``", turns capped at 0.2 diameters, aim 0.03"``); a second-order step says so
        (``", second order"``)."""
        if self.run.step == "position":
            p = self.position
            chosen = "" if p.margin is not None else \
                f", search margin {search_margin(p, self.run.dimensions == 2):g} (by the scene)"
            if self.run.growth_per_step is None and self.time_step_rule() == "growth":
                chosen += f", growth per step {self.growth_per_step():g} (by the scene)"
            bending = ", second order" if uses_second_order(p) else ""
            bending += "" if p.turn_limit is None else f", turns capped at {p.turn_limit:g} diameters"
            if p.aim != PositionSettings().aim:
                bending += f", aim {p.aim:g}"
            return (f"position step, {p.solver} at tolerance {p.tolerance:g}, overlap ≤ {p.overlap_tolerance:g}"
                    f"{bending}{chosen}")
        v = self.velocity
        return f"velocity step, {v.solver}/{v.formulation} at tolerance {v.tolerance:g}"

    def describe_growth(self) -> str:
        """The pressure-dependent growth, in words (pictures, summaries): ``"pressure growth
        off"`` or ``"pressure growth linear, stall pressure 100 F/µm"``."""
        m = self.model
        if m.pressure_growth == "off":
            return "pressure growth off"
        return (f"pressure growth {m.pressure_growth}, stall pressure {m.stall_pressure:g} "
                f"{PRESSURE_UNITS[self.run.dimensions]}")

    def unused(self, s: Setting) -> str:
        """Why setting ``s`` does not apply to this run ("" if it does)."""
        step = self.run.step
        if s.table in ("position", "velocity") and s.table != step:
            return f"a setting of the {s.table} step; this run takes {step} steps (--step {s.table} to use it)"
        rule = self.time_step_rule()
        if s.path == "run.growth_per_step" and rule != "growth":
            return f"used by the growth time step only; this run's time step is {rule}"
        if s.path == "run.cfl" and rule != "expansion" and step != "velocity":
            return ("used by the expansion time step (--time-step expansion) and the velocity step only; this run "
                    "takes position steps with the growth time step")
        if s.path == "model.sink_speed" and self.run.dimensions != 3:
            return "3D only (cells driven towards the substrate); this run is 2D"
        if s.path == "velocity.damping" and self.velocity.dynamics != "inertial":
            return "used by inertial dynamics only (--velocity-dynamics inertial)"
        if s.path == "model.rate" and self.model.type_rates:
            return "replaced by type_rates (a cell's mean rate is that of her type); give one or the other"
        if s.path == "model.stall_pressure" and self.model.pressure_growth == "off":
            return ("used by pressure-dependent growth only (--pressure-growth linear or exponential); this run's "
                    "pressure growth is off")
        return ""

    # -- stored and given values ------------------------------------------------------------
    def to_tables(self, *, applying: bool = False) -> dict[str, dict[str, Any]]:
        """``{table: {key: value}}`` (snapshots store all; ``applying``: only the settings that
        apply to this run, as ``config.toml`` shows them)."""
        return schema.to_tables(self, (lambda s: not self.unused(s)) if applying else None)

    def updated(self, values: Mapping[str, Any], source: str = "settings") -> Settings:
        """These settings with ``values`` replaced, by name (``cells``, ``position_tolerance``)
        or path (``run.cells``); each checked.

        Raises:
            InvalidArgumentError: an unknown name or a value the setting refuses, naming ``source``.
        """
        paths = {}
        for name, value in values.items():
            s = schema.find_setting(Settings, name)
            if s is None:
                raise InvalidArgumentError(f"{source}: unknown setting {name!r}; known: "
                                           f"{schema.known_names(Settings)}")
            paths[s.path] = value
        return merge([Layer(source, paths)], base=self)

    @classmethod
    def from_stored(cls, values: Mapping[str, Any], source: str) -> Settings:
        """The settings stored in a snapshot or a sweep (tables, or the flat table of earlier
        versions: :func:`stored_values`)."""
        return merge([Layer(source, stored_values(values, source), "state")])


# -- the one merge, and the checks of the whole run ---------------------------------------------
def merge(layers: Iterable[Layer], base: Settings | None = None) -> Settings:
    """The one merge of a run's settings: ``base`` (default: the defaults), then each layer in
    order, later winning (simulate: the snapshot's settings, ``--config``, the flags; sweep:
    ``--config``, the flags, then each run's varied values); each value checked, each file path
    made absolute (:func:`qpcontact.schema.merge`)."""
    return schema.merge(Settings, layers, base)


#: The names of the flat settings table of earlier versions (config.toml, snapshots, sweeps)
#: that are not a key of exactly one table now.
FORMER_NAMES = {
    "n_cells": "run.cells", "growth_inertia": "model.growth_inertia_ratio", "model": "model.hook",
    "position_solver": "position.solver", "position_tolerance": "position.tolerance",
    "solver": "velocity.solver", "tolerance": "velocity.tolerance", "margin": "velocity.margin",
}


def _former_path(name: str) -> str | None:
    if name in FORMER_NAMES:
        return FORMER_NAMES[name]
    matches = [s.path for s in settings_of(Settings) if s.key == name]
    return matches[0] if len(matches) == 1 else None


def stored_values(values: Mapping[str, Any], source: str) -> dict[str, Any]:
    """Settings as stored (``{table: {key: value}}``, or the flat ``{name: value}`` table of
    earlier versions, or both in one TOML file) as ``{path: value}``.

    Raises:
        InvalidArgumentError: an unknown table or name, listing the known ones.
    """
    tables = {k: v for k, v in values.items() if isinstance(v, Mapping)}
    out = schema.values_of_tables(Settings, tables, source)
    for name, value in values.items():
        if isinstance(value, Mapping):
            continue
        path = _former_path(name)
        if path is None:
            raise InvalidArgumentError(f"{source}: unknown setting {name!r}; known: {schema.known_names(Settings)} "
                                       "(or the flat names of earlier versions)")
        out[path] = value
    return out


def file_layer(path: Path, values: Mapping[str, Any] | None = None) -> Layer:
    """The settings of a TOML file (``--config``; read from ``path`` unless ``values`` are given),
    its file paths relative to its folder."""
    values = read_toml(path) if values is None else values
    return Layer(str(path), stored_values(values, str(path)), "file", relative_to=Path(path).resolve().parent)


def flag_layer(args: argparse.Namespace) -> Layer:
    """The settings given as flags (:func:`add_setting_flags`), file paths relative to the
    current directory."""
    return Layer("command line", schema.flags_given(Settings, args), "flags", relative_to=Path.cwd())


def refuse_unused(runs: Sequence[Settings], layers: Iterable[Layer]) -> None:
    """Refuse a setting given by a flag, a file or a sweep's grid that applies to none of
    ``runs`` (a file's value equal to the default is let through: it changes nothing).

    Raises:
        InvalidArgumentError: naming the setting as its source does, and why.
    """
    by_path = {s.path: s for s in settings_of(Settings)}
    for layer in layers:
        if layer.kind not in ("flags", "file", "grid"):
            continue
        for path, value in layer.values.items():
            s = by_path[path]
            if layer.kind == "file" and schema.coerce(s, value) == s.default:
                continue
            reasons = [run.unused(s) for run in runs]
            if all(reasons):
                raise InvalidArgumentError(f"{layer.source}: {layer.label(s)}: {reasons[0]}")


#: Settings a run continued from a snapshot keeps (a change would corrupt the state or be
#: ignored), and why.
KEPT_FROM_THE_STATE = {
    "run.dimensions": "the state is {value}D (a 2D run's cells lie in the plane z = 0 with planar unknowns, a 3D run "
                      "has the substrate plane): changing it would corrupt the run",
    "model.radius": "it sets the founder only; the snapshot's cells keep their radii",
    "model.growth_inertia_ratio": "it sets the founder only; the snapshot's cells keep their growth inertia",
    "run.seed": "the snapshot carries the random generator's state",
}
#: Settings a run continued in its own folder keeps, and why.
KEPT_IN_PLACE = {
    "run.step": "the run's history, its warm start and its time-step rule belong to its step ({value}); start a new "
                "run from the snapshot (--start SNAPSHOT --out ANOTHER_FOLDER) to change it",
}


def check_continuation(state: Settings, layers: Iterable[Layer], *, in_place: bool, has_generator: bool) -> None:
    """Refuse the changes a run continued from a snapshot cannot take (:data:`KEPT_FROM_THE_STATE`;
    in its own folder also :data:`KEPT_IN_PLACE`): given values that differ from ``state``, the
    snapshot's settings. All are named in one line.

    Raises:
        InvalidArgumentError: naming each setting, its source and why.
    """
    kept = {**KEPT_FROM_THE_STATE, **(KEPT_IN_PLACE if in_place else {})}
    if not has_generator:
        kept.pop("run.seed")  # a snapshot without a generator state takes the seed's
    by_path = {s.path: s for s in settings_of(Settings)}
    refused = []
    for layer in layers:
        if layer.kind not in ("flags", "file"):
            continue
        for path, value in layer.values.items():
            s = by_path[path]
            before = getattr(getattr(state, s.table), s.key)
            if path in kept and schema.coerce(s, value) != before:
                why = kept[path].format(value=schema.show(before))
                refused.append(f"{layer.source}: {layer.label(s)} {schema.show(value)}: {why}")
    if refused:
        raise InvalidArgumentError(f"a run continued from a snapshot keeps these settings: {'; '.join(refused)}")


def add_setting_flags(parser: argparse.ArgumentParser, title: str = "") -> None:
    """The flags of every setting, one group per table (titled ``[table] help``, with ``title``
    after it), and the flags of earlier versions refused with their new names."""
    current = {s.flag for s in settings_of(Settings)}
    refused: dict[str, list[Setting]] = {}
    for name, path in [*((s.key, s.path) for s in settings_of(Settings) if s.table in ("position", "velocity")),
                       *FORMER_NAMES.items()]:
        flag = "--" + name.replace("_", "-")
        if flag not in current:
            s = schema.find_setting(Settings, path)
            assert s is not None
            if s not in refused.setdefault(flag, []):
                refused[flag].append(s)
    def where(s: Setting) -> str:
        return f"{s.flag} (the {s.table} step's)" if s.table in ("position", "velocity") else s.flag

    why = {flag: ("each step has its own: " if len(found) > 1 else "use ") + " or ".join(map(where, found))
           for flag, found in refused.items()}
    schema.add_flags(Settings, parser, lambda table_name, info: f"[{table_name}] {info.help}{title}", why)
