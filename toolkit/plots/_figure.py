"""What every figure shares: making axes with or without ``pyplot``, titles, notes, thinning
many lines, and rendering to PNG bytes.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

#: Most contact-speed lines drawn in one panel; larger sets are thinned (and the panel says so).
MAX_LINES = 50
#: Drawing order: contact speeds < prediction < exact simulation < target.
_Z_CONTACTS, _Z_PREDICTION, _Z_EXACT, _Z_TARGET = 1.0, 3.0, 4.0, 6.0


#: Set inside :func:`offscreen`: figures are made without pyplot.
_OFFSCREEN: contextvars.ContextVar[bool] = contextvars.ContextVar("toolkit_plots_offscreen", default=False)


@contextlib.contextmanager
def offscreen() -> Iterator[None]:
    """Within this context the functions of :mod:`toolkit.plots` draw new figures as plain
    :class:`matplotlib.figure.Figure` objects, outside ``pyplot``: no backend is chosen or
    used, nothing is shown, nothing needs closing (for figures that only go to files)."""
    token = _OFFSCREEN.set(True)
    try:
        yield
    finally:
        _OFFSCREEN.reset(token)


def _subplots(nrows: int, ncols: int, figsize: tuple[float, float], **options: Any) -> np.ndarray:
    """A new figure's axes, shape (nrows, ncols): with ``pyplot`` (the user's backend), or
    :func:`offscreen` without it."""
    if _OFFSCREEN.get():
        from matplotlib.figure import Figure

        return Figure(figsize=figsize, layout="constrained").subplots(nrows, ncols, squeeze=False, **options)
    import matplotlib.pyplot as plt

    _, axes = plt.subplots(nrows, ncols, figsize=figsize, layout="constrained", squeeze=False, **options)
    return axes


def _figure(nrows: int = 1, figsize: tuple[float, float] = (6.0, 4.0)):
    return tuple(_subplots(nrows, 1, figsize, sharex=nrows > 1)[:, 0])


def _axes(ax: Any, figsize: tuple[float, float] = (6.0, 4.0)):
    return ax if ax is not None else _figure(1, figsize)[0]


def _title(ax: Any, title: str | None, what: str) -> None:
    """``"<title>: <what>"`` (the scene name first), or ``what`` alone."""
    ax.set_title(f"{title}: {what}" if title else what, fontsize="medium")


def _note(ax: Any, text: str, *, corner: str = "lower left", color: str = "0.25") -> None:
    """A small text note in a corner of the axes (axes coordinates)."""
    x, ha = (0.01, "left") if corner.endswith("left") else (0.99, "right")
    y, va = (0.01, "bottom") if corner.startswith("lower") else (0.99, "top")
    ax.text(x, y, text, transform=ax.transAxes, ha=ha, va=va, fontsize="x-small", color=color,
            gid="note")


def _thinned(n: int, order: np.ndarray | None = None) -> np.ndarray:
    """Indices of at most ``MAX_LINES`` of ``n`` lines, evenly spread over ``order``
    (e.g. the contacts sorted by speed, so the drawn ones span the whole set)."""
    order = np.arange(n) if order is None else np.asarray(order)
    if n <= MAX_LINES:
        return order
    return order[np.unique(np.linspace(0, n - 1, MAX_LINES).round().astype(int))]


def _thinning_note(ax: Any, shown: int, n: int) -> None:
    if shown < n:
        _note(ax, f"showing {shown} of {n} contact speeds", corner="upper left")



def figure_png(ax: Any) -> bytes:
    """Render the figure of ``ax`` (an Axes or a sequence of Axes of one figure, as
    :func:`plot_schedule` returns) to PNG bytes; a figure ``pyplot`` manages is closed."""
    import io

    if isinstance(ax, Sequence) or isinstance(ax, np.ndarray):
        ax = next(iter(np.ravel(np.asarray(ax, dtype=object))))
    figure = ax.figure
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=120)
    if getattr(figure.canvas, "manager", None) is not None:      # made by pyplot
        import matplotlib.pyplot as plt

        plt.close(figure)
    return buffer.getvalue()


def render_png(draw: Callable[..., Any], *args: Any, **kwargs: Any) -> bytes:
    """``draw(*args, **kwargs)`` (a function of :mod:`toolkit.plots`) :func:`offscreen`, rendered to
    PNG bytes: what the reports write."""
    with offscreen():
        return figure_png(draw(*args, **kwargs))
