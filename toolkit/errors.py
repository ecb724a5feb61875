"""The toolkit's error classes: one small hierarchy, each subclassing the matching built-in.

Every message follows one template (see :func:`parameter_message`)::

    The 'forces' parameter of ContactSet must be >= 0. Got -0.2 instead.

so a user learns the parameter, the rule and the value received.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "ToolkitError",
    "ParameterError",
    "ParameterTypeError",
    "SceneError",
    "SceneFileNotFoundError",
    "SolverError",
    "OutputError",
    "parameter_message",
]


class ToolkitError(Exception):
    """Base class of every error the toolkit raises on purpose."""


class ParameterError(ToolkitError, ValueError):
    """A parameter has the right type but a value that breaks a rule."""


class ParameterTypeError(ToolkitError, TypeError):
    """A parameter has the wrong type."""


class SceneError(ParameterError):
    """A scene file is malformed: unknown key, missing section, bad value."""


class SceneFileNotFoundError(ToolkitError, FileNotFoundError):
    """A scene file (or another input file) does not exist."""


class SolverError(ToolkitError, RuntimeError):
    """A numerical back end failed in a way no status can express."""


class OutputError(ToolkitError, OSError):
    """An output folder that cannot be written (found before any work)."""


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def parameter_message(name: str, owner: str, rule: str, value: Any) -> str:
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
    str
        ``"The 'forces' parameter of ContactSet must be >= 0. Got -0.2 instead."``
    """
    return f"The {name!r} parameter of {owner} must {rule}. Got {_show(value)} instead."
