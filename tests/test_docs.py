"""Citations in the code point at documents and sections that exist; every code block of the
README and the docs runs or is checked; module docstrings stay short; no history in the text."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The team's physics brief, which lives outside the repository (named in pieces: this file does not cite it).
BRIEF = "PHYSICS" + ".md"


def _tracked(*folders: str) -> list[Path]:
    out = subprocess.run(["git", "ls-files", "--", *folders], cwd=ROOT, capture_output=True, text=True,
                         check=True).stdout.split()
    return [ROOT / name for name in out if (ROOT / name).is_file()]


def _sections(doc: Path) -> set[str]:
    return set(re.findall(r"^#{2,3} (\d+)\.", doc.read_text(), flags=re.M))


def test_physics_citations_name_existing_sections() -> None:
    sections = _sections(ROOT / "docs" / "physics.md")
    assert {"3", "4", "5", "6", "8"} <= sections          # the sections the code cites most
    cite = re.compile(r"docs/physics\.md`?,?\s+sections?\s+(\d+)(?:\s+and\s+(\d+))?")
    seen = 0
    for path in _tracked("toolkit", "tests", "notebooks"):
        if path.suffix not in (".py", ".toml", ".ipynb", ".md"):
            continue
        for match in cite.finditer(path.read_text(encoding="utf-8")):
            for number in filter(None, match.groups()):
                seen += 1
                assert number in sections, f"{path.relative_to(ROOT)} cites docs/physics.md section {number}"
    assert seen >= 20                                     # the test reads the citations it checks


def test_no_citation_of_a_file_the_repository_does_not_hold() -> None:
    cited = re.compile(r"\b((?:docs|designs|notebooks)/[\w./-]+\.(?:md|toml|ipynb))")
    # (the tests name missing files on purpose, to check the errors: they are not read here)
    for path in _tracked("toolkit", "notebooks", "docs") + [ROOT / "README.md"]:
        if path.suffix not in (".py", ".toml", ".ipynb", ".md"):
            continue
        text = path.read_text(encoding="utf-8")
        assert BRIEF not in text, f"{path.relative_to(ROOT)} cites {BRIEF} (not in the repository)"
        for name in cited.findall(text):
            assert (ROOT / name).exists(), f"{path.relative_to(ROOT)} cites {name}, which does not exist"


#: The paper's figures as its source numbers them (the order of its figure environments),
#: the panels each has, and words one of which names a reference to it within the 90
#: characters before "Fig. N" (docs/physics.md section 6 lists them).
_FIGURES = {
    1: ("bc", ("motivat", "sketch")),
    2: ("abcd", ("carousel", "wheel", "characteri", "caption", "schematic", "motor speeds")),
    3: ("abc", ("median", "equilib", "startup", "steady")),
    4: ("abc", ("force-speed", "step", "all speeds equal", "five against five", "viscosity")),
    5: ("", ("viscosity", "time constant", "tau")),
    6: ("abc", ("friction", "mu/mu0", "transition", "brake", "split", "reduction", "n = 0")),
}
_EQUATIONS = {1: ("1/N", "sum"), 2: ("CDF", "Summing", "weighted")}
_REFERENCE = re.compile(r"\b(Figs?|Eq)\.\s+(\d+)([a-z]?)")


def _texts() -> list[tuple[str, str]]:
    import nbformat

    out = []
    for path in _tracked("toolkit", "docs", "notebooks") + [ROOT / "README.md"]:
        if path.suffix in (".py", ".toml", ".md"):
            out.append((str(path.relative_to(ROOT)), path.read_text(encoding="utf-8")))
        elif path.suffix == ".ipynb":
            cells = nbformat.read(path, as_version=4).cells
            out.append((str(path.relative_to(ROOT)), "\n".join(cell.source for cell in cells)))
    return out


def check_references(text: str) -> list[str]:
    """References to a figure, panel or equation the paper's source does not have, or without
    a word of the figure's subject just before them."""
    flat = " ".join(text.split())
    bad = []
    for match in _REFERENCE.finditer(flat):
        kind, number, panel = match.group(1), int(match.group(2)), match.group(3)
        before = flat[max(0, match.start() - 90):match.start()].lower()
        if kind == "Eq":
            words = _EQUATIONS.get(number)
            ok = words is not None and any(w.lower() in before for w in words)
        else:
            panels, words = _FIGURES.get(number, ("", ()))
            ok = number in _FIGURES and (not panel or panel in panels) and any(w in before for w in words)
        if not ok:
            bad.append(flat[max(0, match.start() - 60):match.end()])
    return bad


def test_check_references_catches_the_old_numbering():
    # The numbering the code used before (one figure off): viscosity Fig. 6, friction Fig. 7,
    # median law Fig. 2b.
    assert check_references("runs the paper's viscosity (Fig. 6) and friction-fraction (Fig. 7)")
    assert check_references("The median law (the paper's Fig. 2b): steady speed")
    assert not check_references("runs the paper's viscosity (its Fig. 5) and friction-fraction (its Fig. 6)")
    assert not check_references("The median law (the paper's Fig. 3b): steady speed; Summing gives Eq. 2")


def test_figure_and_equation_numbers_are_the_papers():
    seen = 0
    for name, text in _texts():
        seen += len(_REFERENCE.findall(" ".join(text.split())))
        assert not check_references(text), (name, check_references(text))
    assert seen >= 30                                     # the test reads the references it checks


# -- the pages' code blocks: every one runs, or is checked against what it shows

DOCS = ROOT / "docs"
FENCE = re.compile(r"^```(\S*)[^\n]*\n(.*?)^```$", re.M | re.S)
#: The languages a page's fenced block may have: python (doctests, run by pytest's
#: --doctest-glob), console (commands, run below), text (a synopsis or a diagram, checked below
#: where it shows commands), toml (a scene), and MyST directives ({toctree}, {literalinclude}, ...).
LANGUAGES = {"python", "console", "text", "toml"}


def _pages() -> list[Path]:
    return [ROOT / "README.md"] + sorted(
        p for p in DOCS.rglob("*.md")
        if not {"_build", "generated", "notebooks"} & set(p.relative_to(DOCS).parts))


def _blocks(language: str) -> list[tuple[Path, str]]:
    return [(page, body) for page in _pages() for lang, body in FENCE.findall(page.read_text(encoding="utf-8"))
            if lang == language]


def test_every_code_block_is_a_doctest_or_a_command() -> None:
    seen = 0
    for page in _pages():
        for lang, body in FENCE.findall(page.read_text(encoding="utf-8")):
            seen += 1
            assert lang in LANGUAGES or lang.startswith("{"), (page.name, lang)
            if lang == "python":
                # every line a prompt, a continuation, output or blank: pytest runs it all
                assert body.lstrip().startswith(">>> "), (page.name, body[:60])
            if lang == "console":
                assert all(line.startswith("$ ") for line in body.splitlines() if line.strip()), page.name
    assert seen >= 20


def _commands() -> list[tuple[Path, str]]:
    return [(page, line[2:]) for page, body in _blocks("console") for line in body.splitlines()
            if line.startswith("$ ")]


def _check_against_parser(words: list[str]) -> None:
    from toolkit.cli import parser

    sub = parser()._subparsers._group_actions[0].choices  # noqa: SLF001 (argparse keeps them here)
    command = words[0]
    assert command in sub, command
    flags = {option for action in sub[command]._actions for option in action.option_strings}  # noqa: SLF001
    for word in words[1:]:
        if word.startswith("--"):
            assert word.split("=")[0] in flags, (command, word)


def test_every_command_shown_is_one_the_parser_accepts() -> None:
    # console blocks and the README's synopsis: each subcommand exists and takes every flag shown
    shown = [line.split() for _, line in _commands() if line.startswith("active-contacts ")]
    synopsis = [line.split() for _, body in _blocks("text") for line in body.splitlines()
                if line.startswith("active-contacts ")]
    assert len(synopsis) >= 10 and len(shown) >= 5
    for words in shown + synopsis:
        _check_against_parser([w.strip("[]|") for w in words[1:]])
    made = {line.split()[1] for _, line in _commands() if line.startswith("make ")}
    targets = set(re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), flags=re.M))
    assert made and made <= targets, made - targets


#: Console commands that run for as long as they say (a live loop for 60 s of real time, on a
#: serial port or the simulated device) or need hardware: checked against the parser above, and
#: run by tests/test_live.py on short durations instead.
NOT_RUN = ("active-contacts live ", "active-contacts estimate designs/speed_hold_live.toml --record out/sim")


@pytest.mark.slow
def test_console_blocks_run(tmp_path: Path) -> None:
    # Each page's commands, in order, in a fresh folder holding the repository's designs: every
    # one exits 0 (make lines are what CI itself runs: `make test`, `make docs`).
    import os
    import shlex
    import sys

    (tmp_path / "designs").symlink_to(ROOT / "designs")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    ran = 0
    for page, line in _commands():
        if not line.startswith("active-contacts ") or line.startswith(NOT_RUN):
            continue
        args = shlex.split(line)[1:]
        done = subprocess.run([sys.executable, "-m", "toolkit.cli", *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, (page.name, line, done.stderr[-2000:])
        ran += 1
    assert ran >= 4


# -- what module docstrings hold, and what no text of the package carries

#: A module docstring says what the module holds (python-control's style); derivations live in docs/.
MAX_DOCSTRING_LINES = 15


def _docstring_lines(path: Path) -> int:
    import ast

    doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=False)
    return len(doc.strip().splitlines()) if doc else 0


def test_module_docstrings_say_what_the_module_holds_in_15_lines() -> None:
    sizes = {str(p.relative_to(ROOT)): _docstring_lines(p) for p in _tracked("toolkit") if p.suffix == ".py"}
    assert len(sizes) > 50
    over = {name: n for name, n in sizes.items() if n > MAX_DOCSTRING_LINES}
    assert over == {}, over


#: A module holds one concept (STYLE.md); past this many lines it holds several.
MAX_MODULE_LINES = 800


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_no_module_is_over_800_lines() -> None:
    sizes = {str(p.relative_to(ROOT)): _lines(p) for p in _tracked("toolkit") if p.suffix == ".py"}
    assert len(sizes) > 50
    over = {name: n for name, n in sizes.items() if n > MAX_MODULE_LINES}
    assert over == {}, over


#: The longest function a kernel module may hold, lines (a kernel reads as one screen or two).
MAX_KERNEL_LINES = 120


def test_no_kernel_is_over_120_lines() -> None:
    import ast

    lengths = {}
    for path in _tracked("toolkit/_compiled"):
        if path.suffix == ".py":
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.FunctionDef):
                    lengths[f"{path.name}:{node.name}"] = node.end_lineno - node.lineno + 1
    assert len(lengths) > 100
    assert {name: n for name, n in lengths.items() if n > MAX_KERNEL_LINES} == {}


#: History lives in git: no load figure and no issue number in the package, the README, the
#: docs or the notebooks.
HISTORY = re.compile(r"load (average )?(of |about )?[0-9]|issues? [0-9]+", re.I)


def test_no_load_figures_or_issue_numbers() -> None:
    found = []
    for path in _tracked("toolkit", "docs", "notebooks") + [ROOT / "README.md"]:
        if path.suffix in (".py", ".md", ".toml", ".ipynb", ".rst", ".txt"):
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if HISTORY.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:80]}")
    assert found == []
    assert HISTORY.search("the load average 2.8 on 2 cores") and HISTORY.search("issue 32, row 6")


#: A token that could name a commit: 7 to 40 hexadecimal digits, a letter and a digit among them.
HEXLIKE = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")


def test_no_commit_is_cited() -> None:
    # Every token of the package, the README and the docs that names a commit of this
    # repository (git resolves it) is history in the wrong place.
    tokens = {}
    for path in _tracked("toolkit", "docs") + [ROOT / "README.md"]:
        if path.suffix in (".py", ".md", ".toml", ".rst", ".txt"):
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                for token in HEXLIKE.findall(line):
                    tokens.setdefault(token, f"{path.relative_to(ROOT)}:{number}")
    check = subprocess.run(["git", "-C", str(ROOT), "cat-file", "--batch-check"], input="".join(
        f"{token}^{{commit}}\n" for token in tokens), capture_output=True, text=True, check=True)
    named = [where for where, answer in zip(tokens.values(), check.stdout.splitlines())
             if not answer.endswith("missing") and " commit " in answer]
    assert named == []
    assert HEXLIKE.findall("base 8ca862c, colour 1f77b4, a facade, abc1234") == ["8ca862c", "abc1234"]
