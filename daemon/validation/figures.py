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
    """Save :func:`point_figure` as a PNG."""
    path = Path(path)
    point_figure(v, title, window_s).savefig(path, dpi=110)
    return path


def point_figure(v: PointValidation, title: str = "", window_s: float = 0.3) -> Any:
    """The point's figure: y/L of sensor and reconstruction at the beam, e/L below, Delta_RMS/L below that.

    Only ``window_s`` of the record (its middle) is drawn, so flapping cycles stay visible: the top
    panel says it is an excerpt, each panel gives the excerpt's own statistics, and the title the whole
    point's (named so). Errors and distances are in % of L. Delta_RMS is drawn with a marker per
    update, so the few updates of a still flag that have events show.
    """
    fig = _figure((7.5, 7.0))
    ax_y, ax_e, ax_d = fig.subplots(3, 1, sharex=True, height_ratios=(2, 1, 1))
    span = _times(v)
    if len(span) == 0:
        ax_y.text(0.5, 0.5, v.status, ha="center", va="center", transform=ax_y.transAxes)
    else:
        lo, hi = _window(span, window_s)
        whole_s = float(span[-1] - span[0])
        shown = (
            "the whole point" if hi - lo >= whole_s else f"an excerpt: {hi - lo:.2f} s of the point's {whole_s:.2f} s"
        )
        ax_y.set_title(f"{shown} (t = {lo:.2f} to {hi:.2f} s); each panel's statistics are of what it shows",
                       fontsize=8)  # fmt: skip
        _draw_y(ax_y, v, lo, hi)
        _draw_e(ax_e, v, lo, hi)
        _draw_delta(ax_d, v, lo, hi)
    ax_y.set_ylabel(f"y/L at x/L = {v.x_over_l:.2f}")
    ax_e.set_ylabel("e/L (% of L)")
    ax_d.set_ylabel(r"$\Delta_{RMS}/L$ (% of L)")
    ax_d.set_xlabel("t (s, camera clock)")
    fig.suptitle(title + ("\n" if title else "") + _stats(v), fontsize=9)
    return fig


def _times(v: PointValidation) -> np.ndarray:
    """The times the point's figure spans: the compared sensor samples', else the reconstruction's."""
    c = v.comparison
    return c.t_s if c is not None and len(c.t_s) else v.t_recon_s


def _draw_y(ax: Any, v: PointValidation, lo: float, hi: float) -> None:
    length, c = v.frame.length, v.comparison
    rec = (v.t_recon_s >= lo) & (v.t_recon_s <= hi)
    if v.n_stale:  # updates without events (lost camera data), drawn but not compared
        ax.plot(v.t_recon_s[rec], v.y_recon[rec] / length, color="0.7", linewidth=0.8,
                label="camera, updates without events")  # fmt: skip
    y_used = np.where(v.stale, np.nan, v.y_recon)
    ax.plot(v.t_recon_s[rec], y_used[rec] / length, color="C0", linewidth=1.0, label="event-based camera")
    if c is not None:
        sen = (c.t_s >= lo) & (c.t_s <= hi)
        ax.plot(c.t_s[sen], (c.y_sensor[sen] + c.bias) / length, ".", color="C3", markersize=2.0, label="point sensor")
    ax.legend(loc="upper right", fontsize=8)


def _draw_e(ax: Any, v: PointValidation, lo: float, hi: float) -> None:
    c = v.comparison
    if c is None:
        _note(ax, f"no comparison: {v.status}")
        return
    sen = (c.t_s >= lo) & (c.t_s <= hi)
    e_pct = 100 * c.error[sen] / v.frame.length
    ax.plot(c.t_s[sen], e_pct, color="C1", linewidth=0.8)
    if len(e_pct):
        _note(ax, f"shown: e/L RMS {_pct(np.sqrt(np.mean(e_pct**2)) / 100)}, "
                  f"|e|/L max {_pct(np.max(np.abs(e_pct)) / 100)} ({len(e_pct)} samples)")  # fmt: skip


def _draw_delta(ax: Any, v: PointValidation, lo: float, hi: float) -> None:
    rec = (v.t_recon_s >= lo) & (v.t_recon_s <= hi)
    d_pct = 100 * v.delta_rms[rec] / v.frame.length
    finite = np.isfinite(d_pct)
    ax.plot(v.t_recon_s[rec], d_pct, color="C2", linewidth=0.8, marker=".", markersize=3)
    if finite.any():
        values = d_pct[finite]
        _note(ax, f"shown: mean {_pct(values.mean() / 100)}, std {_pct(values.std() / 100)}; "
                  f"{int(finite.sum())} of {len(d_pct)} updates had events")  # fmt: skip
    else:
        _note(ax, f"none of the {len(d_pct)} updates shown had events (a still flag gives few)")


def _note(ax: Any, text: str) -> None:
    ax.text(0.01, 0.97, text, transform=ax.transAxes, va="top", ha="left", fontsize=7,
            bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "edgecolor": "none", "alpha": 0.8})  # fmt: skip


def _stats(v: PointValidation) -> str:
    """The whole point's statistics (named so), the sync and the sample counts."""
    f = v.fields()
    d_mean, d_std = v.cloud_distance_over_l
    sync = v.sync
    sync_text = (
        f"sync {sync.method} {sync.offset_us / 1e3:+.3f} ms ± {sync.uncertainty_us:.1f} µs"
        if sync.ok and math.isfinite(sync.uncertainty_us)
        else f"sync {sync.method}"
    )
    times = _times(v)
    span = float(times[-1] - times[0]) if len(times) > 1 else 0.0
    return (
        f"{v.status}; whole point ({span:.2f} s): e/L RMS {_pct(f['sensor_error_rms_over_l'])}, "
        f"|e|/L max {_pct(f['sensor_error_max_over_l'])}; "
        + r"$\Delta_{RMS}/L$"
        + f" mean {_pct(d_mean)}, std {_pct(d_std)}\n"
        f"{sync_text}; {v.n_samples} samples, {v.n_missing} missing"
        + (f"\n{v.n_stale} updates without events (lost camera data) not compared" if v.n_stale else "")
    )


def _pct(value: Any) -> str:
    return "n/a" if value is None or not math.isfinite(float(value)) else f"{100 * float(value):.2f} %"
