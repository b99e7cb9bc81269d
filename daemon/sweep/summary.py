"""Summary of a sweep run: a CSV with one row per point, and the A/L-versus-speed figure.

The figure is the paper's figure 5h: time-mean tip amplitude A/L (error bars: standard
deviation) against the wind speed, up and down branches apart, with the detected onset and
decay speeds marked; a second panel shows the event rate, the paper's file-size indicator.

Onset speed: on the up branch, the first point classified ``flapping`` after a ``still`` one.
Decay speed: on the down branch, the first point classified ``still`` after a ``flapping`` one.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
from collections.abc import Sequence
from pathlib import Path

from flagtrack.daemon.sweep.runlog import PointResult, RunRecord, read_run

SUMMARY_CSV = "summary.csv"
AMPLITUDE_FIGURE = "amplitude.png"
VALIDATION_FIGURE = "validation.png"
SUMMARY_COLUMNS = (
    "speed_mps", "branch", "state", "amplitude_over_l", "frequency_hz", "twi", "delta_rms_over_l",
    "event_rate_mev_s", "raw_bytes", "sensor_error_rms_over_l", "sensor_error_max_over_l", "point_id", "index",
    "status", "speed_readback_mps", "amplitude_std_over_l", "raw_file", "centreline_file", "t_start_unix",
    "t_stop_unix", "error", "delta_rms_std_over_l", "sensor_status", "sensor_error_mean_over_l",
    "sensor_error_std_over_l", "sensor_sync", "sensor_offset_us", "sensor_offset_unc_us", "sensor_drift_ppm",
    "sensor_xcorr_offset_us", "sensor_xcorr_unc_us", "sensor_samples", "sensor_missing", "sensor_compared", "sensor_file",
    "sensor_figure", "actions",
)  # fmt: skip


def summary_points(record: RunRecord) -> list[PointResult]:
    """The latest record of every point, in plan order."""
    return list(record.latest_points().values())


def write_summary_csv(points: Sequence[PointResult], path: str | Path) -> Path:
    """Write ``points`` as CSV (``NaN`` for missing numbers), atomically (temp file + rename)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(SUMMARY_COLUMNS)
        for point in points:
            row = dataclasses.asdict(point)
            writer.writerow([_cell(row[name]) for name in SUMMARY_COLUMNS])
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)
    return path


def _cell(value: object) -> object:
    if value is None:
        return ""
    if isinstance(value, float):
        return "NaN" if math.isnan(value) else repr(value)
    return value


def transition_speeds(points: Sequence[PointResult]) -> tuple[float | None, float | None]:
    """Onset and decay speeds (m/s) from the point states, ``None`` where not observed."""
    return _first_change(points, "up", "still", "flapping"), _first_change(points, "down", "flapping", "still")


def _first_change(points: Sequence[PointResult], branch: str, before: str, after: str) -> float | None:
    seen_before = False
    for point in (p for p in points if p.branch == branch and p.status == "done"):
        if point.state == before:
            seen_before = True
        elif point.state == after and seen_before:
            return point.speed_mps
    return None


def load_figure_modules() -> None:
    """Import what :func:`plot_amplitude` draws with (about a second, the first time)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
    from matplotlib.figure import Figure  # noqa: F401


def plot_amplitude(points: Sequence[PointResult], path: str | Path, title: str = "") -> Path:
    """Save the A/L- and event-rate-versus-speed figure (PNG; headless Agg backend)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.0, 6.0), layout="constrained")
    FigureCanvasAgg(fig)
    ax_amp, ax_rate = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    styles = {"up": ("C0", "^", "full", "up"), "down": ("C1", "v", "none", "down")}
    for branch, (color, marker, fill, label) in styles.items():
        mine = [p for p in points if p.branch == branch and p.status == "done"]
        if not mine:
            continue
        speeds = [p.speed_mps for p in mine]
        ax_amp.errorbar(speeds, [p.amplitude_over_l for p in mine], yerr=[_zero_nan(p.amplitude_std_over_l) for p in mine],
                        color=color, marker=marker, fillstyle=fill, capsize=3, linestyle="-", linewidth=0.8,
                        label=f"{label} ({len(mine)} points)")  # fmt: skip
        ax_rate.plot(speeds, [p.event_rate_mev_s for p in mine], color=color, marker=marker, fillstyle=fill, linewidth=0.8)
    onset, decay = transition_speeds(points)
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


def _zero_nan(value: float) -> float:
    return 0.0 if math.isnan(value) else value


def write_summary(run_dir: str | Path) -> tuple[Path, Path]:
    """Read the run log of ``run_dir`` and write ``summary.csv`` and ``amplitude.png`` there (and
    ``validation.png``, the point-sensor comparison against the speed, when a point has one)."""
    record = read_run(run_dir)
    points = summary_points(record)
    csv_path = write_summary_csv(points, Path(run_dir) / SUMMARY_CSV)
    title = f"run {record.start.get('run_id', '?')}"
    fig_path = plot_amplitude(points, Path(run_dir) / AMPLITUDE_FIGURE, title)
    if any(p.sensor_status is not None for p in points):
        from flagtrack.daemon.validation.figures import plot_sweep

        plot_sweep(points, Path(run_dir) / VALIDATION_FIGURE, f"{title}: point sensor and cloud distance")
    return csv_path, fig_path
