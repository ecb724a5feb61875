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


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernels():
    """Compile (or load from numba's cache) the kernels once, before any test times a call."""
    from toolkit.simulation._warmup import warm_up

    warm_up()
