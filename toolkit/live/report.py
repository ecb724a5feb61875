"""What a live run leaves behind: ``record.csv`` (the counts, the commands sent, the receive and
answer times and the estimates: :mod:`toolkit.model.record_io`), ``truth.csv`` (a simulated
device's own record with the truth), ``result.json`` and ``live.png``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..model.record_io import LiveColumns, record_csv_text

__all__ = ["live_score", "live_to_dict", "live_files", "live_lines"]


def live_score(result: Any, truth: Any) -> dict[str, float] | None:
    """The estimates against a simulated device's truth, matched by sequence number: RMS and
    largest error (m/s), and the true speed at the last sample (m/s); None without truth."""
    if truth is None or truth.truth_speed is None or result.record is None:
        return None
    taken = result.sequence < truth.n_samples
    true = truth.truth_speed[result.sequence[taken]]
    error = result.estimate[taken] - true
    return {"estimate_rms_error": float(np.sqrt(np.mean(error ** 2))),
            "estimate_max_error": float(np.max(np.abs(error))), "final_speed": float(true[-1])}


def live_to_dict(result: Any, truth: Any = None, device: dict[str, Any] | None = None) -> dict[str, Any]:
    """JSON-able: how the run ended, the handshake, the deadline statistics, the score
    against the truth (None without) and the simulated device's own tallies (None without)."""
    hello = result.hello
    last = result.record.times[-1] if result.record is not None else math.nan
    return {"status": result.status.name, "message": result.message, "period": result.period,
            "duration": float(last),
            "hello": None if hello is None else {"version": hello.version, "wheels": hello.wheels,
                                                  "rate": hello.rate, "central_cpr": hello.central_cpr,
                                                  "wheel_cpr": hello.wheel_cpr},
            "timing": result.timing(), "score": live_score(result, truth), "device": device}


def live_files(result: Any, truth: Any = None, device: dict[str, Any] | None = None, *, name: str = "",
               plots_too: bool = True) -> dict[str, bytes]:
    """``result.json`` and, when a sample came, ``record.csv`` and (``plots_too``) ``live.png``;
    ``truth.csv`` with a simulated device's truth."""
    from ..scenes.report import to_json

    files = {"result.json": to_json({"scene": name, **live_to_dict(result, truth, device)}).encode()}
    if result.record is not None:
        live = LiveColumns(result.sequence, result.received, result.answered, result.estimate, result.variance)
        files["record.csv"] = record_csv_text(result.record, "live_files", live).encode()
        if plots_too:
            from .. import plots

            files["live.png"] = plots.render_png(plots.plot_live, result, truth, title=name)
    if truth is not None:
        files["truth.csv"] = record_csv_text(truth, "live_files").encode()
    return files


def live_lines(result: Any, truth: Any = None) -> list[str]:
    """The summary a terminal shows: how the run ended, the deadlines, the score."""
    lines = [f"live loop: {result.message}", result.summary()]
    score = live_score(result, truth)
    if score is not None:
        lines.append(f"against the simulated truth: estimate RMS error {score['estimate_rms_error'] * 1e3:.3f} mm/s, "
                     f"max {score['estimate_max_error'] * 1e3:.3f} mm/s; true speed at the end "
                     f"{score['final_speed']:.6f} m/s")
    return lines
