"""Sweeps: many seeded runs of one experiment, on this machine or on a Dask cluster.

An experiment (for example :class:`toolkit.experiments.MedianLaw`) says what one run is;
:func:`sweep` runs it ``runs`` times in chunks and gathers a table (one row per run) and the
experiment's summary statistics; :func:`bootstrap` gives their sampling uncertainty. Random
numbers are counter-based (:class:`RunKeys`), so the table is the same bit for bit in this
process, on a process pool or on a Dask cluster. Reproducibility, scheduling and interrupts:
docs/methods.md."""

from __future__ import annotations

import contextlib
import multiprocessing
import multiprocessing.connection
import pickle
import os
import signal
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from ._compiled import budget_clock
from ._compiled import warm
from ._forked import stop
from .errors import as_float, as_int, suggestion
from .errors import ParameterError, ParameterTypeError, parameter_message

if TYPE_CHECKING:       # the table type, imported only with the first sweep at run time
    import pandas as pd

__all__ = ["Experiment", "RunKeys", "SweepResult", "sweep", "run_keys", "bootstrap", "Bootstrap",
           "MAX_RUNS", "DEFAULT_CHUNK_SIZE", "MAX_RESAMPLES"]

#: Most runs one sweep may take (its table holds one row per run).
MAX_RUNS = 10_000_000
#: Runs per chunk unless the call says otherwise.
DEFAULT_CHUNK_SIZE = 4096
#: Most resamples one :func:`bootstrap` may draw.
MAX_RESAMPLES = 100_000
_OWNER = "sweep"


@runtime_checkable
class Experiment(Protocol):
    """What one sweep runs. Implementations are frozen dataclasses (picklable, so that a
    process pool or a Dask worker can run them)."""

    name: str

    def run(self, keys: RunKeys) -> dict[str, np.ndarray]:
        """Evaluate one chunk: one entry per column, each an array with one value per run."""
        ...

    def summarize(self, table: Any) -> dict[str, float]:
        """Summary statistics of the whole table (a pandas DataFrame)."""
        ...


@dataclass(frozen=True, eq=False)
class SweepResult:
    """The runs of one :func:`sweep`.

    Attributes
    ----------
    experiment : Experiment
    table : pandas.DataFrame
        One row per run, in run order; column ``run`` is the run index ``i``.
    summary : dict of str to float
        The experiment's summary statistics (e.g. the median-law slope).
    runs, seed, chunk_size : int
    scheduler : str
        ``"local"``, ``"processes"`` or ``"dask"``.
    wall_time : float, s
        The sweep's run time: local, of compiled kernels only (loaded, and the experiment's
        first run, before the clock: ``compile_time``); with a pool or Dask, the workers'
        start-up and their own compiling included.
    chunks : int
        Number of chunks the runs were split into.
    compile_time : float, s
        The one-time cost paid before the clock started (:func:`toolkit._compiled.warm`).
    """

    experiment: Experiment
    table: pd.DataFrame
    summary: dict[str, float]
    runs: int
    seed: int
    chunk_size: int
    scheduler: str
    wall_time: float
    chunks: int = field(default=0)
    compile_time: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (not the table): experiment name, runs, seed, scheduler,
        wall time and the summary statistics."""
        return {"experiment": self.experiment.name, "runs": self.runs, "seed": self.seed,
                "chunk_size": self.chunk_size, "scheduler": self.scheduler,
                "wall_time": self.wall_time, "compile_time": self.compile_time,
                "summary": dict(self.summary)}


@dataclass(frozen=True, eq=False)
class Bootstrap:
    """A statistic of a sweep and its bootstrap over the runs.

    Attributes
    ----------
    value : float
        The statistic on the sweep's own table.
    replicates : ndarray of shape (resamples,)
        The statistic on each resample of the runs (drawn with replacement, as many as the
        sweep has).
    """

    value: float
    replicates: np.ndarray

    @property
    def std(self) -> float:
        """Standard deviation of the replicates: the statistic's standard error."""
        return float(np.std(self.replicates, ddof=1))

    def interval(self, level: float = 0.95) -> tuple[float, float]:
        """The percentile interval holding ``level`` of the replicates."""
        level = as_float(level, "level", "Bootstrap.interval", low=0.0, low_open=True, high=1.0)
        lo, hi = np.percentile(self.replicates, [50 * (1 - level), 50 * (1 + level)])
        return float(lo), float(hi)

    def map(self, function: Callable[[np.ndarray], np.ndarray]) -> Bootstrap:
        """The bootstrap of ``function(statistic)`` (vectorized over the replicates), e.g. the
        calibration bias ``1.065 / slope - 1`` that would move a slope to the paper's."""
        return Bootstrap(float(function(np.asarray(self.value))), np.asarray(function(self.replicates), dtype=float))


def bootstrap(result: SweepResult, statistic: str | Callable[[Any], float], *, resamples: int = 1000,
              seed: int = 0) -> Bootstrap:
    """Bootstrap a statistic of a sweep over its runs.

    Parameters
    ----------
    result : SweepResult
    statistic : str or callable
        A key of the experiment's summary (recomputed by ``experiment.summarize`` on each
        resampled table), or a function of a table returning a float.
    resamples : int
        Resamples, ``2 .. MAX_RESAMPLES``.
    seed : int
        Seed of the resampling (``>= 0``).

    Returns
    -------
    Bootstrap
    """
    owner = "bootstrap"
    if not isinstance(result, SweepResult):
        raise ParameterTypeError(parameter_message("result", owner, "be a SweepResult", result))
    if isinstance(statistic, str):
        if statistic not in result.summary:
            raise ParameterError(parameter_message("statistic", owner, f"be one of {sorted(result.summary)}",
                                                   statistic) + suggestion(statistic, result.summary))
        key = statistic

        def compute(table: Any) -> float:
            return float(result.experiment.summarize(table)[key])
    elif callable(statistic):
        compute = statistic
    else:
        raise ParameterTypeError(parameter_message("statistic", owner, "be a summary key or a function of "
                                                   "the table", statistic))
    resamples = as_int(resamples, "resamples", owner, low=2)
    if resamples > MAX_RESAMPLES:
        raise ParameterError(parameter_message("resamples", owner, f"be <= {MAX_RESAMPLES}", resamples))
    rng = np.random.default_rng(as_int(seed, "seed", owner, low=0))
    table = result.table.reset_index(drop=True)
    rows = len(table)
    replicates = np.array([compute(table.iloc[rng.integers(0, rows, rows)].reset_index(drop=True))
                           for _ in range(resamples)])
    return Bootstrap(float(compute(table)), replicates)


#: Interpreted work (about us) of one Philox block of four draws (toolkit._compiled).
_BLOCK_WORK = 40
_MASK64 = (1 << 64) - 1


@dataclass(frozen=True)
class RunKeys:
    """The random numbers of runs ``start`` to ``stop - 1`` of a sweep with root ``seed``.

    Counter-based (Philox4x64-10, the generator of ``numpy.random.Philox``): the numbers of
    run ``i``'s stream ``s`` are those of ``Philox(counter=(0, 0, i, s), key=(seed mod 2^64,
    seed // 2^64))``, so they depend on ``(seed, i, s)`` only. :meth:`uniform` and
    :meth:`normal` draw a whole chunk at once (one compiled call); :meth:`generator` gives one
    run's stream as a ``numpy.random.Generator`` for experiments that draw run by run.

    Parameters
    ----------
    seed : int
        ``0 <= seed < 2**128``.
    start, stop : int
        The runs, ``0 <= start < stop``.
    """

    seed: int
    start: int
    stop: int

    def __len__(self) -> int:
        return self.stop - self.start

    @property
    def indices(self) -> np.ndarray:
        """The run indices, shape (runs,)."""
        return np.arange(self.start, self.stop)

    def _key(self) -> tuple[np.uint64, np.uint64]:
        return np.uint64(self.seed & _MASK64), np.uint64(self.seed >> 64)

    def uniform(self, stream: int, n: int, low: float = 0.0, high: float = 1.0) -> np.ndarray:
        """The first ``n`` draws of each run's stream ``stream``, uniform in ``[low, high)``
        (``low + (high - low) u``, as ``Generator.uniform``): shape (runs, n)."""
        from ._compiled import kernels

        out = np.empty((len(self), n))
        k0, k1 = self._key()
        kernels("core", _BLOCK_WORK * len(self) * ((n + 3) // 4)).philox_uniform(
            k0, k1, self.start, int(stream), out)
        if low != 0.0 or high != 1.0:
            out = low + (high - low) * out
        return out

    def normal(self, stream: int, n: int) -> np.ndarray:
        """``n`` standard normals per run from stream ``stream``: shape (runs, n). Box-Muller
        on consecutive pairs of uniforms ``(u, w)``: ``sqrt(-2 ln(1 - u)) (cos, sin)(2 pi w)``
        (not NumPy's ziggurat: the same law, other numbers)."""
        pairs = (n + 1) // 2
        u = self.uniform(stream, 2 * pairs)
        radius = np.sqrt(-2.0 * np.log1p(-u[:, 0::2]))
        angle = 2.0 * np.pi * u[:, 1::2]
        z = np.empty((len(self), 2 * pairs))
        z[:, 0::2] = radius * np.cos(angle)
        z[:, 1::2] = radius * np.sin(angle)
        return z[:, :n]

    def generator(self, j: int, stream: int = 0) -> np.random.Generator:
        """Run ``start + j``'s stream ``stream`` as a ``numpy.random.Generator`` (its
        ``random()`` draws are :meth:`uniform`'s)."""
        k0, k1 = self._key()
        return np.random.Generator(np.random.Philox(counter=[0, 0, self.start + j, stream],
                                                    key=[int(k0), int(k1)]))

    def run(self, j: int) -> RunKeys:
        """The keys of run ``start + j`` alone."""
        return RunKeys(self.seed, self.start + j, self.start + j + 1)

    def label(self, j: int) -> str:
        """``"run i"`` for messages."""
        return f"run {self.start + j}"


def run_keys(seed: int, start: int, stop: int) -> RunKeys:
    """The keys of runs ``start`` to ``stop - 1`` of a sweep with root ``seed`` (checked)."""
    seed = as_int(seed, "seed", "run_keys", low=0)
    start = as_int(start, "start", "run_keys", low=0)
    stop = as_int(stop, "stop", "run_keys", low=start + 1)
    if seed >= 2**128:
        raise ParameterError(parameter_message("seed", "run_keys", "be < 2**128", seed))
    return RunKeys(seed, start, stop)


def _run_chunk(experiment: Any, seed: int, start: int, stop: int) -> dict[str, np.ndarray]:
    columns = experiment.run(RunKeys(seed, start, stop))
    for name, values in columns.items():
        if np.shape(values) != (stop - start,):
            raise RuntimeError(f"Experiment {experiment.name!r} returned column {name!r} of shape "
                               f"{np.shape(values)} for {stop - start} runs.")
    return columns


#: The named schedulers (besides a Dask address ``tcp://host:port`` or a Client).
SCHEDULERS = ("processes",)


def _check_scheduler(scheduler: Any) -> str:
    """``"local"``, ``"processes"`` or ``"dask"`` for a valid ``scheduler``; a clear error
    otherwise (a string must be ``"processes"`` or an address with ``://``)."""
    if scheduler is None:
        return "local"
    if isinstance(scheduler, str):
        if scheduler == "processes":
            return "processes"
        if "://" in scheduler:
            return "dask"
        raise ParameterError(parameter_message(
            "scheduler", _OWNER, "be None, 'processes' or a Dask scheduler address tcp://host:port",
            scheduler) + suggestion(scheduler, SCHEDULERS))
    distributed = __import__("sys").modules.get("distributed")
    if distributed is not None and isinstance(scheduler, distributed.Client):
        return "dask"
    raise ParameterTypeError(parameter_message(
        "scheduler", _OWNER, "be None, 'processes', a Dask address tcp://host:port or a "
        "distributed.Client", scheduler))


def _client(scheduler: Any) -> Any:
    try:
        import distributed   # optional extra: imported only for a Dask scheduler
    except ImportError:
        raise ParameterError(parameter_message(
            "scheduler", _OWNER, "name a Dask scheduler only where dask.distributed is "
            "installed (pip install 'active-contacts[dask]')", scheduler)) from None
    if isinstance(scheduler, distributed.Client):
        return scheduler, False
    try:
        return distributed.Client(scheduler, timeout=10), True
    except (OSError, TimeoutError, ValueError, TypeError, AssertionError) as error:
        raise ParameterError(parameter_message(
            "scheduler", _OWNER, f"be the address of a reachable Dask scheduler ({error})",
            scheduler)) from None


@contextlib.contextmanager
def _terminate_interrupts() -> Iterator[None]:
    """While a sweep runs (in the main thread), SIGTERM interrupts it as Ctrl-C does
    (``KeyboardInterrupt``), so that either stops the workers and leaves nothing behind; the
    previous handler is back afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    before = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


@contextlib.contextmanager
def _interrupts_held() -> Iterator[None]:
    """While a worker starts, Ctrl-C and SIGTERM are held back, never lost:

    - SIGINT is blocked in this thread, so the new interpreter inherits it blocked and keeps
      it so for its whole life: a Ctrl-C reaching the whole process group never raises in a
      worker, not even while it imports (the parent stops the workers);
    - here, both signals are only noted while the block runs (another thread may receive them
      and Python still raises in this one), and acted on as they would have been once it ends,
      so a start is never broken off half written.
    """
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    held: list[int] = []
    handlers = {signum: signal.signal(signum, lambda signum, frame: held.append(signum))
                for signum in (signal.SIGINT, signal.SIGTERM)}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)    # (a blocked SIGINT is noted now)
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    if held:
        handler = handlers[held[0]]
        if callable(handler):
            handler(held[0], None)                  # as if it came now: KeyboardInterrupt
        elif handler == signal.SIG_DFL:
            os.kill(os.getpid(), held[0])


def _pool_worker(connection: Any) -> None:
    """A pool worker: chunks ``(j, experiment, seed, a, b)`` in, ``(j, columns, error)`` out,
    until ``None``. Ctrl-C in a terminal reaches every process of its group; the parent stops
    the workers itself (:func:`_run_pool`), so they ignore it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        while True:
            task = connection.recv()
            if task is None:
                return
            j, experiment, seed, a, b = task
            try:
                reply = (j, _run_chunk(experiment, seed, a, b), None)
            except Exception as error:              # (reported to the parent, raised there)
                reply = (j, None, error)
            try:
                connection.send(reply)
            except (TypeError, AttributeError, pickle.PicklingError):   # it does not pickle
                connection.send((j, None, RuntimeError(repr(reply[2]))))
    except (EOFError, OSError):                     # the parent has gone: no one to tell
        return


def _run_pool(experiment: Any, seed: int, bounds: list[tuple[int, int]], workers: int,
              done: Any) -> None:
    """The chunks on ``workers`` fresh interpreters ("spawn": a forked child of a process whose
    compiled kernels started OpenMP threads would be killed), each fed one chunk at a time
    through a pipe of its own.

    No thread reads for the parent (a ``concurrent.futures`` pool's does, and it blocks for
    good on a result half written by a worker terminated mid-send): the parent waits on the
    workers' pipes and sentinels itself. Any exception here, an interrupt included, terminates
    the workers and waits for them (no process left behind) before it propagates; a worker
    that dies on its own is reported, not waited for.
    """
    context = multiprocessing.get_context("spawn")
    # multiprocessing's resource tracker unblocks SIGINT as it starts, which would let the
    # workers started in the same hold inherit it unblocked: it starts first, outside.
    from multiprocessing import resource_tracker
    resource_tracker.ensure_running()
    tasks = iter(enumerate(bounds))
    pool: list[tuple[Any, Any]] = []
    busy: dict[Any, Any] = {}                          # connection -> its worker process
    fed: set[Any] = set()                              # connections sent a task or the end

    def feed(process: Any, connection: Any) -> None:
        fed.add(connection)
        task = next(tasks, None)
        if task is None:
            connection.send(None)
            busy.pop(connection, None)
        else:
            j, (a, b) = task
            connection.send((j, experiment, seed, a, b))
            busy[connection] = process

    try:
        for _ in range(workers):
            connection, child = context.Pipe()
            process = context.Process(target=_pool_worker, args=(child,), daemon=True)
            with _interrupts_held():
                process.start()
                child.close()
                pool.append((process, connection))
            feed(process, connection)
        while busy:
            sentinels = {process.sentinel: process for process in busy.values()}
            for ready in multiprocessing.connection.wait([*busy, *sentinels]):
                if ready in sentinels:
                    if any(busy.get(c) is sentinels[ready] and c.poll() for c in busy):
                        continue                       # (its last result is still to read)
                    raise RuntimeError(f"a sweep worker (pid {sentinels[ready].pid}) died "
                                       f"with exit code {sentinels[ready].exitcode}")
                j, columns, error = ready.recv()
                if error is not None:
                    raise error
                done(j, columns)
                feed(busy[ready], ready)
    finally:
        for process, connection in pool:               # (one never fed may be starting still)
            stop(process, connection, busy=connection in busy or connection not in fed)


def _run_dask(experiment: Any, seed: int, bounds: list[tuple[int, int]], scheduler: Any,
              done: Any) -> None:
    """The chunks on a Dask cluster; an exception here, an interrupt included, cancels the
    chunks still queued or running there (the cluster's workers are not ours to stop)."""
    client, own = _client(scheduler)
    futures: dict[Any, int] = {}
    try:
        from distributed import as_completed as dask_completed
        futures = {client.submit(_run_chunk, experiment, seed, a, b, pure=False): j
                   for j, (a, b) in enumerate(bounds)}
        for future in dask_completed(list(futures)):
            done(futures[future], future.result())
    except BaseException:
        if futures:
            client.cancel(list(futures), force=True)
        raise
    finally:
        if own:
            client.close()


def _progress(total: int, enabled: bool, name: str) -> Any:
    if not enabled:
        return None
    from tqdm import tqdm   # only when a bar is shown
    return tqdm(total=total, desc=name, unit="run", leave=False)


def sweep(experiment: Experiment, runs: int, *, seed: int = 0, scheduler: Any = None,
          workers: int | None = None, chunk_size: int | None = None,
          progress: bool = False) -> SweepResult:
    """Run ``experiment`` ``runs`` times with reproducible seeds; gather a tidy table.

    Parameters
    ----------
    experiment : Experiment
        E.g. :class:`toolkit.experiments.MedianLaw`.
    runs : int
        Number of runs, ``1 .. MAX_RUNS``.
    seed : int
        Root seed (``0 <= seed < 2**128``): the key of every run's random numbers
        (:class:`RunKeys`).
    scheduler : None, "processes", str address or distributed.Client
        Where chunks run (see the module docstring).
    workers : int, optional
        Processes of the ``"processes"`` pool (default: the CPU count); refused with any other
        scheduler (a Dask cluster has its own workers).
    chunk_size : int, optional
        Runs per chunk (default :data:`DEFAULT_CHUNK_SIZE`); results do not depend on it.
    progress : bool
        Show a tqdm progress bar on stderr.

    Returns
    -------
    SweepResult

    Raises
    ------
    ParameterError
        Bad counts or seeds; a Dask scheduler without dask.distributed installed, or one
        that cannot be reached.
    """
    if not isinstance(experiment, Experiment):
        raise ParameterTypeError(parameter_message(
            "experiment", _OWNER, "be an experiment (toolkit.experiments)", experiment))
    runs = as_int(runs, "runs", _OWNER, low=1)
    if runs > MAX_RUNS:
        raise ParameterError(parameter_message("runs", _OWNER, f"be <= {MAX_RUNS}", runs))
    seed = as_int(seed, "seed", _OWNER, low=0)
    if seed >= 2**128:
        raise ParameterError(parameter_message("seed", _OWNER, "be < 2**128", seed))
    chunk_size = DEFAULT_CHUNK_SIZE if chunk_size is None else as_int(chunk_size, "chunk_size", _OWNER, low=1)
    kind = _check_scheduler(scheduler)
    if workers is not None:
        workers = as_int(workers, "workers", _OWNER, low=1)
        if kind != "processes":
            raise ParameterError(parameter_message(
                "workers", _OWNER, "be given only with scheduler='processes' (the local path runs "
                "in this process; a Dask cluster has its own workers)", workers))
    if not isinstance(progress, (bool, np.bool_)):
        raise ParameterTypeError(parameter_message("progress", _OWNER, "be True or False", progress))
    bounds = [(a, min(a + chunk_size, runs)) for a in range(0, runs, chunk_size)]
    import pandas as pd   # the table type (imported with the first sweep, before the clock)

    compile_time = 0.0
    if kind == "local":          # the timing policy: compiled, and run 0 once, before the clock
        compile_time = warm(lambda: _run_chunk(experiment, seed, 0, 1), "core")
    started = budget_clock()
    bar = _progress(runs, progress, experiment.name)
    parts: list[dict[str, np.ndarray] | None] = [None] * len(bounds)

    def done(j: int, part: dict[str, np.ndarray]) -> None:
        parts[j] = part
        if bar is not None:
            bar.update(bounds[j][1] - bounds[j][0])

    try:
        with _terminate_interrupts():
            if kind == "local":
                for j, (a, b) in enumerate(bounds):
                    done(j, _run_chunk(experiment, seed, a, b))
            elif kind == "processes":
                workers = (os.cpu_count() or 1) if workers is None else workers
                _run_pool(experiment, seed, bounds, min(workers, len(bounds)), done)
            else:
                _run_dask(experiment, seed, bounds, scheduler, done)
    finally:
        if bar is not None:
            bar.close()
    columns = {"run": np.arange(runs)}
    for name in parts[0]:
        columns[name] = np.concatenate([part[name] for part in parts])
    table = pd.DataFrame(columns)
    summary = experiment.summarize(table)
    return SweepResult(experiment, table, summary, runs, seed, chunk_size, kind,
                       budget_clock() - started, len(bounds), compile_time)
