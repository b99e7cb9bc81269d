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
import textwrap
import time
from collections.abc import Sequence
from pathlib import Path

from flagtrack.daemon.sweep.figures import plot_amplitude, plot_sweep
from flagtrack.daemon.sweep.quantities import POINT_ALIASES
from flagtrack.daemon.sweep.runfiles import write_run_files
from flagtrack.daemon.sweep.runlog import PointResult, RunRecord, read_run
from flagtrack.drivers.atomic import atomic_open

SUMMARY_CSV = "summary.csv"
AMPLITUDE_FIGURE = "amplitude.png"
VALIDATION_FIGURE = "validation.png"
SUMMARY_COLUMNS = (
    "speed_mps", "branch", "state", "amplitude_over_l", "frequency_hz", "twi", "cloud_distance_mean_over_l",
    "event_rate_mev_s", "raw_bytes", "sensor_error_rms_over_l", "sensor_error_max_over_l", "point_id", "index",
    "status", "speed_readback_mps", "amplitude_std_over_l", "raw_file", "centreline_file", "t_start_unix",
    "t_stop_unix", "error", "cloud_distance_std_over_l", "sensor_status", "sensor_error_mean_over_l",
    "sensor_error_std_over_l", "sensor_sync", "sensor_offset_us", "sensor_offset_unc_us", "sensor_drift_ppm",
    "sensor_xcorr_offset_us", "sensor_xcorr_unc_us", "sensor_samples", "sensor_missing", "sensor_compared", "sensor_file",
    "sensor_figure", "actions", "lost_fraction", "suspect", "reason", "stale_fraction", "shed_fraction",
    "chain_reach",
    *POINT_ALIASES,  # the old names of the cloud distance, last, with the same values (for programs that read them)
)  # fmt: skip


def summary_points(record: RunRecord) -> list[PointResult]:
    """The latest record of every point, in plan order."""
    return list(record.latest_points().values())


def write_summary_csv(points: Sequence[PointResult], path: str | Path) -> Path:
    """Write ``points`` as CSV (``NaN`` for missing numbers), atomically (temp file + rename)."""
    path = Path(path)
    with atomic_open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(SUMMARY_COLUMNS)
        for point in points:
            row = dataclasses.asdict(point)
            row.update({old: row[new] for old, new in POINT_ALIASES.items()})
            writer.writerow([_cell(row[name]) for name in SUMMARY_COLUMNS])
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


def write_summary(run_dir: str | Path) -> tuple[Path, Path]:
    """Read the run log of ``run_dir`` and write ``summary.csv`` and ``amplitude.png`` there (and
    ``validation.png``, the point-sensor comparison against the speed, when a point has one), then
    the folder's ``run.json`` and ``README.txt`` (:mod:`~flagtrack.daemon.sweep.runfiles`)."""
    record = read_run(run_dir)
    points = summary_points(record)
    csv_path = write_summary_csv(points, Path(run_dir) / SUMMARY_CSV)
    transitions = transition_speeds(points)
    amplitude_title, sweep_title = figure_titles(record, points)
    try:
        fig_path = plot_amplitude(points, Path(run_dir) / AMPLITUDE_FIGURE, amplitude_title, transitions)
        if any(p.sensor_status is not None for p in points):
            plot_sweep(points, Path(run_dir) / VALIDATION_FIGURE, sweep_title)
    finally:  # the folder describes itself even when a figure cannot be drawn
        write_run_files(record, points, *transitions)
    return csv_path, fig_path


def figure_titles(record: RunRecord, points: Sequence[PointResult]) -> tuple[str, str]:
    """The titles of ``amplitude.png`` and ``validation.png``: what they show and which run."""
    which = run_caption(record, points)
    return (
        f"Tip amplitude A/L against the wind speed (paper fig. 5h)\n{which}",
        f"Point-sensor error and event-cloud distance against the wind speed (paper fig. 5g)\n{which}",
    )


def run_caption(record: RunRecord, points: Sequence[PointResult]) -> str:
    """Which run a figure shows: ``run sweep (runs/sweep), started 2026-11-27 02:27, 17 of 17 points done``."""
    started = record.start.get("t_unix")
    when = (
        f", started {time.strftime('%Y-%m-%d %H:%M', time.localtime(started))}"
        if isinstance(started, int | float)
        else ""
    )
    done = sum(p.status == "done" for p in points)
    folder = f"{record.run_dir.parent.name}/{record.run_dir.name}"
    caption = f"run {record.start.get('run_id', '?')} ({folder}){when}, {done} of {len(record.planned_ids)} points done"
    return textwrap.fill(caption, 70)
