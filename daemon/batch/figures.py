"""The campaign figure of ``flagtrack batch validate``: A/L against the wind speed of every run on one plot,
and below it the point sensor's recomputed RMS error. Headless (Agg canvas, no pyplot state)."""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

CAMPAIGN_FIGURE = "campaign.png"


@dataclass(frozen=True)
class CampaignPoint:
    """What the campaign figure draws of one point of a run's ``validation.csv``."""

    speed_mps: float
    branch: str
    amplitude_over_l: float
    amplitude_std_over_l: float
    sensor_error_rms_over_l: float


def read_points(validation_csv: str | Path) -> list[CampaignPoint]:
    """The ``done`` points of a run's ``validation.csv`` (the summary's columns; NaN where empty)."""
    with open(validation_csv, newline="", encoding="utf-8") as handle:
        return [
            CampaignPoint(
                _number(row["speed_mps"]),
                row["branch"],
                _number(row["amplitude_over_l"]),
                _number(row["amplitude_std_over_l"]),
                _number(row["sensor_error_rms_over_l"]),
            )
            for row in csv.DictReader(handle)
            if row.get("status", "done") == "done"
        ]


def _number(text: str | None) -> float:
    try:
        return float(text) if text else math.nan
    except ValueError:
        return math.nan


def _figure(size: tuple[float, float]) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def plot_campaign(runs: Sequence[tuple[str, Sequence[CampaignPoint]]], path: str | Path, title: str = "") -> Path:
    """Save the campaign figure (PNG): per run (a colour each), A/L ± its std against the speed (up
    branch ▲ filled, down branch ▼ open), and the sensor's RMS |e|/L where the run has a comparison.

    Args:
        runs: (label, points) per run.
        path: the PNG to write.
        title: the figure's title.
    """
    fig = _figure((7.0, 6.5))
    ax_amp, ax_err = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    styles = {"up": ("^", "full"), "down": ("v", "none")}
    for i, (label, points) in enumerate(runs):
        color = f"C{i % 10}"
        labelled = False
        for branch, (marker, fill) in styles.items():
            mine = sorted((p for p in points if p.branch == branch), key=lambda p: p.speed_mps)
            if not mine:
                continue
            speeds = [p.speed_mps for p in mine]
            std = [0.0 if not math.isfinite(p.amplitude_std_over_l) else p.amplitude_std_over_l for p in mine]
            ax_amp.errorbar(
                speeds,
                [p.amplitude_over_l for p in mine],
                yerr=std,
                color=color,
                marker=marker,
                fillstyle=fill,
                capsize=2,
                linewidth=0.8,
                label=None if labelled else label,
            )
            labelled = True
            errors = [
                (p.speed_mps, p.sensor_error_rms_over_l) for p in mine if math.isfinite(p.sensor_error_rms_over_l)
            ]
            if errors:
                ax_err.plot(*zip(*errors), color=color, marker=marker, fillstyle=fill, linewidth=0.8)
    ax_err.axhline(0.01, color="0.6", linestyle="--", linewidth=0.8)
    ax_amp.set_ylabel("tip amplitude A/L (the runs')")
    ax_amp.set_title(f"{title or f'campaign: {len(runs)} runs'} (▲ up, ▽ down)", fontsize=10)
    if ax_amp.get_legend_handles_labels()[0]:
        ax_amp.legend(loc="best", fontsize=7, ncol=2 if len(runs) > 8 else 1)
    ax_err.set_ylabel("sensor RMS |e|/L (recomputed)")
    ax_err.set_xlabel("wind speed U (m/s)")
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path
