"""Test configuration: under CI, hypothesis draws its examples deterministically.

Locally hypothesis explores new random examples on every run (and remembers failures);
in CI (``CI`` set, as ``.ci/run`` runs) the same examples run every time, so a submission
never passes or fails on a lucky draw.
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


_KERNELS: dict[str, float] = {}


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernels():
    """Compile (or load from numba's cache) the kernels once, before the first test; the
    suite's summary says what that cost (:func:`pytest_terminal_summary`)."""
    from toolkit import _compiled
    from toolkit.simulation._warmup import warm_up

    _KERNELS["wall"] = warm_up()
    _KERNELS["compiling"] = _compiled.compile_seconds()


def pytest_terminal_summary(terminalreporter):
    if _KERNELS:
        terminalreporter.write_line(
            f"kernels: compiled or loaded from numba's cache once, in {_KERNELS['wall']:.1f} s "
            f"({_KERNELS['compiling']:.1f} s of it compiling) before the first test")
