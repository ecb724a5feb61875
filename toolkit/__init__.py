"""Active Contacts Toolkit: controllable friction from contacts that move at their own speeds.

The public API is what this module exports; everything else is private.
"""

from __future__ import annotations

from .contacts import ContactDistribution, ContactModel, ContactSet, Staircase
from .errors import (
    ParameterError,
    ParameterTypeError,
    SceneError,
    SceneFileNotFoundError,
    SolverError,
    ToolkitError,
)

__version__ = "0.1.0"

__all__ = [
    "ContactDistribution",
    "ContactModel",
    "ContactSet",
    "Staircase",
    "ParameterError",
    "ParameterTypeError",
    "SceneError",
    "SceneFileNotFoundError",
    "SolverError",
    "ToolkitError",
    "__version__",
]
