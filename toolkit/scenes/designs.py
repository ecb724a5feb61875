"""The designs shipped with the package: scene files installed as package data.

They are read through :mod:`importlib.resources`, so they work from an installed wheel as
well as from a checkout (where ``designs/`` at the repository root points at them).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from importlib import resources
from pathlib import Path

from ..errors import suggestion
from ..errors import OutputError, ParameterError, parameter_message

__all__ = ["design_names", "design_text", "load_design", "copy_designs", "design_path"]

_PACKAGE = "toolkit"
_FOLDER = "designs"


def _folder() -> resources.abc.Traversable:
    return resources.files(_PACKAGE) / _FOLDER


def design_names() -> tuple[str, ...]:
    """Names of the shipped designs (file stems, sorted), e.g. ``"carousel"``."""
    return tuple(sorted(item.name[:-5] for item in _folder().iterdir() if item.name.endswith(".toml")))


def design_text(name: str) -> str:
    """The TOML text of the shipped design ``name`` (with or without ``.toml``)."""
    names = design_names()
    stem = name[:-5] if isinstance(name, str) and name.endswith(".toml") else name
    if stem not in names:
        hint = suggestion(str(stem), names) or f" Shipped designs: {', '.join(names)}."
        raise ParameterError(parameter_message("name", "design_text", "name a shipped design", name)
                             + hint)
    return (_folder() / f"{stem}.toml").read_text(encoding="utf-8")


@contextmanager
def design_path(name: str) -> Iterator[Path]:
    """A file system path of the shipped design ``name`` while the ``with`` block runs (for
    a command run in another process); from a zipped install, a temporary copy."""
    design_text(name)                  # refuses an unknown name with the shipped ones
    stem = name[:-5] if name.endswith(".toml") else name
    with resources.as_file(_folder() / f"{stem}.toml") as path:
        yield path


def load_design(name: str):
    """The shipped design ``name`` as a parsed :class:`~toolkit.scenes.spec.Scene`."""
    from .spec import loads_scene

    stem = name[:-5] if name.endswith(".toml") else name
    return loads_scene(design_text(name), name=stem)


def copy_designs(target: str | Path) -> list[Path]:
    """Write every shipped design into the folder ``target`` (created if needed) for editing.

    Existing files of the same names are not overwritten: the call refuses before writing
    anything when one exists.

    Returns
    -------
    list of Path
        The files written.
    """
    folder = Path(target)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"Cannot copy the designs into {str(folder)!r}: it exists and is not a folder.")
    names = design_names()
    taken = [folder / f"{name}.toml" for name in names if (folder / f"{name}.toml").exists()]
    if taken:
        raise OutputError(f"Cannot copy the designs into {str(folder)!r}: {taken[0].name} is already "
                          f"there ({len(taken)} of {len(names)} files exist); choose an empty folder.")
    written: list[Path] = []
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name in names:
            path = folder / f"{name}.toml"
            path.write_text(design_text(name), encoding="utf-8")
            written.append(path)
    except OSError as error:
        for path in written:           # all or nothing: remove what this call wrote
            path.unlink(missing_ok=True)
        raise OutputError(f"Cannot copy the designs into {str(folder)!r}: {error.strerror or error}.") from None
    return written
