"""Figures of the sensor comparison, in the manner of the paper's figure 5c-e (one point) and 5g (a sweep).

Headless (Agg canvas, no pyplot state).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.validation.point import PointValidation


def _figure(size: tuple[float, float]) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _window(t_s: np.ndarray, window_s: float) -> tuple[float, float]:
    """A window of ``window_s`` in the middle of ``t_s``'s span (the whole span if shorter)."""
    t0, t1 = float(t_s[0]), float(t_s[-1])
    if t1 - t0 <= window_s:
        return t0, t1
    mid = 0.5 * (t0 + t1)
    return mid - 0.5 * window_s, mid + 0.5 * window_s


def plot_point(v: PointValidation, path: str | Path, title: str = "", window_s: float = 0.3) -> Path:
    """Save the point's figure: y/L of sensor and reconstruction at the beam, e/L below, Delta_RMS/L below that.

    Only ``window_s`` of the record (its middle) is drawn, so flapping cycles stay visible; the
    statistics in the title are over the whole record.
    """
    fig = _figure((7.5, 6.8))
    ax_y, ax_e, ax_d = fig.subplots(3, 1, sharex=True, height_ratios=(2, 1, 1))
    length = v.frame.length
    c = v.comparison
    span = c.t_s if c is not None and len(c.t_s) else v.t_recon_s
    if len(span) == 0:
        ax_y.text(0.5, 0.5, v.status, ha="center", va="center", transform=ax_y.transAxes)
    else:
        lo, hi = _window(span, window_s)
        rec = (v.t_recon_s >= lo) & (v.t_recon_s <= hi)
        if v.n_stale:  # updates without events (lost camera data), drawn but not compared
            ax_y.plot(
                v.t_recon_s[rec],
                v.y_recon[rec] / length,
                color="0.7",
                linewidth=0.8,
                label="camera, updates without events",
            )
        y_used = np.where(v.stale, np.nan, v.y_recon)
        ax_y.plot(v.t_recon_s[rec], y_used[rec] / length, color="C0", linewidth=1.0, label="event-based camera")
        ax_d.plot(v.t_recon_s[rec], v.delta_rms[rec] / length, color="C2", linewidth=0.8)
        if c is not None:
            sen = (c.t_s >= lo) & (c.t_s <= hi)
            ax_y.plot(
                c.t_s[sen], (c.y_sensor[sen] + c.bias) / length, ".", color="C3", markersize=2.0, label="point sensor"
            )
            ax_e.plot(c.t_s[sen], c.error[sen] / length, color="C1", linewidth=0.8)
        ax_y.legend(loc="upper right", fontsize=8)
    ax_y.set_ylabel(f"y/L at x/L = {v.x_over_l:.2f}")
    ax_e.set_ylabel("e/L")
    ax_d.set_ylabel(r"$\Delta_{RMS}/L$")
    ax_d.set_xlabel("t (s, camera clock)")
    ax_y.set_title(title + ("\n" if title else "") + _stats(v), fontsize=9)
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def _stats(v: PointValidation) -> str:
    f = v.fields()
    d_mean, d_std = v.delta_rms_over_l
    sync = v.sync
    sync_text = (
        f"sync {sync.method} {sync.offset_us / 1e3:+.3f} ms ± {sync.uncertainty_us:.1f} µs"
        if sync.ok and math.isfinite(sync.uncertainty_us)
        else f"sync {sync.method}"
    )
    return (
        f"{v.status}; e/L RMS {_pct(f['sensor_error_rms_over_l'])}, max {_pct(f['sensor_error_max_over_l'])}; "
        f"ΔRMS/L {_pct(d_mean)} ± {_pct(d_std)}\n{sync_text}; {v.n_samples} samples, {v.n_missing} missing"
        + (f"\n{v.n_stale} updates without events (lost camera data) not compared" if v.n_stale else "")
    )


def _pct(value: Any) -> str:
    return "n/a" if value is None or not math.isfinite(float(value)) else f"{100 * float(value):.2f} %"
