"""Citations in the code point at documents and sections that exist."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

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
