"""Input checks shared by every public constructor and function (private).

Each check raises :class:`~toolkit.errors.ParameterError` or
:class:`~toolkit.errors.ParameterTypeError` with the message template of
:func:`toolkit.errors.parameter_message`; none uses ``assert``.
"""

from __future__ import annotations

import difflib
import numbers
from collections.abc import Iterable
from typing import Any

import numpy as np

from .errors import ParameterError, ParameterTypeError, parameter_message


def _first_bad(values: np.ndarray, bad: np.ndarray) -> Any:
    index = int(np.flatnonzero(bad.ravel())[0])
    return values.ravel()[index].item()


def as_float_array(value: Any, name: str, owner: str, *, ndim: int = 1,
                   allow_empty: bool = False, finite: bool = True) -> np.ndarray:
    """Convert to a read-only float64 array, refusing wrong types, shapes and NaN/inf."""
    if isinstance(value, (str, bytes)) or value is None:
        raise ParameterTypeError(parameter_message(name, owner, "be an array of numbers", value))
    if ndim == 1 and isinstance(value, numbers.Real) and not isinstance(value, bool):
        value = [value]
    if np.asarray(value).dtype == bool or np.iscomplexobj(value):
        raise ParameterTypeError(parameter_message(name, owner, "be an array of real numbers", value))
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterTypeError(
            parameter_message(name, owner, "be an array of numbers", value)) from None
    if array.ndim != ndim:
        raise ParameterError(parameter_message(
            name, owner, f"be {ndim}-dimensional", f"an array of shape {array.shape}"))
    if not allow_empty and array.size == 0:
        raise ParameterError(parameter_message(name, owner, "not be empty", value))
    if finite and not np.all(np.isfinite(array)):
        raise ParameterError(parameter_message(
            name, owner, "be finite (no NaN or inf)", _first_bad(array, ~np.isfinite(array))))
    array.setflags(write=False)
    return array


def as_float(value: Any, name: str, owner: str, *, low: float | None = None,
             high: float | None = None, low_open: bool = False,
             finite: bool = True) -> float:
    """Convert a scalar to float, refusing bools, strings, NaN and values out of range."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        if not (isinstance(value, np.ndarray) and value.ndim == 0):
            raise ParameterTypeError(parameter_message(name, owner, "be a real number", value))
    result = float(value)
    if np.isnan(result) or (finite and not np.isfinite(result)):
        raise ParameterError(parameter_message(name, owner, "be finite", value))
    if low is not None:
        if low_open and not result > low:
            raise ParameterError(parameter_message(name, owner, f"be > {low:g}", value))
        if not low_open and not result >= low:
            raise ParameterError(parameter_message(name, owner, f"be >= {low:g}", value))
    if high is not None and not result <= high:
        raise ParameterError(parameter_message(name, owner, f"be <= {high:g}", value))
    return result


def as_int(value: Any, name: str, owner: str, *, low: int | None = None) -> int:
    """Convert an integral scalar to int, refusing bools, floats with a fraction and strings."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if not (isinstance(value, float) and value.is_integer()):
            raise ParameterTypeError(parameter_message(name, owner, "be an integer", value))
    result = int(value)
    if low is not None and result < low:
        raise ParameterError(parameter_message(name, owner, f"be >= {low}", value))
    return result


def check_nonnegative(array: np.ndarray, name: str, owner: str) -> None:
    """Refuse any negative entry."""
    if np.any(array < 0):
        raise ParameterError(parameter_message(name, owner, "be >= 0", _first_bad(array, array < 0)))


def check_option(value: Any, name: str, owner: str, options: Iterable[str]) -> str:
    """Refuse an unknown option, suggesting the nearest valid one."""
    choices = list(options)
    if not isinstance(value, str):
        raise ParameterTypeError(parameter_message(name, owner, f"be one of {choices}", value))
    if value not in choices:
        raise ParameterError(parameter_message(name, owner, f"be one of {choices}", value)
                             + suggestion(value, choices))
    return value


def suggestion(word: str, choices: Iterable[str]) -> str:
    """Return ``" Did you mean 'x'?"`` for the nearest choice, or ``""`` when none is near."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f" Did you mean {close[0]!r}?" if close else ""
