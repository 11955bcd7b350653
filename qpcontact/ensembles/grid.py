"""The grid of a sweep: seeds × the settings that vary (``--vary``, ``--seeds``, ``--zip``, or a
``[sweep]`` table of ``--config``), each run named by its varied values and its settings merged
as ``qpcontact simulate``'s are (:func:`qpcontact.simulation.settings.merge`).

- :func:`parse_vary`, :func:`varied_values`: a ``--vary NAME=LIST`` and its values, read as the
  setting's flag reads them;
- :class:`Grid`: the varied settings and the seeds; :func:`plan_runs`: every run of the grid,
  with its name (:func:`run_name`) and full settings;
- :func:`read_config`: the settings and the ``[sweep]`` table of a sweep's ``--config``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..cli import comma_list
from ..errors import InvalidArgumentError
from ..io.runs import read_toml
from ..schema import Layer, find_setting, known_names, parse_text
from ..simulation.settings import Settings, merge

__all__ = ["Grid", "grid_layer", "label", "parse_vary", "plan_runs", "read_config", "run_name", "varied_values"]


def parse_vary(text: str) -> tuple[str, list[str]]:
    """``NAME=V1,V2,...`` -> ``(NAME, [V1, V2, ...])`` (the values as text)."""
    name, equals, values = text.partition("=")
    if not equals or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE,VALUE,..., got {text!r}")
    return name.strip(), comma_list()(values)


def varied_values(name: str, values: Sequence[Any], source: str) -> tuple[str, list[Any]]:
    """``(name, values)``: the setting a varied name means (its one name,
    :attr:`qpcontact.schema.Setting.name`) and its values, read from text as its flag reads
    them (values from a TOML file are kept as they are; the merge checks them).

    Raises:
        InvalidArgumentError: an unknown name, the seed (``--seeds`` varies it), a value the
            setting refuses, or no values.
    """
    s = find_setting(Settings, name)
    if s is None:
        raise InvalidArgumentError(f"{source}: unknown setting {name!r} to vary; known: {known_names(Settings)} (by "
                                   "path table.key, or by flag without the dashes)")
    if s.name == "seed":
        raise InvalidArgumentError(f"{source}: vary the seed with --seeds (or seeds = [...] in [sweep])")
    if not isinstance(values, (list, tuple)) or not values:
        raise InvalidArgumentError(f"{source}: {name}: expected a non-empty list of values, got {values!r}")
    out = []
    for value in values:
        try:
            out.append(parse_text(s, value) if isinstance(value, str) and s.kind is not str else value)
        except InvalidArgumentError as exc:
            raise InvalidArgumentError(f"{source}: {name}={value}: {str(exc).split(': ', 1)[1]}") from None
    return s.name, out


def label(value: Any) -> str:
    """A value as it appears in a run's name (file-name safe)."""
    if isinstance(value, float):
        text = f"{value:.6g}"
    elif isinstance(value, (tuple, list)):  # a list setting (type_rates)
        text = "_".join(map(label, value)) or "none"
    else:
        text = str(value)
        if "/" in text or os.sep in text:
            text = Path(text).name
    return re.sub(r"[^A-Za-z0-9.+_-]", "_", text) or "_"


def run_name(varied: Mapping[str, Any]) -> str:
    """The run's folder name: ``name-value`` of each varied setting (the seed last), joined by
    ``__``."""
    return "__".join(f"{name}-{label(value)}" for name, value in varied.items())


@dataclass
class Grid:
    """What varies in a sweep: ``vary`` (setting -> values, in order), ``seeds``, ``zip`` (the
    lists side by side instead of their product)."""

    vary: dict[str, list[Any]]
    seeds: list[int]
    zip: bool = False

    def combinations(self) -> list[dict[str, Any]]:
        """Each run's varied values (the seed last)."""
        names = list(self.vary)
        lists = [self.vary[name] for name in names]
        if self.zip:
            if len({len(values) for values in lists}) > 1:
                raise InvalidArgumentError("--zip: the varied lists must have the same length, got "
                                           + ", ".join(f"{n}: {len(v)}" for n, v in self.vary.items()))
            rows = list(zip(*lists, strict=True)) if lists else [()]
        else:
            rows = list(itertools.product(*lists))
        return [{**dict(zip(names, row, strict=True)), "seed": seed} for row in rows for seed in self.seeds]


def plan_runs(base: Settings, grid: Grid) -> list[dict[str, Any]]:
    """Every run of the sweep (``name``, ``varied``, ``settings`` as tables), each run's settings
    ``base`` merged with its varied values (:func:`qpcontact.simulation.settings.merge`) and checked.

    Raises:
        InvalidArgumentError: a combination the settings refuse (naming the run), or two runs of
            the same name.
    """
    runs: list[dict[str, Any]] = []
    seen: dict[str, dict[str, Any]] = {}
    for varied in grid.combinations():
        name = run_name(varied)
        if name in seen:
            raise InvalidArgumentError(f"the grid has two runs named {name!r} ({seen[name]} and {varied}); vary "
                                       "distinct values")
        seen[name] = varied
        settings = merge([grid_layer(f"run {name}", varied)], base=base)
        runs.append({"name": name, "varied": varied, "settings": settings.to_tables(), "status": "pending", "error": ""})
    return runs


def grid_layer(source: str, varied: Mapping[str, Any]) -> Layer:
    """Varied values by name as a layer of the merge."""
    paths = {}
    for name, value in varied.items():
        s = find_setting(Settings, name)
        assert s is not None, name  # names come from varied_values
        paths[s.path] = value
    return Layer(source, paths, "grid")


def read_config(path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(the settings' tables, the [sweep] table)`` of a configuration file."""
    values = read_toml(path)
    table = values.pop("sweep", {})
    if not isinstance(table, dict):
        raise InvalidArgumentError(f"{path}: sweep must be a table ([sweep])")
    unknown = set(table) - {"seeds", "vary", "zip"}
    if unknown:
        raise InvalidArgumentError(f"{path}: [sweep] has unknown keys {', '.join(sorted(unknown))}; known: seeds, vary, "
                                   "zip")
    return values, table
