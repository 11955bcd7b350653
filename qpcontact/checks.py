"""Checks of the arguments of the public functions: each raises the named error of
:mod:`qpcontact.errors` naming the argument and what was expected, never a raw ``TypeError``.

At the level of :mod:`qpcontact.errors`: every wing may import it. (The command-line
checks are in :mod:`qpcontact.cli`.)
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .errors import InvalidArgumentError, QPContactError


def flag(name: str, value: Any, *, allow_none: bool = False, error: type[QPContactError] = InvalidArgumentError) -> Any:
    """``value`` if it is a real bool (``numpy.bool_`` too), or None where allowed: a string such
    as ``"no"`` is truthy and must not switch anything on."""
    if value is None and allow_none:
        return None
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    expected = "True, False or None" if allow_none else "True or False"
    raise error(f"{name}: expected {expected}, got {value!r}")


def number(name: str, value: Any, *, minimum: float | None = None, maximum: float | None = None,
           open_minimum: bool = False, open_maximum: bool = False, allow_none: bool = False,
           error: type[QPContactError] = InvalidArgumentError) -> Any:
    """``value`` as a finite float within the bounds, or None where allowed. Strings, complex
    numbers, bools and arrays are refused (``"1e-6"`` is not a tolerance)."""
    if value is None and allow_none:
        return None
    interval = ""
    if minimum is not None or maximum is not None:
        low = "(" if open_minimum else "["
        high = ")" if open_maximum else "]"
        interval = f" in {low}{'-inf' if minimum is None else f'{minimum:g}'}, {'inf' if maximum is None else f'{maximum:g}'}{high}"
    expected = f"a finite real number{interval}{' or None' if allow_none else ''}"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise error(f"{name}: expected {expected}, got {value!r} ({type(value).__name__})")
    out = float(value)
    below = minimum is not None and (out <= minimum if open_minimum else out < minimum)
    above = maximum is not None and (out >= maximum if open_maximum else out > maximum)
    if not np.isfinite(out) or below or above:
        raise error(f"{name}: expected {expected}, got {value!r}")
    return out


def instance(name: str, value: Any, kind: type, what: str, error: type[QPContactError] = InvalidArgumentError) -> Any:
    """``value`` if it is a ``kind`` (e.g. the cells, the contacts)."""
    if not isinstance(value, kind):
        raise error(f"{name}: expected {what}, got {type(value).__name__}")
    return value


def mapping(name: str, value: Any) -> dict[str, Any]:
    """A mapping's items as a new dict (None: empty)."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise InvalidArgumentError(f"{name}: expected a dict of names to values, got {type(value).__name__}")
    return dict(value)


def sequence_of(name: str, value: Any, kind: type, what: str) -> list[Any]:
    """``value`` as a list of ``kind`` objects (a list or tuple; one object alone is refused)."""
    if isinstance(value, kind) or not isinstance(value, Sequence) or isinstance(value, str):
        raise InvalidArgumentError(f"{name}: expected a list of {what}, got {type(value).__name__} "
                                   f"(wrap a single one in a list)")
    for item in value:
        if not isinstance(item, kind):
            raise InvalidArgumentError(f"{name}: expected a list of {what}, got an item of type {type(item).__name__}")
    return list(value)


def real_array(name: str, value: Any, error: type[QPContactError]) -> np.ndarray:
    """``value`` as a float array: numbers only (no strings, no complex values, whose imaginary
    part a conversion would drop silently, no ragged nesting)."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nesting
        raise error(f"{name}: cannot be read as an array of numbers ({exc})") from None
    if raw.dtype.kind == "c":
        raise error(f"{name}: complex values are not accepted")
    if raw.dtype.kind not in "iuf":
        raise error(f"{name}: expected numbers, got an array of {raw.dtype} values")
    return raw.astype(float)


def integer(name: str, value: Any, *, minimum: int | None = None,
            error: type[QPContactError] = InvalidArgumentError) -> int:
    """``value`` as an int: a Python or NumPy integer (not a bool, not a float such as NaN or
    2.0: a count or an id is not a measurement)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise error(f"{name}: expected an integer, got {value!r} ({type(value).__name__})")
    out = int(value)
    if minimum is not None and out < minimum:
        raise error(f"{name}: expected an integer >= {minimum}, got {out}")
    return out


def integer_array(name: str, value: Any, error: type[QPContactError] = InvalidArgumentError) -> np.ndarray:
    """``value`` as an int64 array: an array (or list) of integers. Floats are refused, whole or
    not (an id of 0.5 or NaN would be cast to some other id without a word)."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nesting
        raise error(f"{name}: cannot be read as an array of integers ({exc})") from None
    if raw.dtype.kind not in "iu" or (raw.dtype.kind == "u" and raw.size and int(raw.max()) >= 2**63):
        raise error(f"{name}: expected integers, got an array of {raw.dtype} values")
    return raw.astype(np.int64)
