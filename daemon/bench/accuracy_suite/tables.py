"""Tables of the accuracy benchmark: rows split by part, CSV files and summaries (pure functions).

A row is one tracking run of one recording (``evaluate.run_task``): recording columns, the variant
(method, N_j, tau/T) and the metrics (lengths over L; ``t_loss_cycles`` NaN if the tip was never
lost).
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from flagtrack.daemon.bench.accuracy_suite.plan import METHODS, PAPER_JOINTS, PAPER_TAU_OVER_T

RECORDING_COLUMNS = (
    "name",
    "part",
    "kinematics",
    "seed",
    "level",
    "frequency_hz",
    "wavelength_over_l",
    "w_travel",
    "peak_to_peak_over_l",
    "duration_s",
    "leak_rate_hz",
    "shot_noise_hz",
    "n_events",
)
RUN_COLUMNS = (
    "method",
    "joints",
    "tau_over_t",
    "events_kept",
    "track_wall_s",
    "delta_rms_over_l",
    "max_eps_rms_over_l",
    "twi",
    "twi_ref",
    "twi_abs_error",
    "twi_rel_error",
    "t_loss_cycles",
    "evaluated_cycles",
    "max_delta_over_l",
)
COLUMNS = RECORDING_COLUMNS + RUN_COLUMNS
SWEEP_COLUMNS = ("condition", "n_over_n0") + COLUMNS


class PaperFamily(TypedDict):
    """The paper's figures for the family (fractions): ranges (low, high), medians, bounds."""

    delta_rms_over_l: tuple[float, float]
    max_eps_rms_over_l: tuple[float, float]
    twi_rel_error_median: float
    twi_rel_error_p95: float
    twi_abs_error_max: float
    twi_abs_error_median: float


PAPER_FAMILY: PaperFamily = {
    "delta_rms_over_l": (0.0036, 0.010),
    "max_eps_rms_over_l": (0.0053, 0.016),
    "twi_rel_error_median": 0.0109,
    "twi_rel_error_p95": 0.0303,
    "twi_abs_error_max": 0.025,
    "twi_abs_error_median": 1.3e-3,
}
"""The paper's section 3 figures for the family (fractions)."""


def method_rank(method: str) -> int:
    """Order of methods in tables: the paper's first, then as in :data:`plan.METHODS`."""
    names = list(METHODS)
    return names.index(method) if method in names else len(names)


def at_paper_params(row: dict[str, Any]) -> bool:
    """Whether a row used N_j = 10 and tau/T = 5e-3."""
    return row["joints"] == PAPER_JOINTS and math.isclose(row["tau_over_t"], PAPER_TAU_OVER_T)


def with_noise_ratio(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Sweep rows with ``condition`` and ``n_over_n0`` (events over the clean recording's, same kinematics)."""
    rows = list(rows)
    clean = {r["kinematics"]: r["n_events"] for r in rows if r["part"] == "clean"}
    out = []
    for r in rows:
        n0 = clean.get(r["kinematics"])
        ratio = r["n_events"] / n0 if n0 else math.nan
        condition = "clean" if r["part"] == "clean" else f"{r['part']} {r['level']:g}"
        out.append({**r, "condition": condition, "n_over_n0": ratio})
    return out


def split_parts(rows: Sequence[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """The CSV tables: ``family``, ``lost``, ``leak``, ``shot_noise``, ``params_joints``, ``params_tau``."""
    sweep = with_noise_ratio(r for r in rows if r["part"] not in ("family", "lost"))
    paper = [r for r in sweep if at_paper_params(r)]
    fig6 = [r for r in sweep if r["part"] == "clean" or (r["part"] == "shot" and r["level"] == 20.0)]
    tables = {
        "family": [r for r in rows if r["part"] == "family"],
        "lost": [r for r in rows if r["part"] == "lost"],
        "leak": [r for r in paper if r["part"] in ("clean", "leak")],
        "shot_noise": [r for r in paper if r["part"] in ("clean", "shot")],
        "params_joints": [r for r in fig6 if math.isclose(r["tau_over_t"], PAPER_TAU_OVER_T)],
        "params_tau": [r for r in fig6 if r["joints"] == PAPER_JOINTS],
    }
    if not any(r["part"] == "leak" for r in rows):
        tables["leak"] = []
    if not any(r["part"] == "shot" and r["level"] != 20.0 for r in rows):
        tables["shot_noise"] = []
    if not any(not at_paper_params(r) for r in sweep):
        tables["params_joints"], tables["params_tau"] = [], []
    return tables


def write_csv(path: Path, rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> None:
    """Write ``rows`` (only ``columns``, in that order); floats with full precision, NaN as empty."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for row in rows:
            writer.writerow([_cell(row.get(c)) for c in columns])


def read_csv(path: Path) -> list[dict[str, Any]]:
    """Read a table written by :func:`write_csv` (numbers back as int or float, empty as NaN)."""
    with open(path, newline="") as handle:
        return [{k: _parse(v) for k, v in row.items()} for row in csv.DictReader(handle)]


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, (float, np.floating)):
        return "" if not math.isfinite(float(value)) else repr(float(value))
    return str(value)


def _parse(text: str) -> Any:
    if text == "":
        return math.nan
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _stats(values: Sequence[float]) -> dict[str, float]:
    v = np.asarray([x for x in values if math.isfinite(x)], dtype=np.float64)
    if len(v) == 0:
        return {k: math.nan for k in ("min", "p5", "median", "p95", "max", "mean")}
    return {
        "min": float(v.min()),
        "p5": float(np.percentile(v, 5)),
        "median": float(np.median(v)),
        "p95": float(np.percentile(v, 95)),
        "max": float(v.max()),
        "mean": float(v.mean()),
    }


def family_summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method: distribution of delta_RMS/L, max eps_RMS/L, travelling-wave index errors, losses."""
    by_method: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        by_method[r["method"]].append(r)
    out = []
    for method, group in sorted(by_method.items(), key=lambda item: method_rank(item[0])):
        entry: dict[str, Any] = {"method": method, "recordings": len(group)}
        for metric in ("delta_rms_over_l", "max_eps_rms_over_l", "twi_rel_error", "twi_abs_error"):
            for stat, value in _stats([r[metric] for r in group]).items():
                entry[f"{metric}_{stat}"] = value
        entry["below_1pct"] = sum(r["delta_rms_over_l"] < 0.01 for r in group) / len(group)
        entry["lost"] = sum(math.isfinite(r["t_loss_cycles"]) for r in group)
        out.append(entry)
    return out


def sweep_summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method and level (over the sweep kinematics): delta_RMS/L median and worst, N/N0, first loss."""
    groups: dict[tuple[str, float], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[(r["method"], 0.0 if r["part"] == "clean" else float(r["level"]))].append(r)
    out = []
    for (method, level), group in sorted(groups.items(), key=lambda item: (method_rank(item[0][0]), item[0][1])):
        delta = [r["delta_rms_over_l"] for r in group]
        losses = [r["t_loss_cycles"] for r in group if math.isfinite(r["t_loss_cycles"])]
        out.append(
            {
                "method": method,
                "level": level,
                "kinematics": len(group),
                "delta_rms_over_l_median": float(np.median(delta)),
                "delta_rms_over_l_max": float(np.max(delta)),
                "n_over_n0_median": float(np.median([r["n_over_n0"] for r in group])),
                "lost": len(losses),
                "t_loss_cycles_min": min(losses) if losses else math.nan,
                "evaluated_cycles_min": float(min(r["evaluated_cycles"] for r in group)),
            }
        )
    return out


def param_summary(rows: Sequence[dict[str, Any]], key: str) -> list[dict[str, Any]]:
    """Per method, condition and value of ``key`` (``joints`` or ``tau_over_t``): delta_RMS/L median, max."""
    groups: dict[tuple[str, str, float], list[float]] = defaultdict(list)
    for r in rows:
        groups[(r["method"], r["condition"], r[key])].append(r["delta_rms_over_l"])
    return [
        {
            "method": m,
            "condition": c,
            key: v,
            "kinematics": len(d),
            "delta_rms_over_l_median": float(np.median(d)),
            "delta_rms_over_l_max": float(np.max(d)),
        }
        for (m, c, v), d in sorted(groups.items(), key=lambda item: (method_rank(item[0][0]), *item[0][1:]))
    ]


def tolerated_level(summary: Sequence[dict[str, Any]], method: str, limit: float = 0.01) -> float:
    """Highest swept level up to which every kinematics keeps delta_RMS/L below ``limit`` (0 if none)."""
    best = 0.0
    for entry in sorted((e for e in summary if e["method"] == method), key=lambda e: e["level"]):
        if entry["delta_rms_over_l_max"] >= limit:
            break
        best = entry["level"]
    return best
