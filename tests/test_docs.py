"""Citations in the code point at documents and sections that exist."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


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
        assert "PHYSICS.md" not in text, f"{path.relative_to(ROOT)} cites PHYSICS.md (not in the repository)"
        for name in cited.findall(text):
            assert (ROOT / name).exists(), f"{path.relative_to(ROOT)} cites {name}, which does not exist"
