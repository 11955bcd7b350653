"""Settings described once: each field of a settings dataclass carries its unit, its help and
its bounds (:func:`setting`), and what users see is generated from that one description.

A *settings tree* is a dataclass whose fields are *tables* (:func:`table`), each a dataclass of
described fields. From it this module generates

- the **names** (:func:`settings_of`): each setting's path ``table.key`` (the TOML location,
  ``[position] tolerance``), its name (``position_tolerance``: the table's prefix, if any, and
  the key) and its flag (``--position-tolerance``);
- the **checks** (:func:`check_fields`): type, bounds and choices of every field, each error
  naming the field and what was expected;
- the **conversions** of a value from text (flags, ``--vary``; :func:`parse_text`) and from a
  file (TOML, JSON; :func:`coerce`);
- the **command-line flags** (:func:`add_flags`, :func:`flags_given`) with the help text
  ``help [unit] (default: ...)``;
- the **merge** of layers of values (defaults, then each :class:`Layer` in order; later wins):
  :func:`merge`.

The rules that tie settings to each other (what applies to which run) belong to the tree's own
module (:mod:`qpcontact.simulation.settings`). Standard library only; importable from every wing.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import math
import types
import typing
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import InvalidArgumentError

#: The word for "no value" of an optional setting, in flags and in TOML files (which have no null).
NONE = "none"
_BOOL_WORDS = {"on": True, "yes": True, "true": True, "off": False, "no": False, "false": False}


@dataclass(frozen=True)
class Description:
    """What a setting means: its unit, a one-line help, its bounds or choices.

    Attributes:
        unit: the unit, as shown in brackets (``"µm"``, ``"fraction of the diameter"``);
            ``""`` for a choice or a flag.
        help: what it does, in a phrase (units and defaults are added where it is shown).
        above, at_least, below, at_most: bounds on a number (``> above`` ... ``<= at_most``).
        choices: the values it may take.
        path: a file path: resolved to an absolute path when given (so a run that stores it
            can continue from any directory).
    """

    unit: str
    help: str
    above: float | None = None
    at_least: float | None = None
    below: float | None = None
    at_most: float | None = None
    choices: tuple[Any, ...] | None = None
    path: bool = False

    def bounds(self) -> str:
        """The bounds in words (``"> 0"``, ``"in (0, 1)"``), "" if none."""
        low = f"({self.above:g}" if self.above is not None else (f"[{self.at_least:g}"
                                                                   if self.at_least is not None else None)
        high = f"{self.below:g})" if self.below is not None else (f"{self.at_most:g}]"
                                                                    if self.at_most is not None else None)
        if low and high:
            return f"in {low}, {high}"
        if low:
            return f"{'>' if low[0] == '(' else '>='} {low[1:]}"
        if high:
            return f"{'<' if high[-1] == ')' else '<='} {high[:-1]}"
        return ""


def setting(default: Any, *, unit: str, help: str, above: float | None = None, at_least: float | None = None,
            below: float | None = None, at_most: float | None = None, choices: Sequence[Any] | None = None,
            path: bool = False) -> Any:
    """A dataclass field described once (:class:`Description`): its default, unit, help and
    bounds or choices. Use as ``radius: float = setting(0.5, unit="µm", help="cell radius",
    above=0)``."""
    description = Description(unit, help, above, at_least, below, at_most,
                              None if choices is None else tuple(choices), path)
    return field(default=default, metadata={"described": description})


@dataclass(frozen=True)
class TableInfo:
    """A table of a settings tree: its help and the prefix of its flags and names (``""``: the
    keys are the names, so they must be unique across the unprefixed tables)."""

    help: str
    prefix: str = ""


def table(factory: Callable[[], Any], *, help: str, prefix: str = "") -> Any:
    """A field of a settings tree holding one table (a dataclass of described fields)."""
    return field(default_factory=factory, metadata={"table": TableInfo(help, prefix)})


@dataclass(frozen=True)
class Setting:
    """One setting of a tree, as users name it.

    Attributes:
        table, key: where it lives (``[table] key`` in TOML, ``settings.table.key`` in Python).
        name: its one name (``position_tolerance``; ``cells``): what ``--vary`` and run names use.
        flag: its command-line flag (``--position-tolerance``).
        kind: the value's type: ``int``, ``float``, ``str``, ``bool`` or ``tuple`` (a list of
            numbers, annotated ``tuple[float, ...]``: the bounds hold for each; written
            ``0.5,0.3`` as a flag, ``[0.5, 0.3]`` in TOML; empty, ``none``, for "not given").
        optional: it may be None (written ``none``).
        default: its default value.
        description: unit, help, bounds.
    """

    table: str
    key: str
    name: str
    flag: str
    kind: type
    optional: bool
    default: Any
    description: Description

    @property
    def path(self) -> str:
        """``table.key``."""
        return f"{self.table}.{self.key}"

    def help_text(self) -> str:
        """``help [unit] (default: value)``, as the flags show it."""
        unit = f" [{self.description.unit}]" if self.description.unit else ""
        return f"{self.description.help}{unit} (default: {show(self.default)})"


def show(value: Any) -> str:
    """A value as a user writes it (``none``, ``true``, ``0.001``)."""
    if value is None or value == ():
        return NONE
    if isinstance(value, tuple):
        return ",".join(map(show, value))
    if isinstance(value, bool):
        return "true" if value else "false"
    if value == "":
        return "\"\""
    return f"{value:g}" if isinstance(value, float) else str(value)


def _kind(annotation: Any) -> tuple[type, bool]:
    """``(type, optional)`` of a field's resolved annotation (``float | None`` -> float, True)."""
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        members = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(members) != 1:
            raise TypeError(f"a setting has one type (or it and None), got {annotation!r}")
        return members[0], True
    if typing.get_origin(annotation) is tuple:
        if typing.get_args(annotation) != (float, ...):
            raise TypeError(f"a list setting is a tuple[float, ...], got {annotation!r}")
        return tuple, False
    return annotation, False


_FIELDS: dict[Any, tuple[tuple[dataclasses.Field[Any], Description, type, bool], ...]] = {}
_SETTINGS: dict[Any, tuple[Setting, ...]] = {}


def described_fields(cls: Any) -> tuple[tuple[dataclasses.Field[Any], Description, type, bool], ...]:
    """The described fields of a dataclass: ``(field, description, type, optional)``."""
    if cls in _FIELDS:
        return _FIELDS[cls]
    hints = typing.get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        description = f.metadata.get("described")
        if description is not None:
            out.append((f, description, *_kind(hints[f.name])))
    _FIELDS[cls] = tuple(out)
    return _FIELDS[cls]


def settings_of(tree: Any) -> tuple[Setting, ...]:
    """Every setting of a settings tree, in table and field order.

    Raises:
        TypeError: two settings have the same name (a programming error).
    """
    if tree in _SETTINGS:
        return _SETTINGS[tree]
    out: list[Setting] = []
    for tf in dataclasses.fields(tree):
        info = tf.metadata.get("table")
        if info is None:
            continue
        cls = typing.cast(Callable[[], Any], tf.default_factory)()
        for f, description, kind, optional in described_fields(type(cls)):
            name = f"{info.prefix}_{f.name}" if info.prefix else f.name
            out.append(Setting(tf.name, f.name, name, "--" + name.replace("_", "-"), kind, optional,
                               getattr(cls, f.name), description))
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        raise TypeError(f"{tree.__name__}: settings share a name: {sorted({n for n in names if names.count(n) > 1})}")
    _SETTINGS[tree] = tuple(out)
    return _SETTINGS[tree]


def tables_of(tree: type) -> dict[str, TableInfo]:
    """The tables of a settings tree by name, in order."""
    return {f.name: f.metadata["table"] for f in dataclasses.fields(tree) if "table" in f.metadata}


def find_setting(tree: type, name: str) -> Setting | None:
    """The setting a user's name means: its path (``position.tolerance``), its name
    (``position_tolerance``) or its flag without the dashes (``position-tolerance``)."""
    for s in settings_of(tree):
        if name in (s.path, s.name, s.flag[2:]):
            return s
    return None


def known_names(tree: type) -> str:
    """Every setting, table by table: ``[model] radius, division_length; [run] cells, ...``."""
    return "; ".join(f"[{t}] " + ", ".join(s.key for s in settings_of(tree) if s.table == t) for t in tables_of(tree))


# -- values ---------------------------------------------------------------------------------
def check_value(s: Setting | tuple[str, Description, type, bool], value: Any) -> Any:
    """``value`` if it has the setting's type and keeps its bounds and choices (an integer is a
    number too, and becomes a float).

    Raises:
        InvalidArgumentError: naming the setting by its key and saying what was expected.
    """
    key, description, kind, optional = ((s.key, s.description, s.kind, s.optional) if isinstance(s, Setting) else s)
    if value is None and optional:
        return None
    if kind is tuple:
        return _check_list(key, description, value)
    words = {str: "a string", bool: "true or false", int: "an integer", float: "a number"}[kind]
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
        raise InvalidArgumentError(f"{key}: expected {words}{' or none' if optional else ''}, got {value!r}")
    number: Any = value  # an int or a float from here on, where kind says so
    if kind is float and not math.isfinite(number):
        raise InvalidArgumentError(f"{key}: expected a finite number, got {value!r}")
    d = description
    if kind in (int, float) and not ((d.above is None or number > d.above) and (d.at_least is None or number >= d.at_least)
                                     and (d.below is None or number < d.below)
                                     and (d.at_most is None or number <= d.at_most)):
        raise InvalidArgumentError(f"{key}: expected {words} {d.bounds()}, got {value!r}")
    if d.choices is not None and value not in d.choices:
        raise InvalidArgumentError(f"{key}: expected one of {', '.join(map(show, d.choices))}, got {value!r}")
    return value


def _check_list(key: str, description: Description, value: Any) -> tuple[float, ...]:
    """A list setting's value as a tuple of floats, each checked as a number with the bounds."""
    if not isinstance(value, (list, tuple)):
        raise InvalidArgumentError(f"{key}: expected a list of numbers (or none), got {value!r}")
    item = (key, description, float, False)
    try:
        return tuple(check_value(item, number) for number in value)
    except InvalidArgumentError as exc:
        raise InvalidArgumentError(f"{key}: expected a list of numbers, each {str(exc).split(': expected ', 1)[1]}"
                                   ) from None


def check_fields(obj: Any) -> None:
    """Check every described field of the dataclass instance ``obj`` (:func:`check_value`);
    a dataclass's ``__post_init__`` calls it. A list given as a list is stored as a tuple (so
    that the settings stay hashable and compare equal however they were given)."""
    for f, description, kind, optional in described_fields(type(obj)):
        value = check_value((f.name, description, kind, optional), getattr(obj, f.name))
        if kind is tuple:
            object.__setattr__(obj, f.name, value)


def parse_text(s: Setting, text: str) -> Any:
    """A value from text (a flag, ``--vary``): ``none`` for an optional setting, ``on``/``off``
    (``true``/``false``, ``yes``/``no``) for a flag, a number or a string; checked.

    Raises:
        InvalidArgumentError: it cannot be read as the setting's type, or is out of bounds.
    """
    if s.optional and text.strip().lower() == NONE:
        return None
    if s.kind is tuple:
        words = [] if text.strip().lower() in (NONE, "") else text.split(",")
        try:
            numbers = [float(word) for word in words]
        except ValueError:
            raise InvalidArgumentError(f"{s.key}: cannot read {text!r} as numbers separated by commas") from None
        return check_value(s, numbers)
    try:
        if s.kind is bool:
            value: Any = _BOOL_WORDS[text.strip().lower()]
        else:
            value = s.kind(text)
    except (KeyError, ValueError):
        raise InvalidArgumentError(f"{s.key}: cannot read {text!r} as "
                                   f"{ {bool: 'on or off', int: 'an integer', float: 'a number'}.get(s.kind, 'text')}"
                                   ) from None
    return check_value(s, value)


def coerce(s: Setting, value: Any) -> Any:
    """A value from a file (TOML, JSON): the string ``none`` for None, otherwise as it is;
    checked (:func:`check_value`)."""
    if s.optional and isinstance(value, str) and value.strip().lower() == NONE:
        value = None
    return check_value(s, value)


# -- layers and the merge -------------------------------------------------------------------
@dataclass
class Layer:
    """Values of some settings from one source, by path (``{"run.cells": 500}``).

    Attributes:
        source: where they come from, for messages (``"run.toml"``, ``"command line"``).
        values: path -> value.
        kind: ``"flags"`` (named by their flags in messages), ``"file"`` (by ``[table] key``),
            ``"state"`` (a snapshot's settings), ``"grid"`` (a sweep's varied values) or
            ``"python"``.
        relative_to: the folder that relative file paths of this layer are relative to (None:
            left as they are).
    """

    source: str
    values: dict[str, Any]
    kind: str = "python"
    relative_to: Path | None = None

    def label(self, s: Setting) -> str:
        """How this layer's source names a setting."""
        if self.kind == "flags":
            return s.flag
        if self.kind == "file":
            return f"[{s.table}] {s.key}"
        return s.name


def merge(tree: type, layers: Iterable[Layer], base: Any = None) -> Any:
    """The settings of ``base`` (default: the tree's defaults) with each layer's values replacing
    them in order (later wins), each value checked and each file path resolved
    (:attr:`Layer.relative_to`); the tree's own checks run on the result.

    Raises:
        InvalidArgumentError: an unknown path, or a value the setting or the tree refuses,
            naming the layer's source and the setting as that source names it.
    """
    current = tree() if base is None else base
    by_path = {s.path: s for s in settings_of(tree)}
    source = "defaults"
    for layer in layers:
        source = layer.source
        changes: dict[str, dict[str, Any]] = {}
        for path, value in layer.values.items():
            s = by_path.get(path)
            if s is None:
                raise InvalidArgumentError(f"{layer.source}: unknown setting {path!r}; known: {known_names(tree)}")
            try:
                value = coerce(s, value)
            except InvalidArgumentError as exc:
                raise InvalidArgumentError(f"{layer.source}: {layer.label(s)}: {str(exc).split(': ', 1)[1]}") from None
            if s.description.path and value and layer.relative_to is not None:
                value = str((layer.relative_to / value).resolve())
            changes.setdefault(s.table, {})[s.key] = value
        try:
            current = dataclasses.replace(current, **{t: dataclasses.replace(getattr(current, t), **values)
                                                      for t, values in changes.items()})
        except InvalidArgumentError as exc:  # a check across settings: named by the first setting it names
            message = str(exc)
            for s in settings_of(tree):
                for said in (s.name, s.key if s.table in changes else None):
                    if said and message.startswith(f"{said}:"):
                        message = layer.label(s) + message[len(said):]
                        break
                else:
                    continue
                break
            raise InvalidArgumentError(f"{source}: {message}") from None
    return current


def to_tables(settings: Any, keep: Callable[[Setting], bool] | None = None) -> dict[str, dict[str, Any]]:
    """The settings as ``{table: {key: value}}`` (the TOML and JSON form: a list setting as a
    list), optionally only those ``keep`` keeps; tables left empty are left out."""
    out: dict[str, dict[str, Any]] = {}
    for s in settings_of(type(settings)):
        if keep is None or keep(s):
            value = getattr(getattr(settings, s.table), s.key)
            out.setdefault(s.table, {})[s.key] = list(value) if s.kind is tuple else value
    return out


def values_of_tables(tree: type, tables: Mapping[str, Any], source: str) -> dict[str, Any]:
    """``{table: {key: value}}`` (a TOML file, stored settings) as ``{path: value}``.

    Raises:
        InvalidArgumentError: a table or key the tree does not have (listing those it has), or
            a table that is not a table.
    """
    known = tables_of(tree)
    out: dict[str, Any] = {}
    for name, values in tables.items():
        if name not in known:
            raise InvalidArgumentError(f"{source}: unknown table [{name}]; known: {known_names(tree)}")
        if not isinstance(values, Mapping):
            raise InvalidArgumentError(f"{source}: {name} must be a table ([{name}] with key = value lines)")
        for key, value in values.items():
            path = f"{name}.{key}"
            if find_setting(tree, path) is None:
                raise InvalidArgumentError(f"{source}: unknown setting {key!r} in [{name}]; known: {known_names(tree)}")
            out[path] = value
    return out


# -- command-line flags ---------------------------------------------------------------------
def _text_type(s: Setting) -> Callable[[str], Any]:
    def convert(text: str) -> Any:
        try:
            return parse_text(s, text)
        except InvalidArgumentError as exc:
            raise argparse.ArgumentTypeError(str(exc).split(": ", 1)[1]) from None

    convert.__name__ = {bool: "on/off", int: "integer", float: "number", tuple: "list"}.get(s.kind, "text")
    return convert


def add_flags(tree: type, parser: argparse.ArgumentParser, title: Callable[[str, TableInfo], str],
              refused: Mapping[str, str] | None = None) -> None:
    """A flag per setting of ``tree`` (``--name``), in one argument group per table (titled by
    ``title(table, info)``); a flag not given is absent from the parsed arguments
    (:func:`flags_given`). ``refused`` maps further flags to why they are refused: giving one is
    exit status 2 and that line (e.g. a flag of an earlier version, renamed)."""
    for name, info in tables_of(tree).items():
        group = parser.add_argument_group(title(name, info))
        for s in settings_of(tree):
            if s.table != name:
                continue
            metavar = None if s.description.choices else {int: "N", float: "X", bool: "on|off", tuple: "X,X,..."}.get(
                s.kind, "FILE" if s.description.path else "NAME")
            choices = s.description.choices
            # A flag setting given alone means on (--vtk); --vtk off says it.
            extra: dict[str, Any] = dict(nargs="?", const=True) if s.kind is bool else {}
            group.add_argument(s.flag, dest=s.path, type=_text_type(s), default=argparse.SUPPRESS, metavar=metavar,
                               choices=choices, help=s.help_text(), **extra)
    for flag, why in (refused or {}).items():
        parser.add_argument(flag, nargs="?", action=_Refused, why=why, help=argparse.SUPPRESS)


class _Refused(argparse.Action):
    """A flag that is refused with its reason (exit status 2, one line)."""

    def __init__(self, *args: Any, why: str, **kwargs: Any) -> None:
        self.why = why
        super().__init__(*args, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        parser.error(f"{option_string}: {self.why}")


def flags_given(tree: type, args: argparse.Namespace) -> dict[str, Any]:
    """The settings given as flags (:func:`add_flags`), by path."""
    given = vars(args)
    return {s.path: given[s.path] for s in settings_of(tree) if s.path in given}


def documented(cls: type) -> type:
    """Class decorator: append an ``Attributes:`` section generated from the described fields
    (``key: help [unit] (default: value; bounds)``) to the class's docstring, so that the API
    reference shows the one description too."""
    lines = []
    for f, d, _, optional in described_fields(cls):
        unit = f" [{d.unit}]" if d.unit else ""
        bounds = f"; {d.bounds()}" if d.bounds() else ""
        choices = f"; one of {', '.join(map(show, d.choices))}" if d.choices else ""
        lines.append(f"    {f.name}: {d.help}{unit} (default: {show(f.default)}{bounds}{choices}"
                     f"{'; or none' if optional else ''}).")
    cls.__doc__ = inspect.cleandoc(cls.__doc__ or "") + "\n\nAttributes:\n" + "\n".join(lines) + "\n"
    return cls
