"""All-or-nothing file output (private).

:func:`atomic_write_bytes` writes one file whole or not at all. :func:`write_tree` writes a
whole output folder that way: every file goes into a temporary folder beside the target,
which then replaces the target in one rename, so a failure leaves either the previous
outputs or none. :func:`check_output_dir` refuses, before any work, a target that cannot
be written (an existing non-folder, a parent that is a file or not writable, a folder
holding files the toolkit did not write).

Files and folders get the usual modes: ``0o666`` and ``0o777`` less the umask (0644 and
0755 with umask 022).
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

from ..errors import OutputError

__all__ = ["OUTPUT_NAMES", "OutputError", "atomic_write_bytes", "atomic_write_text", "check_output_dir",
           "check_output_file", "claim_output_dir", "write_tree"]

#: Every file name the toolkit writes into an output folder. A folder that holds anything
#: else is not the toolkit's and is never replaced.
OUTPUT_NAMES = frozenset({"result.json", "force_curve.png", "simulation.png", "schedule.png",
                          "schedule.csv", "schedule.json", "precision.json", "precision.png",
                          "estimation.png", "closed_loop.png", "estimate.json", "estimate.png", "estimate.csv",
                          "results.csv", "record.csv", "truth.csv", "live.png", "sweep.json", "sweep.png", "planar.json", "planar.png", "planar_precision.png"})


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_output_dir(path: str | os.PathLike[str]) -> Path:
    """Refuse an output folder that :func:`write_tree` could not replace.

    Raises
    ------
    OutputError
        ``path`` exists and is not a folder, or holds something other than toolkit output
        files (:data:`OUTPUT_NAMES`); its nearest existing parent is not a folder or not
        writable.
    """
    target = Path(path)
    shown = repr(str(target))
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        raise OutputError(f"cannot write the output: {shown} exists and is not a folder")
    if target.is_dir():
        foreign = sorted(entry.name for entry in os.scandir(target)
                         if entry.name not in OUTPUT_NAMES or not entry.is_file(follow_symlinks=False))
        if foreign:
            raise OutputError(f"cannot write the output: the folder {shown} holds files the toolkit did "
                              f"not write ({', '.join(foreign[:3])}{', ...' if len(foreign) > 3 else ''}); "
                              "choose a new or empty folder")
    parent = target.absolute().parent
    while not os.path.lexists(parent) and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(f"cannot write the output: {str(parent)!r} (a parent of {shown}) is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write the output: the folder {str(parent)!r} is not writable")
    _probe(parent)
    return target


def _probe(parent: Path) -> None:
    """Make and remove a folder in ``parent``, as the writers do first: a file system such as
    /proc refuses it even where :func:`os.access` says writable (a superuser)."""
    try:
        os.rmdir(tempfile.mkdtemp(dir=parent, prefix=".active-contacts.", suffix=".probe"))
    except OSError as error:
        raise OutputError(f"cannot write the output: nothing can be made in the folder {str(parent)!r} "
                          f"({error.strerror})") from None


def check_output_file(path: str | os.PathLike[str]) -> Path:
    """Refuse, before any work, an output file that :func:`atomic_write_bytes` could not write:
    an existing folder (or a non-regular file), a parent that is not a writable folder."""
    target = Path(path)
    shown = repr(str(target))
    if os.path.lexists(target) and not target.is_file():
        raise OutputError(f"cannot write the output: {shown} exists and is not a regular file")
    parent = target.absolute().parent
    if not parent.is_dir():
        raise OutputError(f"cannot write the output: the folder {str(parent)!r} of {shown} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write the output: the folder {str(parent)!r} is not writable")
    _probe(parent)
    return target


@contextmanager
def claim_output_dir(path: str | os.PathLike[str] | None) -> Iterator[Path | None]:
    """Check an output folder before any work and hold it for this run until the block ends.

    Two runs into one folder would both write and both say so, though only the last one's
    files survive: the second run to claim a folder is refused here, before any work. The
    claim is an advisory lock (``flock``) on a file named after the folder's absolute path
    in the system's temporary folder, so nothing is written beside the outputs; it ends
    with the block or with the process.

    Yields
    ------
    Path or None
        The checked folder (``None`` in, ``None`` out: a command without ``--out``).

    Raises
    ------
    OutputError
        The folder cannot be written (:func:`check_output_dir`) or another run holds it.
    """
    if path is None:
        yield None
        return
    target = check_output_dir(path)
    key = hashlib.sha256(os.fsencode(os.path.abspath(target))).hexdigest()[:32]
    locks = Path(tempfile.gettempdir()) / "active-contacts-outputs"
    locks.mkdir(mode=0o1777, exist_ok=True)
    lock = locks / f"{key}.lock"
    handle = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(handle, 32, 0).decode(errors="replace").strip() or "unknown"
            raise OutputError(f"cannot write the output: another run (pid {holder}) is writing into "
                              f"{str(target)!r}; wait for it or choose another folder") from None
        os.ftruncate(handle, 0)
        os.pwrite(handle, str(os.getpid()).encode(), 0)
        yield target
    finally:
        os.close(handle)                 # releases the lock (the file stays, empty of meaning)


def _write_file(path: Path, data: bytes) -> None:
    """Write one new file (mode 0o666 less the umask) and flush it to disk."""
    with open(path, "xb") as stream:
        stream.write(data)
        stream.flush()
        os.fsync(stream.fileno())


def write_tree(path: str | os.PathLike[str], files: Mapping[str, bytes]) -> list[Path]:
    """Replace the folder ``path`` by one holding exactly ``files`` (name -> bytes), all or nothing.

    The files are written into a temporary folder beside ``path``; an existing ``path`` is
    renamed aside, the new folder renamed in, and the old one removed. On any failure the
    temporary folder is removed and the old folder (if any) is put back, so ``path`` holds
    either the previous outputs or the new ones, never a mix.

    Returns
    -------
    list of Path
        The files written, in the order given.
    """
    target = check_output_dir(path)
    parent = target.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    fresh = Path(tempfile.mkdtemp(dir=parent, prefix=f".{target.name}.", suffix=".new"))
    aside: Path | None = None
    try:
        os.chmod(fresh, 0o777 & ~_umask())
        for name, data in files.items():
            _write_file(fresh / name, data)
        if target.exists():
            aside = Path(tempfile.mkdtemp(dir=parent, prefix=f".{target.name}.", suffix=".old"))
            os.rmdir(aside)
            os.rename(target, aside)
        os.rename(fresh, target)
    except BaseException:
        shutil.rmtree(fresh, ignore_errors=True)
        if aside is not None and os.path.lexists(aside) and not os.path.lexists(target):
            os.rename(aside, target)
        raise
    if aside is not None:
        shutil.rmtree(aside, ignore_errors=True)
    return [target / name for name in files]


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename.

    On any failure the temporary file is removed and ``path`` is left as it was. The file
    gets mode ``0o666`` less the umask.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        os.fchmod(handle, stat.S_IMODE(0o666 & ~_umask()))
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, target)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise
    return target


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 ``text`` atomically; see :func:`atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode("utf-8"))
