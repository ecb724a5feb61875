"""The few array operations the model's laws need, for numpy and for casadi (private).

Each physical law in :mod:`toolkit.model` is written once over an array namespace ``xp``:
``xp=numpy`` (the default) evaluates it on arrays, ``xp=casadi`` builds the same expression
symbolically for casadi's integrators and optimizers. :func:`ops` maps the module a caller
passes to an object with the operations below, so a law never branches on the back end.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

__all__ = ["ops", "ArrayOps"]


class ArrayOps:
    """Operations of one back end: ``tanh exp sign fmin fmax sum concat const``.

    ``sum`` adds along the last axis (numpy) or the rows of a column (casadi); ``concat``
    joins a scalar and a vector into one state vector; ``const`` turns a numeric parameter
    array into the back end's constant type.
    """

    def __init__(self, module: ModuleType) -> None:
        self.module = module
        self.symbolic = module is not np
        if self.symbolic:
            self.tanh, self.exp, self.sign = module.tanh, module.exp, module.sign
            self.fmin, self.fmax = module.fmin, module.fmax
            self.const = module.DM
            self.sum = module.sum1
            self.concat = lambda head, tail: module.vertcat(head, tail)
        else:
            self.tanh, self.exp, self.sign = np.tanh, np.exp, np.sign
            self.fmin, self.fmax = np.minimum, np.maximum
            self.const = np.asarray
            self.sum = lambda a: np.sum(a, axis=-1)
            self.concat = lambda head, tail: np.concatenate((np.atleast_1d(head), tail))


_NUMPY = ArrayOps(np)
_CACHE: dict[int, ArrayOps] = {}


def ops(xp: Any = np) -> ArrayOps:
    """The :class:`ArrayOps` of ``xp`` (``numpy`` or the ``casadi`` module)."""
    if xp is np or xp is None:
        return _NUMPY
    found = _CACHE.get(id(xp))
    if found is None:
        found = _CACHE[id(xp)] = ArrayOps(xp)
    return found
