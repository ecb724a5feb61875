"""Bad input and how the toolkit says so: one small hierarchy of errors, each subclassing the
matching built-in, the one message template, and the checks every constructor uses.

Every message follows one template (see :func:`parameter_message`)::

    The 'forces' parameter of ContactSet must be >= 0. Got -0.2 instead.

so a user learns the parameter, the rule and the value received; the error carries the
parameter's name (``error.parameter``). No check uses ``assert``.
"""

from __future__ import annotations

import difflib
import math
import numbers
from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = [
    "ToolkitError",
    "ParameterError",
    "ParameterTypeError",
    "SceneError",
    "SceneFileNotFoundError",
    "SolverError",
    "OutputError",
    "DeviceError",
    "parameter_message",
    "ParameterMessage",
    "as_float",
    "as_float_array",
    "as_int",
    "check_nonnegative",
    "check_option",
    "suggestion",
]


class ToolkitError(Exception):
    """Base class of every error the toolkit raises on purpose."""


class _ParameterNamed:
    """Mixin: the parameter and its owner, taken from a :func:`parameter_message` message.

    Attributes
    ----------
    parameter : str or None
        The parameter's name (``"forces"``); None when the message names none.
    owner : str or None
        The function, class or scene section that takes it (``"ContactSet"``).
    """

    parameter: str | None
    owner: str | None

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        message = args[0] if args else None
        self.parameter = getattr(message, "parameter", None)
        self.owner = getattr(message, "owner", None)


class ParameterError(_ParameterNamed, ToolkitError, ValueError):
    """A parameter has the right type but a value that breaks a rule (``.parameter`` names it)."""


class ParameterTypeError(_ParameterNamed, ToolkitError, TypeError):
    """A parameter has the wrong type (``.parameter`` names it)."""


class SceneError(ParameterError):
    """A scene file is malformed: unknown key, missing section, bad value."""


class SceneFileNotFoundError(ToolkitError, FileNotFoundError):
    """A scene file (or another input file) does not exist."""


class SolverError(ToolkitError, RuntimeError):
    """A numerical back end failed in a way no status can express."""


class OutputError(ToolkitError, OSError):
    """An output folder that cannot be written (found before any work)."""


class DeviceError(_ParameterNamed, ToolkitError, OSError):
    """A device of the live loop that cannot be opened (no such port, a busy one) or whose
    handshake disagrees with the scene (``.parameter`` names what was given)."""


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


class ParameterMessage(str):
    """An error message that remembers the parameter and owner it names (see
    :func:`parameter_message`); text added to it keeps them."""

    parameter: str
    owner: str

    def __new__(cls, text: str, parameter: str, owner: str) -> ParameterMessage:
        message = super().__new__(cls, text)
        message.parameter, message.owner = parameter, owner
        return message

    def __add__(self, other: str) -> ParameterMessage:
        return ParameterMessage(str(self) + other, self.parameter, self.owner)


def parameter_message(name: str, owner: str, rule: str, value: Any) -> ParameterMessage:
    """Format the single error template used everywhere.

    Parameters
    ----------
    name : str
        The parameter's name, e.g. ``"forces"``.
    owner : str
        The function, class or scene section that takes it, e.g. ``"ContactSet"``.
    rule : str
        What the value must satisfy, e.g. ``"be >= 0"``.
    value : object
        What was received; shortened to 80 characters.

    Returns
    -------
    ParameterMessage
        ``"The 'forces' parameter of ContactSet must be >= 0. Got -0.2 instead."``, a ``str``
        that carries ``name`` and ``owner``: an error raised with it has them as
        ``error.parameter`` and ``error.owner``.
    """
    return ParameterMessage(f"The {name!r} parameter of {owner} must {rule}. Got {_show(value)} instead.",
                            name, owner)


# -- input checks: each returns the cleaned value or raises with the template ------------------

def _first_bad(values: np.ndarray, bad: np.ndarray) -> Any:
    index = int(np.flatnonzero(bad.ravel())[0])
    return values.ravel()[index].item()


def as_float_array(value: Any, name: str, owner: str, *, ndim: int = 1,
                   allow_empty: bool = False, finite: bool = True) -> np.ndarray:
    """Convert to a read-only float64 array, refusing wrong types, shapes and NaN/inf."""
    if type(value) is np.ndarray and value.dtype == np.float64:
        array = value.copy()                # (a float array: the type checks below pass)
    else:
        if isinstance(value, (str, bytes)) or value is None:
            raise ParameterTypeError(parameter_message(name, owner, "be an array of numbers", value))
        if ndim == 1 and isinstance(value, numbers.Real) and not isinstance(value, bool):
            value = [value]
        try:
            probe = np.asarray(value)
        except ValueError:                  # nested sequences of unequal lengths
            raise ParameterError(parameter_message(
                name, owner, "be a rectangular array (nested sequences of equal lengths)", value)) from None
        if probe.dtype == bool or np.iscomplexobj(probe):
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
    if finite and not np.isfinite(array).all():
        raise ParameterError(parameter_message(
            name, owner, "be finite (no NaN or inf)", _first_bad(array, ~np.isfinite(array))))
    array.setflags(write=False)
    return array


def as_float(value: Any, name: str, owner: str, *, low: float | None = None,
             high: float | None = None, low_open: bool = False,
             finite: bool = True) -> float:
    """Convert a scalar to float, refusing bools, strings, NaN and values out of range."""
    if type(value) is not float and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
        if not (isinstance(value, np.ndarray) and value.ndim == 0):
            raise ParameterTypeError(parameter_message(name, owner, "be a real number", value))
    result = float(value)
    if math.isnan(result) or (finite and not math.isfinite(result)):
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
    if (array < 0).any():
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
