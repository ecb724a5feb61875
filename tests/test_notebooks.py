"""Every notebook in notebooks/ runs top to bottom in a Jupyter kernel with the kernel's own
(inline) matplotlib backend, displays a figure for every cell that plots, labels every model
number it shows beside a paper number, states in its text no result its code does not print,
and is stored without outputs.

The rule for the text: every number a markdown cell states with a decimal point or a percent
sign is printed, to its stated digits, by some output of the executed notebook (outside the
output's labels and its quotes of the paper), or typed as a literal in its code (an input),
or is in the notebook's allow-list (:data:`ALLOWED`: the paper's numbers and inputs, each
with its reason). A matching number can be a coincidence: the rule catches a result no
output prints, not one attached to the wrong quantity."""

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


#: A number in text: digits with an optional decimal part and exponent, then optionally a
#: second number joined by "+-", "-" or "to" (an uncertainty or a range), then optionally "%",
#: which applies to both (``91 +- 4 %``, ``2.6-6.6 %``). Not part of a word or of a longer number.
_NUM = r"\d+(?:\.\d+)?(?:e[-+]?\d+)?"
NUMBER = re.compile(rf"(?<![\w.])({_NUM})(?:\s?(?:\+-|-|to)\s?({_NUM}))?(\s?%)?")

#: The paper's numbers, which a notebook's text may state without printing them.
PAPER = {
    "91%": "the paper's friction reduction at n = 0 (its Fig. 6b)",
    "4%": "the paper's uncertainty of its friction reduction",
    "4.6%": "the paper's motor speed rise on release (its Fig. 2d)",
    "2.0%": "the paper's uncertainty of the rise on release",
    "2.6%": "the lower end of the paper's rise on release, 4.6 - 2.0 %",
    "6.6%": "the upper end of the paper's rise on release, 4.6 + 2.0 %",
}

#: Numbers a notebook's text may state without printing them: the paper's (from PAPER) and
#: inputs its code does not type, each with its reason. Every entry is a number its notebook's
#: text states (test_allow_list_names_numbers_the_text_states).
ALLOWED = {
    "estimation": {},
    "estimation_robustness": {"95%": "the level of the NEES's chi-square interval (an input)",
                              "0.95": "the share of samples a consistent filter keeps in its 95 % "
                                      "interval: the interval's level (an input)"},
    "force_speed_curves": {key: PAPER[key] for key in ("91%", "4%")},
    "gaps": {key: PAPER[key] for key in ("91%", "4%", "4.6%", "2.0%", "2.6%", "6.6%")},
    "mean_median_outliers": {key: PAPER[key] for key in ("91%",)},
    "median_law": {key: PAPER[key] for key in ("91%", "4.6%", "2.0%")},
    "planar_disc": {},
    "planar_hexapod": {"30%": "how much slower the turning gait's left legs sweep (turn=0.3, an input)"},
    "planar_snake": {},
    "predictions": {**{key: PAPER[key] for key in ("91%", "4.6%", "2.0%")},
                    "63.2%": "the crossing's definition, 1 - 1/e (an input)"},
}


def _numbers(text: str) -> list[tuple[str, bool]]:
    """Every number in ``text`` as typed, with whether it is a percentage."""
    found = []
    for match in NUMBER.finditer(text):
        percent = match.group(3) is not None
        found += [(number, percent) for number in match.group(1, 2) if number is not None]
    return found


def stated_numbers(markdown: str) -> list[tuple[str, bool]]:
    """The result numbers a markdown text states: every number with a decimal point (``0.780``,
    ``2.8e-17``) or a percent sign (``21 %``, ``91 +- 4 %``). Whole numbers without one (counts,
    seeds, figure, section and equation numbers, ``n = 5``) are not results by this rule."""
    return [(number, percent) for number, percent in _numbers(markdown)
            if percent or "." in number.split("e")[0]]


def printed_numbers(text: str) -> list[tuple[float, bool]]:
    """The numbers an output prints as results: every number outside its labels (``[predicted]``,
    ``[bounded ...]``, ``[fitted to ...]``) and outside what it quotes of the paper (from the
    word "paper" to the end of the line or the next ';'), as values, with whether each is
    printed as a percentage."""
    text = re.sub(r"\[(?:predicted|bounded|fitted)[^\]]*\]", " ", text)
    text = re.sub(r"\bpaper\b[^;\n]*", " ", text, flags=re.I)
    return [(float(number), percent) for number, percent in _numbers(text)]


def _rounds_to(value: float, number: str) -> bool:
    """Whether ``value`` stated to the digits of ``number`` (as typed) is ``number``."""
    mantissa = number.split("e")[0]
    digits = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return float(format(abs(value), f".{digits}{'e' if 'e' in number else 'f'}")) == float(number)


def unprinted_numbers(markdown: str, printed: list[tuple[float, bool]], typed: set[float],
                      allowed: dict[str, str]) -> list[str]:
    """The result numbers ``markdown`` states (:func:`stated_numbers`) that nothing computed
    shows. A number stated to ``d`` decimals is shown by a printed number that rounds to it at
    ``d`` decimals (``0.7744`` shows ``0.77``; signs aside), a percentage only by a printed
    percentage; a number that is not a percentage may also be one the notebook's code types as
    a literal (``typed``: an input, or the paper's number the code compares with), equal in
    value; and ``allowed`` (keyed ``"0.653"`` or ``"91%"``) names the paper's numbers and
    inputs the text may state without either."""
    missing = []
    for number, percent in stated_numbers(markdown):
        key = f"{number}{'%' if percent else ''}"
        if key in allowed:
            continue
        if any(p == percent and _rounds_to(value, number) for value, p in printed):
            continue
        if not percent and float(number) in typed:
            continue
        missing.append(key)
    return missing


def notebook_unprinted_numbers(notebook, allowed: dict[str, str]) -> list[tuple[int, str]]:
    """The markdown cells of an executed notebook, by index, and the numbers each states that
    its outputs (stream and ``text/plain``, of any cell) do not print (:func:`unprinted_numbers`)."""
    printed, typed = [], set()
    for cell in notebook.cells:
        if cell.cell_type == "code":
            typed |= {float(number) for number, percent in _numbers(cell.source) if not percent}
            for output in cell.outputs:
                printed += printed_numbers(output.get("text", "") if output.output_type == "stream"
                                           else output.get("data", {}).get("text/plain", ""))
    return [(index, number) for index, cell in enumerate(notebook.cells) if cell.cell_type == "markdown"
            for number in unprinted_numbers(cell.source, printed, typed, allowed)]


def unlabelled_lines(text: str) -> list[str]:
    """Lines that show a number beside the word "paper" without a label (the convention the
    notebooks follow: such a line is a model number next to a paper number)."""
    return [line for line in text.splitlines()
            if re.search(r"\bpaper\b", line, re.I) and re.search(r"\d", line) and not LABEL.search(line)]


def unlabelled_cells(markdown: str) -> list[str]:
    """Cells of markdown tables with a "paper" column whose other numeric cells carry no
    label (the validation page's table follows the same rule: tests/test_readme.py)."""
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


def test_result_rule_catches_a_number_no_output_prints():
    text = "lowers k by about 1.5 % (R^2 0.68); paper 91 +- 4 %, rise 2.6-6.6 %; Fig. 3b, n = 5, 660 runs"
    assert stated_numbers(text) == [("1.5", True), ("0.68", False), ("91", True), ("4", True), ("2.6", True),
                                    ("6.6", True)]
    # What the labels and the paper's quotes of an output say is not a result it prints.
    line = "k = 1.0317, -20.4 % against the loop; r2 0.683 [fitted to the paper's 91 +- 4 %; predicts k]; paper: 0.35 s"
    printed = printed_numbers(line)
    assert printed == [(1.0317, False), (20.4, True), (0.683, False)]
    assert printed_numbers("displacement [0.1 0.0012] m [bounded]") == [(0.1, False), (0.0012, False)]
    allowed = {"91%": "the paper's", "4%": "the paper's"}
    # The stale sentence of predictions.ipynb against what its code printed for the same effect.
    assert unprinted_numbers(text, printed, set(), allowed) == ["1.5%", "2.6%", "6.6%"]
    # Stated to fewer digits than printed, a number is shown; to other digits, or as a
    # percentage where a fraction is printed, it is not.
    assert unprinted_numbers("by about 20 % (R^2 0.7; k 1.03)", printed, set(), {}) == []
    assert unprinted_numbers("by about 21 % (R^2 0.69; 68 %)", printed, set(), {}) == ["21%", "0.69", "68%"]
    # A number the code types is an input, equal in value; not as a percentage.
    assert unprinted_numbers("an amplitude of 0.30 m/s, 30 % of it", [], {0.3}, {}) == ["30%"]
    assert unprinted_numbers("an error of 2.8e-17 m/s", [(2.83e-17, False)], set(), {}) == []


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_allow_list_names_numbers_the_text_states(path):
    notebook = nbformat.read(path, as_version=4)
    stated = {f"{number}{'%' if percent else ''}" for cell in notebook.cells if cell.cell_type == "markdown"
              for number, percent in stated_numbers(cell.source)}
    assert set(ALLOWED[path.stem]) <= stated, set(ALLOWED[path.stem]) - stated
    assert set(ALLOWED) == {p.stem for p in NOTEBOOKS}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_stored_without_outputs(path):
    notebook = nbformat.read(path, as_version=4)
    assert all(not cell.get("outputs") for cell in notebook.cells if cell.cell_type == "code")


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_shows_its_figures_and_labels_its_numbers(path, monkeypatch):
    """Runs the notebook, then checks its figures, its labels and that its text states no
    result its outputs do not print."""
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
    # The text states no result the code does not print (unprinted_numbers).
    assert not notebook_unprinted_numbers(notebook, ALLOWED[path.stem]), (
        path.name, notebook_unprinted_numbers(notebook, ALLOWED[path.stem]))
