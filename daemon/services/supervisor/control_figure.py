"""The figure of a control run: A/L with the law's set-point, f, and the wind speed (asked, applied,
written, read back) against time. Headless (Agg); matplotlib is imported when drawn."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flagtrack.drivers.atomic import atomic_path


def _column(records: Sequence[dict[str, Any]], get: Any) -> list[float]:
    values = []
    for record in records:
        try:
            value = get(record)
        except (KeyError, TypeError):
            value = None
        values.append(float(value) if isinstance(value, int | float) and value is not None else math.nan)
    return [v if math.isfinite(v) and v != -1.0 else math.nan for v in values]


def plot_control(records: Sequence[dict[str, Any]], path: str | Path, title: str = "") -> Path:
    """Save the figure of a control log's ``records`` at ``path`` (PNG), atomically."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    steps = [r for r in records if r.get("requester", "law") == "law"]
    t = _column(steps, lambda r: r["t_s"])
    fig = Figure(figsize=(7.0, 7.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax_amp, ax_f, ax_speed = fig.subplots(3, 1, sharex=True, height_ratios=(2, 1, 1.5))
    ax_amp.plot(t, _column(steps, lambda r: r["state"]["amplitude_over_l"]), ".", ms=3, color="C0", label="A/L (cycle)")
    ax_amp.plot(t, _column(steps, lambda r: r["setpoint"]), "-", color="k", lw=1, label="set-point")
    ax_amp.set_ylabel("A/L")
    ax_amp.legend(loc="best", fontsize="small")
    ax_f.plot(t, _column(steps, lambda r: r["state"]["frequency_hz"]), ".", ms=3, color="C2")
    ax_f.set_ylabel("f (Hz)")
    ax_speed.plot(t, _column(steps, lambda r: r["asked_mps"]), "x", ms=3, color="C3", label="asked")
    ax_speed.plot(t, _column(steps, lambda r: r["applied_mps"]), "-", color="C1", lw=1, label="applied")
    ax_speed.plot(t, _column(steps, lambda r: r["state"]["speed_mps"]), "-", color="C0", lw=1, label="read back")
    requests = [r for r in records if r.get("requester", "law") != "law"]
    if requests:
        ax_speed.plot(_column(requests, lambda r: r["t_s"]), _column(requests, lambda r: r["applied_mps"]), "s",
                      ms=4, color="C4", label="requests (applied)")  # fmt: skip
    ax_speed.set_ylabel("speed (m/s)")
    ax_speed.set_xlabel("time since the loop began (s)")
    ax_speed.legend(loc="best", fontsize="small")
    if title:
        ax_amp.set_title(title, fontsize="medium")
    with atomic_path(path, keep_suffix=True) as tmp:
        fig.savefig(tmp, dpi=110)
    return Path(path)
