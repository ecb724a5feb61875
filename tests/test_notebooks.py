"""Every notebook in notebooks/ runs top to bottom in a Jupyter kernel with the kernel's own
(inline) matplotlib backend, displays a figure for every cell that plots, labels every model
number it shows beside a paper number, and is stored without outputs."""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.ipynb"))

#: A cell plots when it calls a toolkit plot function or draws with pyplot or an Axes.
PLOTS = re.compile(r"\b(?:(?:tk|tp)\.plot_\w+|plt\.subplots|plt\.figure)\(|\bax\d?\.plot\(")
#: The labels of a model number shown beside a paper number (toolkit.model.parameters.LABELS):
#: [predicted], [bounded ...], [fitted to X; predicts Y].
LABEL = re.compile(r"\[(?:predicted|bounded[^\]]*|fitted to [^\];]+; predicts [^\]]+)\]")


def unlabelled_lines(text: str) -> list[str]:
    """Lines that show a number beside the word "paper" without a label (the convention the
    notebooks follow: such a line is a model number next to a paper number)."""
    return [line for line in text.splitlines()
            if re.search(r"\bpaper\b", line, re.I) and re.search(r"\d", line) and not LABEL.search(line)]


def unlabelled_cells(markdown: str) -> list[str]:
    """Cells of markdown tables with a "paper" column whose other numeric cells carry no
    label (the README's paper table follows the same rule: tests/test_readme.py)."""
    missing, header = [], None
    for line in markdown.splitlines():
        if not line.lstrip().startswith("|"):
            header = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = [c.lower() for c in cells]
            continue
        if set("".join(cells)) <= set("-: "):
            continue
        if "paper" not in header:
            continue
        for name, cell in zip(header, cells):
            if name not in ("paper", "", "result", "command") and re.search(r"\d", cell) and not LABEL.search(cell):
                missing.append(f"{name}: {cell}")
    return missing


def test_label_conventions_catch_a_bare_number():
    assert unlabelled_lines("slope 0.990; paper 1.065") == ["slope 0.990; paper 1.065"]
    assert unlabelled_lines("slope 0.990 [predicted]; paper 1.065") == []
    assert unlabelled_lines("slope 0.990 [fitted to 0.09]; paper 1.065") != []     # says what it predicts
    assert unlabelled_lines("slope 0.990 [fitted to 0.09; predicts 1.065]; paper 1.065") == []
    table = "| | paper | ideal model |\n|---|---|---|\n| slope | 1.065 | 0.7744 |\n"
    assert unlabelled_cells(table) == ["ideal model: 0.7744"]
    assert unlabelled_cells(table.replace("0.7744", "[predicted] 0.7744")) == []


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_stored_without_outputs(path):
    notebook = nbformat.read(path, as_version=4)
    assert all(not cell.get("outputs") for cell in notebook.cells if cell.cell_type == "code")


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_shows_its_figures_and_labels_its_numbers(path, monkeypatch):
    from nbclient import NotebookClient

    # The kernel's default backend (ipykernel's inline), whatever the test process uses.
    monkeypatch.delenv("MPLBACKEND", raising=False)
    notebook = nbformat.read(path, as_version=4)
    NotebookClient(notebook, timeout=300, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    plotting = 0
    for index, cell in enumerate(notebook.cells):
        if cell.cell_type == "markdown":
            assert not unlabelled_cells(cell.source), (path.name, index, unlabelled_cells(cell.source))
            continue
        texts = [o.get("text", "") if o.output_type == "stream" else o.get("data", {}).get("text/plain", "")
                 for o in cell.outputs]
        for text in texts:
            assert not unlabelled_lines(text), (path.name, index, unlabelled_lines(text))
        if PLOTS.search(cell.source):
            plotting += 1
            images = sum("image/png" in o.get("data", {}) for o in cell.outputs)
            assert images >= 1, f"{path.name} cell {index} plots but displays no image"
    assert plotting >= 1, f"{path.name} has no plotting cell"
