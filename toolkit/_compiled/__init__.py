"""Compiled kernels: one source, run by numba compiled or by Python as written.

The kernel modules of this package (:mod:`.exact`: the exact method's event loop, dense
evaluator, no-event certificate and batch; :mod:`.contacts`: the Coulomb force on many
speeds) are plain Python functions over arrays and scalars. They import nothing heavy,
so the rest of the toolkit may import them freely (a scene that never simulates never loads
numba). :func:`load` returns a kernel module compiled: the first time, it replaces every
function the module lists in ``KERNELS`` by ``numba.njit(cache=True, **options)`` of that
very function. numba resolves a kernel's globals when it compiles it, so kernels that call
each other call the compiled versions; callers go through the module attribute
(``load("exact").ideal_piece(...)``), never through a name imported before :func:`load`;
a kernel calls only kernels of its own module.

There is no second implementation to keep in step: with ``NUMBA_DISABLE_JIT=1`` (numba's own
switch) :func:`load` returns the same functions uncompiled and the same source runs as
Python. The tests run the kernel tests both ways (``make test``).

Caching. ``cache=True`` stores the machine code beside the source (``__pycache__``), keyed on
the source file, so a fresh process loads it instead of compiling. Where that directory is
not writable (a read-only site-packages) numba falls back to its user-wide cache directory
(``NUMBA_CACHE_DIR`` when set, else the user cache directory); where no cache directory is
writable at all the kernels are compiled without a cache (each process pays the compile).
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["load", "loaded"]

_LOADED: dict[str, ModuleType] = {}


def load(name: str) -> ModuleType:
    """The kernel module ``toolkit._compiled.<name>`` with its kernels compiled (numba
    imported, machine code loaded from the cache or compiled, on the first call only)."""
    module = _LOADED.get(name)
    if module is None:
        module = importlib.import_module(f"{__name__}.{name}")
        _compile(module)
        _LOADED[name] = module
    return module


def loaded() -> tuple[str, ...]:
    """Names of the kernel modules compiled in this process (tests check laziness)."""
    return tuple(_LOADED)


def _compile(module: ModuleType) -> None:
    import numba

    if hasattr(module, "prange"):
        module.prange = numba.prange                          # a parallel loop when compiled
    for fname, options in module.KERNELS.items():
        function = getattr(module, fname)
        try:
            compiled = numba.njit(cache=True, **options)(function)
        except RuntimeError:        # no writable cache directory anywhere: compile per process
            compiled = numba.njit(cache=False, **options)(function)
        setattr(module, fname, compiled)
