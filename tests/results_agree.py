"""Checks that a sweep's numbers read the same wherever they are shown (issue 32): one name, one unit and
one statistic per number in the terminal lines, README.txt, run.json, run.jsonl, summary.csv, the demo's
report and ``--json``, and the figures (read as matplotlib figures: their titles, labels and data).

A value shown two ways must be equal within the rounding of the way that rounds more; errors and
distances a person reads are in % of L, the files hold fractions under ``_over_l`` keys. Used by
tests/unit/test_results_agree.py (a run made of records) and the integration tests of real sweeps.
"""

from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from flagtrack.daemon.sweep.quantities import POINT_ALIASES, QUANTITIES
from flagtrack.daemon.sweep.runfiles import README_COLUMNS
from flagtrack.daemon.sweep.runlog import RUN_LOG

NUMBER = r"(-?\d+(?:\.\d+)?)"


def agrees(shown: str, value: float | None, scale: float = 1.0) -> bool:
    """Whether the number ``shown`` (``-`` for none) is ``value * scale`` rounded to its digits."""
    if shown == "-":
        return value is None or not math.isfinite(value)
    if value is None or not math.isfinite(value):
        return False
    digits = len(shown.split(".")[1]) if "." in shown else 0
    return abs(float(shown) - value * scale) <= 0.5 * 10**-digits + 1e-9


def check_files(run_dir: Path) -> dict[str, Any]:
    """run.json against run.jsonl, summary.csv and README.txt; returns run.json."""
    run = json.loads((run_dir / "run.json").read_text())
    points = {p["point_id"]: p for p in run["points"]}
    for p in points.values():
        for old, new in POINT_ALIASES.items():
            assert p[old] == p[new], (p["point_id"], old)  # the old keys: the same values
    latest: dict[str, dict[str, Any]] = {}
    for line in (run_dir / RUN_LOG).read_text().splitlines():
        record = json.loads(line)
        if record["type"] == "point":
            latest[record["point_id"]] = record
    for pid, record in latest.items():
        for key, value in points[pid].items():
            assert record.get(key) == value, (pid, key, record.get(key), value)
    with open(run_dir / "summary.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["point_id"] for r in rows] == list(points)
    for row in rows:
        p = points[row["point_id"]]
        for key, cell in row.items():
            value = p[key]
            if isinstance(value, float) or (key.endswith(("_over_l", "_mps", "_hz", "_us", "_s")) and value is None):
                assert (cell == "NaN" and value is None) or float(cell) == value, (key, cell, value)
    _check_readme((run_dir / "README.txt").read_text(), run)
    return run


def _check_readme(text: str, run: dict[str, Any]) -> None:
    lines = text.splitlines()
    header = next(line for line in lines if line.lstrip().startswith("point ") and "branch" in line)
    for key in README_COLUMNS:  # every column says its unit as quantities.py does; no bare fraction of L
        assert QUANTITIES[key].heading in header, (key, header)
        assert not key.endswith("_over_l") or QUANTITIES[key].unit in ("%", ""), key
    start = lines.index(header) + 1
    for p, line in zip(run["points"], lines[start : start + len(run["points"])], strict=True):
        cells = line.split()
        assert cells[0] == p["point_id"], line
        for key, shown in zip(README_COLUMNS, cells[4:], strict=True):
            assert agrees(shown, p[key], QUANTITIES[key].scale), (p["point_id"], key, shown, p[key])
    for name, key in (("Onset", "onset_mps"), ("Decay", "decay_mps")):
        line = next(line for line in lines if line.startswith(name))
        speed = re.search(rf"{name}\s+{NUMBER} m/s", line)
        assert (speed is None and "not observed" in line and run[key] is None) or (
            speed is not None and float(speed.group(1)) == run[key]
        ), line


def check_terminal(lines: list[str], run: dict[str, Any]) -> int:
    """The per-point lines (``point 3/17 ...``) against run.json; returns how many were checked."""
    checked = 0
    for line in lines:
        head = re.match(r"\s*point\s+(\d+)/(\d+)\s", line)
        if head is None or "FAILED" in line or "LOSSY" in line:
            continue
        p = run["points"][int(head.group(1)) - 1]
        amplitude = re.search(r"A/L\s+(\S+)", line)
        assert amplitude and agrees(amplitude.group(1), p["amplitude_over_l"]), (line, p["amplitude_over_l"])
        lost = re.search(rf"lost ({NUMBER} %|-)", line)
        assert lost, line
        assert agrees(lost.group(1).removesuffix(" %"), p["lost_fraction"], 100.0), (line, p["lost_fraction"])
        error = re.search(rf"e/L RMS {NUMBER} %", line)
        assert (error is None and p["sensor_error_rms_over_l"] is None) or agrees(
            error.group(1), p["sensor_error_rms_over_l"], 100.0
        ), (line, p["sensor_error_rms_over_l"])
        assert not re.search(r"e/L \d", line) and not re.search(r"\d%", line), line  # named statistic, '0.4 %'
        checked += 1
    return checked


def check_demo_report(text: str, summary: dict[str, Any], run: dict[str, Any]) -> None:
    """The demo's closing lines and its --json object against run.json."""
    assert "None" not in text, text
    for name, key in (("onset", "onset_mps"), ("decay", "decay_mps")):
        line = next(line for line in text.splitlines() if line.strip().startswith(name))
        found = re.search(rf"detected {NUMBER} m/s", line)
        assert summary[f"{name}_mps_detected"] == run[key]
        assert (found is None and "not detected" in line and run[key] is None) or float(found.group(1)) == run[key]
    flapping = [p for p in run["points"] if p["state"] == "flapping" and p["status"] == "done"]
    checked = [p for p in flapping if p["sensor_error_rms_over_l"] is not None]
    worst = max(checked, key=lambda p: p["sensor_error_rms_over_l"]) if checked else None
    assert summary["sensor_error_rms_over_l_max"] == (worst["sensor_error_rms_over_l"] if worst else None)
    if worst is not None:
        shown = re.search(rf"worst e/L RMS {NUMBER} % of L over (\d+) flapping points \(([^;]+);", text)
        assert shown and agrees(shown.group(1), worst["sensor_error_rms_over_l"], 100.0), text
        assert int(shown.group(2)) == len(checked) and shown.group(3) == worst["point_id"]


def figure_texts(fig: Any) -> list[str]:
    """Every text of a matplotlib figure: titles, axis labels, legend entries, annotations."""
    texts = [fig._suptitle.get_text()] if fig._suptitle is not None else []
    for ax in fig.axes:
        texts += [ax.get_title(), ax.get_xlabel(), ax.get_ylabel(), *(t.get_text() for t in ax.texts)]
        legend = ax.get_legend()
        if legend is not None:
            texts += [t.get_text() for t in legend.get_texts()]
    return [t for t in texts if t]


def check_reference_lines(fig: Any) -> None:
    """Every horizontal or vertical reference line is labelled (in a legend or by an annotation)."""
    for ax in fig.axes:
        annotations = " ".join(t.get_text() for t in ax.texts)
        for line in ax.lines:
            x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            straight = len(x) == 2 and (x[0] == x[1] or y[0] == y[1])
            if straight:
                position = x[0] if x[0] == x[1] else y[0]
                labelled = not line.get_label().startswith("_") or f"{position:.2f}" in annotations
                assert labelled, (ax.get_ylabel(), line.get_xdata(), line.get_ydata())


def check_sweep_figures(run: dict[str, Any], amplitude: Any | None, sweep: Any | None) -> None:
    """amplitude.png and validation.png (as figures) against run.json: what, which run, units, data."""
    for fig in (amplitude, sweep):
        if fig is None:
            continue
        title = fig.axes[0].get_title()
        assert f"run {run['run_id']}" in title and "against the wind speed" in title, title
        check_reference_lines(fig)
    if amplitude is not None:
        done = [p for p in run["points"] if p["status"] == "done"]
        drawn = [float(y) for c in amplitude.axes[0].containers for y in c.lines[0].get_ydata()]
        want = [p["amplitude_over_l"] for p in done if p["amplitude_over_l"] is not None]
        assert sorted(y for y in drawn if math.isfinite(y)) == sorted(want)
    if sweep is None:
        return
    ax_e, ax_d = sweep.axes
    assert "% of L" in ax_e.get_ylabel() and "% of L" in ax_d.get_ylabel()
    rms_lines = {line.get_label(): line for line in ax_e.lines}
    for branch in ("up", "down"):
        mine = [p for p in run["points"] if p["branch"] == branch]
        rms = [100 * p["sensor_error_rms_over_l"] for p in mine if p["sensor_error_rms_over_l"] is not None]
        if rms:
            np.testing.assert_allclose(np.asarray(rms_lines[f"e/L RMS ({branch})"].get_ydata(), float), rms, rtol=1e-12)
        for ax, key in ((ax_e, "sensor_error_mean_over_l"), (ax_d, "cloud_distance_mean_over_l")):
            means = [100 * p[key] for p in mine if p[key] is not None]
            bars = [c for c in ax.containers if c.get_label().endswith(f"mean ± std over time ({branch})")]
            assert len(bars) == (1 if means else 0), (key, branch)
            if means:
                np.testing.assert_allclose(np.asarray(bars[0].lines[0].get_ydata(), float), means, rtol=1e-12)
    texts = " ".join(figure_texts(sweep))
    assert "mean ± std over time" in texts and "e/L RMS" in texts and "1 % of L" in texts


def check_point_figure(fig: Any, whole: dict[str, Any] | None = None) -> None:
    """A point's figure: the excerpt says it is one, each panel's statistic is of what it draws, the
    title's are the whole point's (``whole``: its run.json record, when known), Delta_RMS has markers."""
    ax_y, ax_e, ax_d = fig.axes
    suptitle = fig._suptitle.get_text()
    assert "whole point" in suptitle, suptitle
    top = ax_y.get_title()
    shown = re.search(rf"(\S+) s of the point's {NUMBER} s", top)
    assert ("an excerpt" in top and shown) or "the whole point" in top, top
    if whole is not None and whole.get("sensor_error_rms_over_l") is not None:
        rms = re.search(rf"whole point \({NUMBER} s\): e/L RMS {NUMBER} %", suptitle)
        assert rms and agrees(rms.group(2), whole["sensor_error_rms_over_l"], 100.0), (suptitle, whole)
    e_lines = [line for line in ax_e.lines if len(line.get_ydata())]
    if e_lines:
        e_pct = np.asarray(e_lines[0].get_ydata(), float)
        note = " ".join(t.get_text() for t in ax_e.texts)
        rms = re.search(rf"shown: e/L RMS {NUMBER} %, \|e\|/L max {NUMBER} %", note)
        assert rms and agrees(rms.group(1), float(np.sqrt(np.mean(e_pct**2)))), note
        assert agrees(rms.group(2), float(np.max(np.abs(e_pct)))), note
    assert "% of L" in ax_e.get_ylabel() and "% of L" in ax_d.get_ylabel()
    d_line = ax_d.lines[0]
    assert d_line.get_marker() not in (None, "None", "", " "), "Delta_RMS: a marker where a line cannot be"
    d_pct = np.asarray(d_line.get_ydata(), float)
    note = " ".join(t.get_text() for t in ax_d.texts)
    if np.isfinite(d_pct).any():
        mean = re.search(rf"shown: mean {NUMBER} %, std {NUMBER} %; (\d+) of (\d+) updates", note)
        assert mean and agrees(mean.group(1), float(np.nanmean(d_pct))), note
        assert int(mean.group(3)) == int(np.isfinite(d_pct).sum()) and int(mean.group(4)) == len(d_pct)
    else:
        assert "had events" in note, note
