"""Test configuration: hypothesis's CI profile, the compiled kernels loaded once per run, and
how pytest-xdist shares the tests among its workers.

Locally hypothesis explores new random examples on every run (and remembers failures);
in CI (``CI`` set, as ``.ci/run`` runs) the same examples run every time, so a submission
never passes or fails on a lucky draw.

The kernels are compiled (or loaded from numba's cache) before the first test. Under
pytest-xdist (``make test`` runs ``pytest -n 2``) the controller compiles them before its
workers start (groups of warm-ups in two processes at once), and each worker loads them from
the cache; the summary says what each step cost. docs/testing.md tells the rules.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")

import pytest  # noqa: E402

# The tests run the kernels of toolkit._compiled compiled from their first call (a process
# outside the tests runs them as Python until it has done enough work to pay for compiling);
# with NUMBA_DISABLE_JIT=1 the same source runs as Python (make test runs the kernel tests
# both ways). Subprocess tests inherit this unless they set it themselves.
os.environ.setdefault("ACTIVE_CONTACTS_COMPILE", "eager")

#: The warm-ups of the kernels every test process loads first, in the groups that compile at
#: once (few kernels in common; the kernels' cache saves are locked).
from toolkit._warmups import GROUPS, run_group  # noqa: E402

_KERNELS: dict[str, float] = {}              # this process: the warm-ups' wall time, compiling
_AHEAD: dict[str, float] = {}                # the xdist controller: each step's wall time
_WORKERS: dict[str, dict[str, float]] = {}   # the xdist controller: what each worker reported


def _distributed(config: pytest.Config) -> bool:
    """Whether this process is a pytest-xdist controller that starts workers to run tests."""
    return (getattr(config.option, "dist", "no") != "no" and not hasattr(config, "workerinput")
            and not config.option.collectonly)


def pytest_configure(config: pytest.Config) -> None:
    # Under xdist, before the workers start: the GROUPS in parallel, then, if they compiled
    # anything (a fresh clone, a changed kernel), `active-contacts warm`: every kernel the
    # shipped designs run (the estimators' and controllers'), on the kernels cached by then.
    # Without numba's compiler there is nothing to compile.
    if not _distributed(config) or os.environ.get("NUMBA_DISABLE_JIT", "0") not in ("", "0"):
        return
    import json
    import multiprocessing
    import subprocess
    import sys
    import time
    from concurrent.futures import ProcessPoolExecutor

    started = time.perf_counter()
    with ProcessPoolExecutor(len(GROUPS), mp_context=multiprocessing.get_context("spawn")) as pool:
        runs = {" and ".join(module.split(".")[1] for module in group): pool.submit(run_group, group)
                for group in GROUPS}
        done = {name: run.result() for name, run in runs.items()}
    _AHEAD.update((name, wall) for name, (wall, _) in done.items())
    _AHEAD["total"] = time.perf_counter() - started
    if not any(compiling for _, compiling in done.values()):
        return                               # (loaded from a warm cache: nothing to compile)
    warm = subprocess.run([sys.executable, "-m", "toolkit.cli", "warm", "--json"], capture_output=True,
                          text=True, cwd=config.rootpath)
    if warm.returncode != 0:                 # (tests/test_compile_notice.py tells what failed)
        raise pytest.UsageError(f"active-contacts warm failed before the tests:\n{warm.stderr}")
    _AHEAD["warm"] = json.loads(warm.stdout)["wall_time"]
    _AHEAD["total"] = time.perf_counter() - started


@pytest.hookimpl(tryfirst=True)              # (before pytest-xdist reads the groups)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    # The tests that share a module-scoped fixture run on one worker (pytest-xdist's
    # --dist loadgroup), so that it is computed once; the others are sent one by one.
    for item in items:
        fixtures = getattr(item, "_fixtureinfo", None)
        if (fixtures is not None and not any(item.iter_markers("xdist_group"))
                and any(defs[-1].scope == "module" for defs in fixtures.name2fixturedefs.values())):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernels():
    """Compile (or load from numba's cache) the kernels once, before the first test; the
    suite's summary says what that cost (:func:`pytest_terminal_summary`)."""
    from toolkit import _compiled

    _KERNELS["wall"] = sum(run_group(group)[0] for group in GROUPS)
    _KERNELS["compiling"] = _compiled.compile_seconds()


def pytest_sessionfinish(session: pytest.Session) -> None:
    # An xdist worker hands the controller its warm-up and all it compiled.
    if hasattr(session.config, "workeroutput") and _KERNELS:
        from toolkit import _compiled

        session.config.workeroutput["kernels"] = dict(_KERNELS, total=_compiled.compile_seconds())


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error) -> None:
    kernels = getattr(node, "workeroutput", {}).get("kernels")
    if kernels is not None:
        _WORKERS[node.gateway.id] = kernels


def pytest_terminal_summary(terminalreporter):
    write = terminalreporter.write_line
    if _AHEAD:
        designs = (f", then every shipped design once (active-contacts warm, {_AHEAD['warm']:.1f} s)"
                   if "warm" in _AHEAD else "")
        groups = " and ".join(f"{name} ({wall:.1f} s)" for name, wall in _AHEAD.items()
                              if name not in ("total", "warm"))
        write(f"kernels: compiled or loaded from numba's cache before the workers started, in "
              f"{_AHEAD['total']:.1f} s: the warm-ups of {groups} in parallel{designs}")
    for name, kernels in sorted(_WORKERS.items()):
        write(f"kernels: {name} loaded them in {kernels['wall']:.1f} s ({kernels['compiling']:.1f} s "
              f"compiling), and compiled {kernels['total'] - kernels['compiling']:.1f} s more in its tests")
    if _KERNELS:
        write(f"kernels: compiled or loaded from numba's cache once, in {_KERNELS['wall']:.1f} s "
              f"({_KERNELS['compiling']:.1f} s of it compiling) before the first test")
