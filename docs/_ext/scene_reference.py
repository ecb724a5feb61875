"""Sphinx extension: writes ``reference/scenes.rst`` from the scene keys' declaration when a build starts.

The page is :func:`toolkit.scenes.reference.render`'s text; it is written only when it changed,
so an unchanged declaration does not make Sphinx read the page again.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: The page's docname under the documentation source folder.
DOCNAME = "reference/scenes"


def write_page(app: Any) -> None:
    """Render the scene reference into the source folder (``builder-inited``)."""
    from toolkit.scenes.reference import render

    target = Path(app.srcdir) / f"{DOCNAME}.rst"
    text = render()
    if not target.is_file() or target.read_text(encoding="utf-8") != text:
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text, encoding="utf-8")


def setup(app: Any) -> dict[str, Any]:
    app.connect("builder-inited", write_page)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
