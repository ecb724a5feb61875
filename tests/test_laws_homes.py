"""Each law of :mod:`toolkit.laws` is written there only: no copy of its formula in the
code of the toolkit (strings and comments aside), and the implicit (Moreau) step against a
second method."""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import numpy as np
import pytest

from toolkit import laws

ROOT = Path(laws.__file__).resolve().parent
HOME = Path(laws.__file__).resolve()

#: A copy of each formula as code would write it (on code with strings and comments removed).
FORMULAS = {
    "tie_tolerance (4 (K + 1) eps F_tot)": r"\b4(?:\.0)?\s*\*\s*\([^()]*\+\s*1\)\s*\*.*eps\b",
    "lag_response / lag_decay / lag_travel (exp(-s / tau))":
        r"\bexp(?:m1)?\(\s*-\s*\(?[^()]*\)?\s*/\s*(?:self\.)?(?:tau|lag)\b",
    "cell_centre ((c + 1/2) q)": r"\+\s*0\.5\s*\)\s*\*\s*(?:self\.)?_?(?:q|resolution)\b",
    "quantization_variance (q^2 / 12, or (q1^2 + q2^2) / 12)":
        r"(?:\b((?:self\.)?_?(?:q\w*|wc|resolution))\s*\*\s*\1|\bq\w*\s*\*\*\s*2)\s*/\s*12(?:\.0)?\b"
        r"|\b(\w+)\s*\*\s*\2\s*\+\s*(\w+)\s*\*\s*\3\s*\)\s*/\s*12",
    "implicit_step ((b + P_k) / a on the staircase)": r"\(\s*b(?:eta)?\s*\+\s*(?:plateau|level)\w*",
}


def _code(path: Path) -> list[tuple[int, str]]:
    """The lines of ``path`` with every string and comment blanked."""
    source = path.read_text(encoding="utf-8")
    lines = source.splitlines()
    blank = [list(line) for line in lines]
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type in (tokenize.STRING, tokenize.COMMENT):
            (r0, c0), (r1, c1) = token.start, token.end
            for r in range(r0, r1 + 1):
                row = blank[r - 1]
                lo = c0 if r == r0 else 0
                hi = c1 if r == r1 else len(row)
                row[lo:hi] = " " * (hi - lo)
    return [(i + 1, "".join(row)) for i, row in enumerate(blank)]


def _sources() -> list[Path]:
    return [p for p in sorted(ROOT.rglob("*.py"))
            if p.resolve() != HOME]


@pytest.mark.parametrize("name", list(FORMULAS))
def test_each_formula_is_written_in_its_home_only(name):
    pattern = re.compile(FORMULAS[name], re.IGNORECASE)
    copies = [f"{path.relative_to(ROOT.parent)}:{number}: {line.strip()}"
              for path in _sources() for number, line in _code(path) if pattern.search(line)]
    assert not copies, f"{name} written outside toolkit/laws.py:\n" + "\n".join(copies)
    home = [line for _, line in _code(HOME) if pattern.search(line)]
    assert home, f"the pattern of {name} no longer matches its home: the test would pass vacuously"


def test_the_kernels_compile_the_laws_they_call():
    # The kernel modules list each law they call among their kernels, so that toolkit._compiled
    # compiles it (a law called but not listed would stay a Python function numba cannot call).
    import importlib

    names = {"tie_tolerance", "lag_decay", "lag_response", "lag_travel", "cell_centre",
             "quantization_variance"}
    folder = ROOT / "_compiled"
    for path in sorted(folder.glob("*.py")):
        if path.name == "__init__.py":
            continue
        module = importlib.import_module(f"toolkit._compiled.{path.stem}")
        called = {name for name in names if re.search(rf"\b{name}\(", path.read_text(encoding="utf-8"))}
        missing = called - set(getattr(module, "KERNELS", {}))
        assert not missing, f"{path.name} calls {sorted(missing)} without listing them in KERNELS"


def _inclusion_gap(levels, plateaus, a, b, W):
    """How far ``a W - b`` lies outside the force set ``F(W)`` of the staircase (0: a solution)."""
    first, past = np.searchsorted(levels, W, side="left"), np.searchsorted(levels, W, side="right")
    lo, hi = plateaus[past], plateaus[first]          # (equal off the levels)
    g = a * W - b
    return max(lo - g, g - hi, 0.0)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_implicit_step_solves_the_inclusion(scale):
    # W solves a W - b in F(W): the residual is rounding only (a few ulp of the force scale
    # F_tot + |b|: atol 64 eps of it), and rows solved at once equal each row solved alone.
    rng = np.random.default_rng(29)
    for _ in range(200):
        n = int(rng.integers(1, 9))
        speeds = np.sort(rng.choice(np.linspace(-1.0, 1.0, 9), n))   # ties included
        forces = rng.uniform(0.1, 2.0, n) * scale                      # unequal forces
        plateaus = forces.sum() - 2.0 * np.concatenate(([0.0], np.cumsum(forces)))
        a = float(rng.uniform(0.5, 5.0)) * scale
        b = rng.uniform(-3.0, 3.0, 6) * scale
        rows_W, rows_stuck = laws.implicit_step(np.tile(speeds, (6, 1)), np.tile(plateaus, (6, 1)), a, b)
        for r in range(6):
            W, stuck = laws.implicit_step(speeds, plateaus, a, float(b[r]))
            assert (rows_W[r], bool(rows_stuck[r])) == (W, stuck)
            assert stuck == bool(np.any(speeds == W))
            tol = 64 * np.finfo(float).eps * (forces.sum() + abs(b[r]))
            assert _inclusion_gap(speeds, plateaus, a, float(b[r]), W) <= tol
