"""Compiled kernels: one source, run by numba compiled or by Python as written.

The kernel modules (:mod:`.core` and the engines it gathers, :mod:`.lines`, :mod:`.planar`,
:mod:`.imm`, :mod:`.window`) are plain Python functions over arrays and scalars that import
nothing of the toolkit but :mod:`toolkit.laws`. :func:`load` returns one compiled: each
function a module lists in ``KERNELS`` replaced by ``numba.njit(cache=True, **options)`` of
itself, and the kernels it imports from the other kernel modules bound to theirs. Under ``NUMBA_DISABLE_JIT=1`` the same source runs
as Python. :func:`kernels` runs them as Python until a process has done enough work in them
to pay for compiling; :func:`warm` compiles before a timed call; :func:`budget_clock` is the
clock budgets read (compile time excluded); :func:`on_compile` reports compiles; :func:`parallel`
sets the threads of a parallel kernel. The policy and its reasons: docs/physics.md, section 11.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import time
from collections.abc import Callable, Iterator
from types import ModuleType
from typing import Any

import numpy as np

__all__ = ["COMPILE_AFTER", "MODULES", "budget_clock", "charge", "compile_seconds", "compiled",
           "cache_note", "ensure_compiled", "kernels", "load", "loaded", "on_compile", "parallel", "threads", "versions", "warm"]

_LOADED: dict[str, Any] = {}          # name -> the compiled module (or its _Interpreted)

#: The kernel modules of this package.
MODULES = ("core", "lines", "planar")

#: Work (in units of about one interpreted microsecond: a query time, a contact, an event
#: round) that a process runs through the kernels as Python before it compiles them. Loading
#: compiled kernels costs about 0.25 s even from a warm cache (numba and its compiler runtime),
#: more than a short run of the CLI spends in them interpreted; a process that keeps calling
#: them compiles once it has spent about that much interpreting (the ski-rental rule: never
#: more than twice the better choice in hindsight). Timed work does not wait for it
#: (:func:`warm`; the module docstring states the policy).
COMPILE_AFTER = 250_000
_WORK = [0]
_EAGER = os.environ.get("ACTIVE_CONTACTS_COMPILE", "").strip().lower() == "eager"


class _Interpreted:
    """A kernel module's kernels run as Python: each call from outside runs inside
    ``np.errstate(all="ignore")``, since compiled kernels overflow to inf and NaN silently and
    NumPy scalars would warn instead (the kernels' own results say what happened)."""

    def __init__(self, module: ModuleType) -> None:
        self._module = module

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._module, name)
        if name not in self._module.KERNELS:
            return value

        def call(*args: Any) -> Any:
            with np.errstate(all="ignore"):
                return value(*args)

        call.__name__ = call.__qualname__ = name
        call.__doc__ = value.__doc__
        setattr(self, name, call)               # (looked up once)
        return call


_INTERPRETED: dict[str, _Interpreted] = {}


def _interpreted(name: str) -> _Interpreted:
    module = _INTERPRETED.get(name)
    if module is None:
        module = _INTERPRETED[name] = _Interpreted(
            importlib.import_module(f"{__name__}.{name}"))
    return module


def kernels(name: str, work: int = 0) -> ModuleType | _Interpreted:
    """The kernel module ``toolkit._compiled.<name>`` to call now: compiled once this process
    has compiled it; before that its source run as Python, until the work charged (plus this
    call's ``work``) reaches :data:`COMPILE_AFTER`, when it is compiled (:func:`load`)."""
    module = _LOADED.get(name)
    if module is not None:
        return module
    _WORK[0] += work
    if _EAGER or _WORK[0] >= COMPILE_AFTER:
        return load(name)
    return _interpreted(name)


def ensure_compiled(*names: str) -> float:
    """Load the kernel modules ``names`` (default: every one of :data:`MODULES`) compiled now:
    from here on this process runs their machine code (numba compiles or loads each kernel
    at its first call). Returns the seconds this took (0 when already loaded)."""
    started = time.perf_counter()
    for name in names or MODULES:
        load(name)
    return time.perf_counter() - started


def warm(run: Callable[[], Any] | None = None, *names: str) -> float:
    """The timing policy in one call (module docstring): :func:`ensure_compiled` ``(*names)``,
    then ``run()`` once, untimed (the call about to be timed, on a short horizon: it compiles
    or loads exactly the kernels it uses). Returns the seconds both took: the one-time cost
    a report shows on its own."""
    started = time.perf_counter()
    ensure_compiled(*names)
    if run is not None:
        run()
    return time.perf_counter() - started


#: Work (about interpreted microseconds, as :func:`kernels` counts it) below which a parallel
#: kernel runs on one thread (waking threads costs more than they save).
PARALLEL_AFTER = 20_000


def threads(work: int = PARALLEL_AFTER) -> int:
    """Threads for a parallel kernel doing ``work``: 1 below :data:`PARALLEL_AFTER`, else the
    cores left idle by the others, ``floor(cores - load + 1)`` (the 1-minute load average
    counts this process), within ``[1, cores]``."""
    cores = os.cpu_count() or 1
    if work < PARALLEL_AFTER or cores == 1:
        return 1
    try:
        load = os.getloadavg()[0]
    except OSError:                 # (no load average on this platform)
        return cores
    return max(1, min(cores, int(cores - load + 1.0)))


@contextlib.contextmanager
def parallel(work: int) -> Iterator[int]:
    """Run the parallel kernels called inside on :func:`threads` ``(work)`` threads (numba's
    ``set_num_threads``, restored after); yields the number. Nothing to set while the
    kernels run as Python."""
    count = threads(work)
    numba = sys.modules.get("numba") if any(compiled(name) for name in MODULES) else None
    if numba is None:
        yield count
        return
    before = numba.get_num_threads()
    numba.set_num_threads(min(count, numba.config.NUMBA_NUM_THREADS))
    try:
        yield count
    finally:
        numba.set_num_threads(before)


def charge(work: int) -> None:
    """Count ``work`` units run interpreted toward :data:`COMPILE_AFTER`."""
    _WORK[0] += work


def load(name: str) -> ModuleType | _Interpreted:
    """The kernel module ``toolkit._compiled.<name>`` with its kernels compiled (numba
    imported, machine code loaded from the cache or compiled, on the first call only); under
    ``NUMBA_DISABLE_JIT=1`` its source run as Python."""
    module = _LOADED.get(name)
    if module is None:
        # OpenMP threads that wait passively (module docstring), unless the user chose.
        os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
        try:
            import numba
        except ImportError:          # a broken install: the same source, run as Python
            import warnings

            warnings.warn("numba cannot be imported: the toolkit's kernels run as Python "
                          "(correct, but slower); reinstall numba >= 0.60", stacklevel=2)
            module = _interpreted(name)
        else:
            if numba.config.DISABLE_JIT:
                module = _interpreted(name)
            else:
                module = importlib.import_module(f"{__name__}.{name}")
                _compile(module)
        _LOADED[name] = module
    return module


def compiled(name: str) -> ModuleType | None:
    """The kernel module ``toolkit._compiled.<name>`` if this process has compiled it (not
    run as Python under ``NUMBA_DISABLE_JIT`` or without numba), else None: for callers with
    a NumPy way of their own that only pays to switch to a kernel once it is machine code."""
    module = _LOADED.get(name)
    return module if isinstance(module, ModuleType) else None


def versions() -> dict[str, int]:
    """The number of compiled versions (numba's specializations, one per argument types) of
    each kernel this process has compiled or loaded from the cache, by kernel name."""
    return {function.__name__: len(dispatcher.signatures)
            for function, dispatcher in _DISPATCHERS.items() if dispatcher.signatures}


def loaded() -> tuple[str, ...]:
    """Names of the kernel modules compiled in this process (tests check laziness)."""
    return tuple(_LOADED)


# -- compile time: counted, reported to a listener, never charged to a budget ---------------

#: Compiles in this process: seconds of finished top-level compiles, nesting depth, start of
#: the open one (``perf_counter``), and the listener (:func:`on_compile`).
_COMPILING: dict[str, Any] = {"seconds": 0.0, "depth": 0, "since": 0.0, "listener": None, "installed": False}


def compile_seconds() -> float:
    """Seconds this process has spent compiling kernels so far (numba's own compile events;
    loading machine code from the cache is not compiling)."""
    open_part = time.perf_counter() - _COMPILING["since"] if _COMPILING["depth"] else 0.0
    return _COMPILING["seconds"] + open_part


def budget_clock() -> float:
    """The clock every wall-clock budget and every reported run time reads, s:
    ``time.perf_counter()`` less the time spent compiling kernels, so that a one-time compile
    is never charged to a budget nor counted in a reported time (it stands still while one
    runs; its cost is reported apart)."""
    state = _COMPILING
    return (state["since"] if state["depth"] else time.perf_counter()) - state["seconds"]


def on_compile(listener: Callable[[str, str, float], None] | None) -> Callable[[str, str, float], None] | None:
    """Call ``listener(event, kernel, seconds)`` around every top-level kernel compile of this
    process: ``("start", name, 0.0)`` before numba compiles ``name``, ``("end", name,
    seconds)`` after; None stops. Returns the previous listener. Loading machine code from the
    cache calls nothing."""
    previous = _COMPILING["listener"]
    _COMPILING["listener"] = listener
    return previous


def _install_compile_events(numba: ModuleType) -> None:
    """Listen to numba's ``numba:compile`` events (once per process)."""
    if _COMPILING["installed"]:
        return
    from numba.core import event

    class _Listener(event.Listener):          # numba's event API (numba.core.event)
        def on_start(self, ev: Any) -> None:
            compile_started(_kernel_name(ev))

        def on_end(self, ev: Any) -> None:
            compile_ended(_kernel_name(ev))

    event.register("numba:compile", _Listener())
    _COMPILING["installed"] = True


def _kernel_name(ev: Any) -> str:
    function = getattr(ev.data.get("dispatcher"), "py_func", None)
    return getattr(function, "__name__", "kernel")


def compile_started(kernel: str) -> None:
    """A compile of ``kernel`` starts: nested compiles (a kernel compiling the kernels it
    calls) count once, in the outermost, which stops :func:`budget_clock`."""
    if _COMPILING["depth"] == 0:
        _COMPILING["since"] = time.perf_counter()
        _tell("start", kernel, 0.0)
    _COMPILING["depth"] += 1


def compile_ended(kernel: str) -> None:
    """A compile of ``kernel`` ends (the outermost restarts :func:`budget_clock`)."""
    _COMPILING["depth"] -= 1
    if _COMPILING["depth"] == 0:
        seconds = time.perf_counter() - _COMPILING["since"]
        _COMPILING["seconds"] += seconds
        _tell("end", kernel, seconds)


def _tell(kind: str, kernel: str, seconds: float) -> None:
    listener = _COMPILING["listener"]
    if listener is not None:
        listener(kind, kernel, seconds)


def _compile(module: ModuleType) -> None:
    import numba

    _install_compile_events(numba)

    if hasattr(module, "prange"):
        module.prange = numba.prange                          # a parallel loop when compiled
    # The kernels it imports from the other kernel modules: those modules loaded first, their
    # compiled kernels bound here (numba resolves a kernel's globals when it compiles it).
    for fname, value in list(vars(module).items()):
        home = getattr(value, "__module__", None) or ""
        if (callable(value) and home != module.__name__ and home.startswith(__name__ + ".")
                and not hasattr(value, "py_func")):
            setattr(module, fname, getattr(load(home.rsplit(".", 1)[1]), value.__name__))
    for fname, options in module.KERNELS.items():
        function = getattr(module, fname)
        if hasattr(function, "py_func"):                      # (bound above)
            continue
        compiled = _DISPATCHERS.get(function)
        if compiled is None:
            try:
                compiled = numba.njit(cache=True, **options)(function)
                _CACHE.setdefault(module.__name__, getattr(compiled._cache, "_cache_path", None))
            except RuntimeError:    # no writable cache directory anywhere: compile per process
                compiled = numba.njit(cache=False, **options)(function)
                _CACHE.setdefault(module.__name__, None)
            _one_specialization(compiled)
            _saves_locked(compiled)
            _DISPATCHERS[function] = compiled
        setattr(module, fname, compiled)


def _one_specialization(dispatcher: Any) -> None:
    """Type a kernel called from another kernel by its arguments' plain types: a constant
    argument (``0``, ``True``) makes numba compile the callee once more for that literal value
    (``Literal[int](0)``), which no kernel needs (none asks for a literal); with plain types a
    kernel compiles once whatever its callers pass (numba's own conversions do the rest)."""
    from numba.core import types

    template = dispatcher.get_call_template

    def get_call_template(args: Any, kws: Any) -> Any:
        return template(tuple(types.unliteral(a) for a in args),
                        {k: types.unliteral(v) for k, v in kws.items()})

    dispatcher.get_call_template = get_call_template


def _saves_locked(dispatcher: Any) -> None:
    """Make ``dispatcher``'s cache saves hold a lock file beside its index, so that processes
    compiling at once (``active-contacts warm``, the test workers) cannot mix their versions.

    numba caches a kernel as one index (argument types -> data file) and a data file per
    version, and saves a version by reading the index, naming a data file the index does not
    list, writing the index, then the data: two processes saving two versions of one kernel
    at once can both take the same name, and the index then points one version at the other's
    machine code. Under the lock each save reads the index the previous one wrote."""
    cache_file = getattr(getattr(dispatcher, "_cache", None), "_cache_file", None)
    if cache_file is not None and hasattr(cache_file, "_index_path"):
        cache_file.__class__ = _locked(type(cache_file))


_LOCKED: dict[type, type] = {}


def _locked(kind: type) -> type:
    """``kind`` (numba's cache file class) with :meth:`save` under a lock file."""
    locked = _LOCKED.get(kind)
    if locked is None:
        from filelock import FileLock

        def save(self: Any, key: Any, data: Any) -> None:
            lock = FileLock(self._index_path + ".lock")
            try:
                lock.acquire()
            except (OSError, NotImplementedError):   # (a file system without locks: numba's save)
                kind.save(self, key, data)
                return
            try:
                kind.save(self, key, data)
            finally:
                lock.release()

        locked = _LOCKED[kind] = type(f"Locked{kind.__name__}", (kind,), {"save": save})
    return locked


_CACHE: dict[str, str | None] = {}       # kernel module -> the folder numba caches it in
#: Each kernel function compiled once per process, whichever modules list it (a kernel that
#: several modules import, such as a law of :mod:`toolkit.laws`, is one dispatcher).
_DISPATCHERS: dict[Callable[..., Any], Any] = {}


def cache_note() -> str | None:
    """Where the compiled kernels are cached when that is not beside their source (a read-only
    install: numba's user-wide cache folder, or none at all), in words; None when beside it."""
    here = os.path.join(os.path.dirname(__file__), "__pycache__")
    folders = {path for path in _CACHE.values()}
    if None in folders:
        return "no cache folder is writable: every process compiles the kernels again"
    elsewhere = sorted(path for path in folders if os.path.realpath(path) != os.path.realpath(here))
    if not elsewhere or os.environ.get("NUMBA_CACHE_DIR"):
        return None
    return f"the package folder is not writable: kernels cached in {elsewhere[0]}"
