"""Figures of a sweep run: A/L and event rate against the wind speed (paper, figure 5h), and the point
sensor's error and the event-cloud distance against the speed (figure 5g). Headless (Agg); matplotlib
is imported when drawn. Labels, units and statistics are those of :mod:`.quantities` (errors in % of L).

Each ``*_figure`` function returns the figure (its texts are what a test reads); ``plot_*`` saves it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from flagtrack.daemon.sweep.quantities import QUANTITIES
from flagtrack.daemon.sweep.runlog import PointResult

REFERENCE_ERROR_OVER_L = 0.01
"""The line drawn on the error panel: the paper's errors against its laser sensors stay below 1 % of L."""

_BRANCHES = {"up": ("^", "full"), "down": ("v", "none")}


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


def _save(fig: Any, path: str | Path, dpi: int) -> Path:
    path = Path(path)
    fig.savefig(path, dpi=dpi)
    return path


def plot_amplitude(
    points: Sequence[PointResult],
    path: str | Path,
    title: str = "",
    transitions: tuple[float | None, float | None] = (None, None),
) -> Path:
    """Save :func:`amplitude_figure` as a PNG."""
    return _save(amplitude_figure(points, title, transitions), path, 120)


def amplitude_figure(
    points: Sequence[PointResult], title: str = "", transitions: tuple[float | None, float | None] = (None, None)
) -> Any:
    """A/L (bars: its std cycle by cycle) and the event rate against the wind speed, up and down apart;
    ``transitions``: the onset and decay speeds (m/s) to mark, where detected."""
    fig = _figure((6.0, 6.4))
    ax_amp, ax_rate = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    colours = {"up": "C0", "down": "C1"}
    for branch, (marker, fill) in _BRANCHES.items():
        mine = [p for p in points if p.branch == branch and p.status == "done"]
        if not mine:
            continue
        speeds = [p.speed_mps for p in mine]
        ax_amp.errorbar(speeds, [p.amplitude_over_l for p in mine], yerr=[_zero(p.amplitude_std_over_l) for p in mine],
                        color=colours[branch], marker=marker, fillstyle=fill, capsize=3, linestyle="-", linewidth=0.8,
                        label=f"{branch} ({len(mine)} points)")  # fmt: skip
        ax_rate.plot(speeds, [p.event_rate_mev_s for p in mine], color=colours[branch], marker=marker,
                     fillstyle=fill, linewidth=0.8)  # fmt: skip
    _mark_suspect(ax_amp, [p for p in points if p.status == "done"])
    _mark_bad(ax_amp, points)
    for speed, colour, name in ((transitions[0], "C0", "onset"), (transitions[1], "C1", "decay")):
        if speed is not None:
            for ax in (ax_amp, ax_rate):
                ax.axvline(speed, color=colour, linestyle="--", linewidth=1.0, label=f"{name} {speed:.2f} m/s")
            ax_amp.annotate(f"{name} {speed:.2f} m/s", (speed, 0.5), xycoords=("data", "axes fraction"),
                            rotation=90, va="center", ha="center", color=colour, fontsize=8,
                            bbox={"boxstyle": "round,pad=0.2", "facecolor": "white", "edgecolor": "none"})  # fmt: skip
    ax_amp.set_ylabel("tip amplitude A/L\n(bars: std of A/L cycle by cycle)")
    ax_amp.set_title(title, fontsize=9)
    if ax_amp.get_legend_handles_labels()[0]:
        ax_amp.legend(loc="lower right", fontsize=8)
    ax_rate.set_yscale("log")
    ax_rate.set_ylabel(f"event rate ({QUANTITIES['event_rate_mev_s'].unit},\nmean over the point)")
    ax_rate.set_xlabel("wind speed U (m/s)")
    return fig


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
    for status, colour in (("failed", "red"), ("lossy", "darkorange")):
        bad = [p for p in points if p.status == status]
        if bad:
            ax.plot([p.speed_mps for p in bad], [0.02] * len(bad), "x", color=colour, markersize=8,
                    transform=ax.get_xaxis_transform(), label=f"{status} ({len(bad)} points)")  # fmt: skip


def plot_sweep(points: Sequence[Any], path: str | Path, title: str = "") -> Path:
    """Save :func:`sweep_figure` as a PNG."""
    return _save(sweep_figure(points, title), path, 110)


def sweep_figure(points: Sequence[Any], title: str = "") -> Any:
    """The point sensor's error and the event-cloud distance against the speed (paper 5g), in % of L.

    Top: |e|/L, time mean (marker) and std (bars), as the paper draws it, and e/L RMS (the figure the
    terminal and README.txt quote) beside it; the reference line at 1 %. Bottom: Delta_RMS/L, time mean
    and std. A point without a number is a grey cross at the foot of its panel.

    Args:
        points: :class:`~flagtrack.daemon.sweep.runlog.PointResult` s (or objects with the same fields).
    """
    fig = _figure((6.4, 6.0))
    ax_e, ax_d = fig.subplots(2, 1, sharex=True)
    speeds = [p.speed_mps for p in points] or [0.0]
    dx = 0.012 * max(max(speeds) - min(speeds), 1.0)  # the two statistics of e side by side
    for branch, (marker, fill) in _BRANCHES.items():
        mine = [p for p in points if p.branch == branch]
        _errorbars(ax_e, mine, "sensor_error_mean_over_l", "sensor_error_std_over_l", -dx, "C1", marker, fill,
                   f"|e|/L mean ± std over time ({branch})")  # fmt: skip
        rms = [p for p in mine if math.isfinite(p.sensor_error_rms_over_l)]
        if rms:
            ax_e.plot([p.speed_mps + dx for p in rms], [100 * p.sensor_error_rms_over_l for p in rms], marker,
                      color="k", fillstyle=fill, markersize=5, linestyle="none", label=f"e/L RMS ({branch})")  # fmt: skip
        _errorbars(ax_d, mine, "cloud_distance_mean_over_l", "cloud_distance_std_over_l", 0.0, "C2", marker, fill,
                   rf"$\Delta_{{RMS}}/L$ mean ± std over time ({branch})")  # fmt: skip
    ax_e.axhline(100 * REFERENCE_ERROR_OVER_L, color="0.5", linestyle="--", linewidth=0.8,
                 label="1 % of L: the paper's error against its laser sensors")  # fmt: skip
    _mark_missing(ax_e, points, "sensor_error_rms_over_l", "no sensor comparison")
    _mark_missing(ax_d, points, "cloud_distance_mean_over_l", "no update with events")
    ax_e.set_ylabel("point-sensor error e/L (% of L)")
    ax_d.set_ylabel("event-cloud distance\n" + r"$\Delta_{RMS}/L$ (% of L)")
    ax_d.set_xlabel("wind speed U (m/s)")
    ax_e.set_title(title, fontsize=9)
    for ax in (ax_e, ax_d):
        ax.set_ylim(0, ax.get_ylim()[1] * 1.45)  # room above the data for the legend
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7, ncols=2, loc="upper left")
    return fig


def _errorbars(ax: Any, points: Sequence[Any], mean: str, std: str, dx: float, colour: str, marker: str,
               fill: str, label: str) -> None:  # fmt: skip
    """Time mean (marker) and std (bars) of the fraction ``mean``/``std`` of each point, in % of L."""
    mine = [p for p in points if math.isfinite(getattr(p, mean))]
    if mine:
        ax.errorbar([p.speed_mps + dx for p in mine], [100 * getattr(p, mean) for p in mine],
                    yerr=[100 * _zero(getattr(p, std)) for p in mine], color=colour, marker=marker, fillstyle=fill,
                    capsize=3, linestyle="none", label=label)  # fmt: skip


def _mark_missing(ax: Any, points: Sequence[Any], key: str, why: str) -> None:
    """A grey cross at the foot of the panel for each point without a finite ``key``."""
    missing = [p for p in points if not math.isfinite(getattr(p, key))]
    if missing:
        ax.plot([p.speed_mps for p in missing], [0.03] * len(missing), "x", color="0.4", markersize=7,
                transform=ax.get_xaxis_transform(), label=f"{why} ({len(missing)} points)")  # fmt: skip
