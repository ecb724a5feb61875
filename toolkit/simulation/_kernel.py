"""The kernel module the exact engines call, :mod:`toolkit._compiled.core`: compiled once the
process has done enough work to pay for compiling, its source run as Python before.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

from .. import _compiled

_COMPILED: list[ModuleType] = []     # the kernel module, once compiled in this process


def _kernels(work: int = 0) -> Any:
    """The kernel module :mod:`toolkit._compiled.core` to call: compiled, or its source run as
    Python while the process has not done enough work to pay for compiling
    (:func:`toolkit._compiled.kernels`; ``work``: this call's, about one unit per
    interpreted microsecond)."""
    if _COMPILED:
        return _COMPILED[0]
    module = _compiled.kernels("core", work)
    if "core" in _compiled.loaded():
        _COMPILED.append(module)
    return module
