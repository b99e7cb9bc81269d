"""Figures of a sweep run: A/L and event rate against the wind speed, and the point sensor's
comparison against the speed (paper, figure 5g). Headless (Agg); matplotlib is imported when drawn."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flagtrack.daemon.sweep.runlog import PointResult


def _figure(size: tuple[float, float]) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _zero(value: float) -> float:
    return 0.0 if not math.isfinite(value) else value


def load_figure_modules() -> None:
    """Import what :func:`plot_amplitude` draws with (about a second, the first time)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
    from matplotlib.figure import Figure  # noqa: F401


def plot_amplitude(
    points: Sequence[PointResult],
    path: str | Path,
    title: str = "",
    transitions: tuple[float | None, float | None] = (None, None),
) -> Path:
    """Save the A/L- and event-rate-versus-speed figure (PNG; headless Agg backend).

    ``transitions``: the onset and decay speeds (m/s) to mark, where detected.
    """
    fig = _figure((6.0, 6.0))
    ax_amp, ax_rate = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    styles = {"up": ("C0", "^", "full", "up"), "down": ("C1", "v", "none", "down")}
    for branch, (color, marker, fill, label) in styles.items():
        mine = [p for p in points if p.branch == branch and p.status == "done"]
        if not mine:
            continue
        speeds = [p.speed_mps for p in mine]
        ax_amp.errorbar(speeds, [p.amplitude_over_l for p in mine], yerr=[_zero(p.amplitude_std_over_l) for p in mine],
                        color=color, marker=marker, fillstyle=fill, capsize=3, linestyle="-", linewidth=0.8,
                        label=f"{label} ({len(mine)} points)")  # fmt: skip
        ax_rate.plot(
            speeds, [p.event_rate_mev_s for p in mine], color=color, marker=marker, fillstyle=fill, linewidth=0.8
        )
    _mark_suspect(ax_amp, [p for p in points if p.status == "done"])
    _mark_bad(ax_amp, points)
    onset, decay = transitions
    for speed, color, name in ((onset, "C0", "onset"), (decay, "C1", "decay")):
        if speed is not None:
            for ax in (ax_amp, ax_rate):
                ax.axvline(speed, color=color, linestyle="--", linewidth=1.0)
            ax_amp.annotate(f"{name} {speed:.2f} m/s", (speed, 0.5), xycoords=("data", "axes fraction"),
                            rotation=90, va="center", ha="center", color=color, fontsize=8,
                            bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "edgecolor": "none"})  # fmt: skip
    ax_amp.set_ylabel("tip amplitude A/L")
    ax_amp.set_title(title)
    if ax_amp.get_legend_handles_labels()[0]:
        ax_amp.legend(loc="lower right", fontsize=8)
    ax_rate.set_yscale("log")
    ax_rate.set_ylabel("event rate (Mev/s)")
    ax_rate.set_xlabel("wind speed U (m/s)")
    path = Path(path)
    fig.savefig(path, dpi=120)
    return path


def _mark_suspect(ax: Any, points: Sequence[PointResult]) -> None:
    """Ring in red the points marked suspect (the tracker lost the flag too often there)."""
    suspect = [p for p in points if getattr(p, "suspect", False)]
    if suspect:
        ax.scatter([p.speed_mps for p in suspect], [_zero(p.amplitude_over_l) for p in suspect], s=140,
                   facecolors="none", edgecolors="red", linewidths=1.5, zorder=5,
                   label=f"suspect: flag lost ({len(suspect)})")  # fmt: skip


def _mark_bad(ax: Any, points: Sequence[PointResult]) -> None:
    """Mark the points not measured as planned (``failed``, ``lossy``) as crosses at the foot of the
    amplitude panel, one per speed, labelled with their status."""
    for status, color in (("failed", "red"), ("lossy", "darkorange")):
        bad = [p for p in points if p.status == status]
        if bad:
            ax.plot([p.speed_mps for p in bad], [0.02] * len(bad), "x", color=color, markersize=8,
                    transform=ax.get_xaxis_transform(), label=f"{status} ({len(bad)} points)")  # fmt: skip


def plot_sweep(points: Sequence[Any], path: str | Path, title: str = "") -> Path:
    """Save the sweep figure (paper 5g): time mean ± std of |e|/L and Delta_RMS/L against the speed.

    Args:
        points: :class:`~flagtrack.daemon.sweep.runlog.PointResult` s (or objects with the same fields).
    """
    fig = _figure((6.0, 4.0))
    ax = fig.subplots()
    styles = {"up": ("^", "full"), "down": ("v", "none")}
    all_speeds = [p.speed_mps for p in points] or [0.0]
    dx = 0.01 * max(max(all_speeds) - min(all_speeds), 1.0)  # |e| and Delta_RMS side by side
    for branch, (marker, fill) in styles.items():
        mine = [p for p in points if p.branch == branch and math.isfinite(p.sensor_error_mean_over_l)]
        if mine:
            speeds = [p.speed_mps - dx for p in mine]
            ax.errorbar(
                speeds,
                [p.sensor_error_mean_over_l for p in mine],
                yerr=[_zero(p.sensor_error_std_over_l) for p in mine],
                color="C1",
                marker=marker,
                fillstyle=fill,
                capsize=3,
                linestyle="none",
                label=f"|e|/L ({branch})",
            )
        mine = [p for p in points if p.branch == branch and math.isfinite(p.delta_rms_over_l)]
        if mine:
            ax.errorbar(
                [p.speed_mps + dx for p in mine],
                [p.delta_rms_over_l for p in mine],
                yerr=[_zero(p.delta_rms_std_over_l) for p in mine],
                color="C2",
                marker=marker,
                fillstyle=fill,
                capsize=3,
                linestyle="none",
                label=rf"$\Delta_{{RMS}}/L$ ({branch})",
            )
    ax.axhline(0.01, color="0.6", linestyle="--", linewidth=0.8)
    ax.set_xlabel("wind speed U (m/s)")
    ax.set_ylabel("error / L")
    ax.set_title(title, fontsize=9)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path
