"""The command line's entry point and its process: Ctrl-C and SIGTERM, a closed or vanished
standard output, and the notice of kernels compiling.
"""

from __future__ import annotations

import contextlib
import signal
import sys
from collections.abc import Iterator, Sequence
from typing import Any

from ._common import EXIT_INTERRUPTED, EXIT_OK, EXIT_PIPE, EXIT_USAGE
from ._parser import parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``active-contacts`` console script; returns the exit code.

    Everything past the standard library is imported in here, under the same handlers as the
    work: a Ctrl-C at any moment (while numpy loads, while workers start, while outputs are
    written) ends with one line and exit 130, never a traceback."""
    if sys.stdout is None:             # started with its standard output closed (>&-)
        return _stdout_closed()
    interrupted, previous = _interrupts_noted()
    try:
        with _interrupts_deferred(interrupted):
            try:
                args = parser().parse_args(argv)
            except SystemExit as done:  # --help, --version or a usage error: printed already
                raise SystemExit(_flushed(done.code)) from None
            from ..errors import ToolkitError
            from ..scenes import build, report, study  # noqa: F401  (what every command runs on)

        try:
            with _compiles_announced():
                code = args.handler(args)
            sys.stdout.flush()         # a write error found here is still this command's
            return code
        except ToolkitError as error:
            print(f"active-contacts: error: {error}", file=sys.stderr)
            return EXIT_USAGE
        except BrokenPipeError:
            if not _stdout_gone():
                raise
            return _reader_gone()
        except OSError as error:  # found only while writing: a full disk, a folder removed meanwhile
            print(f"active-contacts: error: cannot write the output: {error}", file=sys.stderr)
            return EXIT_USAGE
    except KeyboardInterrupt:
        print("active-contacts: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception:
        if not interrupted:
            raise
        # What a Ctrl-C broke off (a compiled module's import turns it into an ImportError).
        print("active-contacts: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _stdout_closed() -> int:
    """Exit 2 with one line: the command has nowhere to write its results."""
    if sys.stderr is not None:
        print("active-contacts: error: the standard output is closed; the command writes its results "
              "there (redirect it to a file, or to /dev/null to discard them).", file=sys.stderr)
    return EXIT_USAGE


def _flushed(code: Any) -> int:
    """``code`` once the standard output is flushed; a reader gone meanwhile ends quietly."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        return _reader_gone()
    return code if isinstance(code, int) else EXIT_USAGE if code else EXIT_OK


def _stdout_gone() -> bool:
    """Whether the standard output is a pipe whose reader has closed it (``| head``)."""
    try:
        import select

        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):    # no poll (Windows), no descriptor: assume so
        return True


def _reader_gone() -> int:
    """End quietly as a Unix filter does when its reader stops reading (exit 141, 128 +
    SIGPIPE); the standard output is pointed at /dev/null so the final flush stays silent."""
    import os

    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):
        pass
    return EXIT_PIPE


@contextlib.contextmanager
def _interrupts_deferred(noted: list[int]) -> Iterator[None]:
    """While the command line imports what it runs on, Ctrl-C and SIGTERM are only noted, and
    raised once the imports are done: an interrupt raised inside an import may be turned into
    an ImportError (a compiled module's import does so) and then swallowed by a guard for an
    optional dependency, and the command would run on."""
    try:
        handlers = {signum: signal.signal(signum, lambda signum, frame: noted.append(signum))
                    for signum in (signal.SIGINT, signal.SIGTERM)}
    except ValueError:                 # not the main thread
        yield
        return
    try:
        yield
    finally:
        for signum, handler in handlers.items():
            signal.signal(signum, handler)
    if noted:
        raise KeyboardInterrupt(f"signal {noted[0]}")


def _interrupts_noted() -> tuple[list[int], dict[int, Any]]:
    """Ctrl-C (SIGINT) and SIGTERM raise ``KeyboardInterrupt`` (workers stopped, partial
    outputs removed, exit 130) and are noted in the returned list, so that an error they
    cause is known for what it is; returns it and the previous handlers (none off the main
    thread, where signals are not ours to take)."""
    noted: list[int] = []

    def interrupt(signum: int, frame: Any) -> None:
        noted.append(signum)
        raise KeyboardInterrupt(f"signal {signum}")

    previous: dict[int, Any] = {}
    try:
        for signum in (signal.SIGINT, signal.SIGTERM):
            previous[signum] = signal.signal(signum, interrupt)
    except ValueError:                 # not the main thread (an embedding caller's thread)
        pass
    return noted, previous


@contextlib.contextmanager
def _compiles_announced() -> Iterator[None]:
    """Say on stderr when kernels compile (a first run on an empty cache): one line before the
    first compile, a progress bar over the kernels where stderr is a terminal, and the time
    they took at the end of the command. Never on stdout; loading from the cache says nothing."""
    from .. import _compiled

    state: dict[str, Any] = {"bar": None, "count": 0, "seconds": 0.0}
    stream = sys.stderr              # (bound now: a command may redirect its own stderr)

    def listener(event: str, kernel: str, seconds: float) -> None:
        if event == "start":
            if state["count"] == 0 and state["bar"] is None:
                note = _compiled.cache_note()
                print("active-contacts: compiling kernels (first run only: cached for the next runs"
                      + (f"; {note}" if note else "") + ")", file=stream, flush=True)
                if stream.isatty():
                    from tqdm import tqdm

                    state["bar"] = tqdm(desc="compiling", unit=" kernels", file=stream, leave=False)
            if state["bar"] is not None:
                state["bar"].set_postfix_str(kernel, refresh=True)
            return
        state["count"] += 1
        state["seconds"] += seconds
        if state["bar"] is not None:
            state["bar"].update(1)

    previous = _compiled.on_compile(listener)
    try:
        yield
    finally:
        _compiled.on_compile(previous)
        if state["bar"] is not None:
            state["bar"].close()
        if state["count"]:
            print(f"active-contacts: compiled {state['count']} kernels in {state['seconds']:.1f} s "
                  "(not charged to any budget)", file=stream, flush=True)
