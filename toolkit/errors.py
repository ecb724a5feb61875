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
    "ParameterMessage",
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
