"""The README and the documentation's pages are true on a fresh clone.

- every link resolves to a file inside the repository (no link outside it, such as the
  team's physics brief in ``../shared``, and no mention of that file);
- every notebook a page names exists and contains what the page says it shows;
- every scene key is on the generated scene reference (tests/test_scene_reference.py);
- the exit codes documented are those of :data:`toolkit.cli.EXIT_CODES`;
- the validation page labels every model number and takes each one from the code.

(The ``>>>`` examples of these pages run as doctests: ``--doctest-glob`` in pyproject.toml.)
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import nbformat
import pytest

from toolkit.cli import EXIT_CODES

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: The team's physics brief, which lives outside the repository (named in pieces: this file does not cite it).
BRIEF = "PHYSICS" + ".md"
README = (ROOT / "README.md").read_text(encoding="utf-8")
LINK = re.compile(r"\]\(([^)\s]+)\)")
#: The documentation's own pages (not the build, not generated stubs).
PAGES = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts and "generated" not in p.parts
               and "notebooks" not in p.parts)


def _page(name: str) -> str:
    return (DOCS / name).read_text(encoding="utf-8")


def _notebook_source(name: str) -> str:
    notebook = nbformat.read(ROOT / "notebooks" / name, as_version=4)
    return "\n".join(cell.source for cell in notebook.cells)


def test_readme_is_a_front_page() -> None:
    # at most 200 lines; the two commands with their cost; the tour runs (a doctest); the site
    lines = README.splitlines()
    assert len(lines) <= 200, len(lines)
    assert "$ make demo" in README and "$ make test" in README
    assert re.search(r"\*\*\d+ min \d+ s\*\*", README) and re.search(r"about \d+ min", README)
    tour = README.split("## A tour of the library", 1)[1].split("\n## ", 1)[0]
    assert 12 <= tour.count(">>> ") <= 20
    for page in ("docs/getting_started.md", "docs/validation.md", "docs/performance.md", "docs/architecture.md"):
        assert f"]({page})" in README, page


def test_every_link_stays_inside_the_repository() -> None:
    for path in [ROOT / "README.md", *PAGES]:
        text = path.read_text(encoding="utf-8")
        for target in LINK.findall(text):
            assert not re.match(r"[a-z]+:", target), f"{path.name}: link outside the repository: {target}"
            resolved = (path.parent / target.split("#")[0]).resolve()
            assert resolved.is_relative_to(ROOT) and resolved.exists(), f"{path.name}: {target}"
        # the team's brief is not part of a clone: no page may send readers there
        assert BRIEF not in text and "../shared" not in text, path.name


def test_named_files_exist() -> None:
    for text in [README, *(p.read_text(encoding="utf-8") for p in PAGES)]:
        for name in set(re.findall(r"`((?:notebooks|designs|docs|tests)/[\w./-]+\.\w+)`", text)):
            assert (ROOT / name).exists(), name


def test_force_speed_curves_notebook_shows_the_allocator_and_dt_to_1e_12() -> None:
    # The allocation page cites this notebook for "the allocator finds that split from
    # FrictionFraction(n/5) and the exact simulation gives dT = ... to 1e-12": the notebook
    # must do both (tests/test_notebooks.py runs it, so its asserts hold).
    page = " ".join(_page("guide/allocation.md").split())
    assert "notebooks/force_speed_curves.ipynb" in page and "to 1e-12" in page
    source = _notebook_source("force_speed_curves.ipynb")
    assert "tk.allocate(tk.FrictionFraction(n / 5" in source
    assert "tk.simulate(plant" in source and "1e-12 * closed" in source
    assert "mass * 2 * v_max / (plant.contacts.total_force * n / 5)" in source


def test_exit_codes_documented_are_the_clis() -> None:
    table = {int(code) for code in re.findall(r"^\| (\d+) \| ", _page("reference/cli.md"), flags=re.M)}
    assert table == set(EXIT_CODES)
    sentence = README.split("Exit codes:", 1)[1].split("\n\n", 1)[0]
    assert {int(code) for code in re.findall(r"(?<![\w.])(\d+) ", sentence)} == set(EXIT_CODES)
    assert "--strict" in _page("reference/cli.md")


def test_performance_page_names_every_benchmark() -> None:
    # Every row of the performance page's table names a benchmark module, and every
    # benchmark module has its row; the page includes the file `make bench-page` writes.
    page = _page("performance.md")
    rows = [line for line in page.splitlines() if line.startswith("| `")]
    named = {re.match(r"\| `([a-z]+)`", row).group(1) for row in rows}
    benches = {path.stem for path in (ROOT / "toolkit" / "bench").glob("*.py")} - {"__init__", "__main__"}
    assert named == benches
    assert "../benchmarks/performance.txt" in page
    assert "bench-page:" in (ROOT / "Makefile").read_text()
    first = (ROOT / "benchmarks" / "performance.txt").read_text().splitlines()[:2]
    assert first[0] == "== machine" and re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d UTC; .+ cores", first[1])


# -- the validation page: every number a substitution that docs/_ext/paper_numbers.py computes

def _paper_numbers():
    sys.path.insert(0, str(DOCS / "_ext"))
    try:
        import paper_numbers
    finally:
        sys.path.remove(str(DOCS / "_ext"))
    return paper_numbers


def _substituted(text: str, value: str = "0.5") -> str:
    return re.sub(r"\{\{ (\w+) \}\}", value, text)


def test_every_model_number_in_the_paper_table_is_labelled() -> None:
    # predicted / bounded / fitted to X; predicts Y (the convention of tests/test_notebooks.py)
    from test_notebooks import unlabelled_cells

    page = _page("validation.md")
    table = page.split("| result | paper |", 1)[1].split("\n\n", 1)[0]
    table = "| result | paper |" + table
    assert table.count("\n") >= 9 and "| result | paper | ideal model | non-ideal model | command |" in table
    assert unlabelled_cells(_substituted(table)) == []
    assert unlabelled_cells(_substituted(table).replace("[predicted] 100 %", "100 %")) == ["ideal model: 100 %"]


def test_validation_numbers_are_substitutions_not_typed() -> None:
    # In the table every model number is a {{ name }} (the paper's numbers, its inputs and the
    # closed forms' tolerances aside): no result with two or more decimals is typed in.
    # (test_validation_numbers_compute_and_fill_the_page checks the names.)
    page = _page("validation.md")
    model = [line.split("|")[3:5] for line in page.splitlines() if line.startswith("| ") and "{{" in line]
    assert model
    for cells in model:
        for cell in cells:
            bare = re.sub(r"\{\{ \w+ \}\}|\[[^\]]*\]|`[^`]*`|\([^)]*\)", "", cell)
            assert not re.search(r"\b\d+\.\d{2,}", bare), cell       # no typed result of two or more decimals


@pytest.mark.slow
def test_validation_numbers_compute_and_fill_the_page() -> None:
    # The extension computes every substitution the page uses (what make docs runs).
    values = _paper_numbers().values(log=lambda message: None)
    used = set(re.findall(r"\{\{ (\w+) \}\}", _page("validation.md")))
    assert used <= set(values), used - set(values)
    assert values["mean_median_mean_range"] == "0" and values["median_held_speed_range"] == "0"
    assert values["outliers_rule"] == "100"
