"""Part ``lost`` of the accuracy benchmark: loss of track, detected and recovered (issue 19).

Each sweep kinematics is simulated once; every scenario of :mod:`flagtrack.drivers.sim.disruptions`
(occlusion, crossing object, bright reflection, both of the issue's, a chain started 90 degrees off,
and the clean recording) is applied to its events and tracked by every method from the truth's
first shape (turned for ``start-90``). The paper's method runs with the detector on and no
re-acquisition, so its chain is the published one and ``/lost`` says what the detector would flag.
Scores (:func:`flagtrack.daemon.core.recovery.recovery_scores`): time back on the flag (every later
update within 1 % L) after the disruption ends, the worst shape error from half a period after
the end (one period for ``start-90``), ``/lost`` on the updates on the flag outside the
disruptions (false) and inside them, and on the updates more than 5 % L off (hit).
"""

from __future__ import annotations

import dataclasses
import math
from collections import defaultdict
from collections.abc import Sequence
from typing import Any

import numpy as np

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.metrics import align, trapezoid
from flagtrack.daemon.core.recovery import ON_FLAG, recovery_scores

COLUMNS = (
    "name",
    "part",
    "kinematics",
    "seed",
    "level",
    "joints",
    "tau_over_t",
    "frequency_hz",
    "duration_s",
    "n_events",
    "method",
    "disruption",
    "recovery_periods",
    "max_eps_rms_over_l_after",
    "false_lost",
    "lost_during",
    "lost_hit",
    "n_off",
    "lost_fraction",
)

MIN_DURATION_S = 0.5
"""Shortest recording of the part (the last disruption ends at 0.45 s), plus three periods."""


def lost_rows(
    events: np.ndarray,
    truth: CentrelineBatch,
    attrs: dict[str, Any],
    runs: Sequence[tuple[Any, Any, Any]],
    base: dict[str, Any],
) -> list[dict[str, Any]]:
    """One row per (scenario, run) of a simulated recording.

    Args:
        runs: (variant, its TrackingConfig, the chain through the truth's first shape) per run.
        base: the recording's columns, with the sensor's ``width`` and ``height``.
    """
    from flagtrack.daemon.core.lost_params import LostParams
    from flagtrack.daemon.core.tracker import Tracker
    from flagtrack.drivers.sim.disruptions import SCENARIOS, disrupted, rotated_start

    f, length = float(attrs["kin_frequency_hz"]), float(attrs["length"])
    root = (float(attrs["kin_root"][0]), float(attrs["kin_root"][1]))
    rows = []
    for name in SCENARIOS:
        scenario = disrupted(name, events, root, length, float(attrs["kin_direction_deg"]), seed=base["seed"])
        for variant, config, start in runs:
            params = config.tracker_params()
            if params.lost is None:  # the paper's update, unchanged; the detector only watches it
                params = dataclasses.replace(params, lost=LostParams(reacquire=False))
            state = rotated_start(start, scenario.start_offset_deg)
            tracker = Tracker(params, state, sensor_size=(base["width"], base["height"]))
            batch = CentrelineBatch.concatenate([tracker.feed(scenario.events), tracker.finish()])
            rows.append(
                {
                    **{k: v for k, v in base.items() if k in COLUMNS},
                    "method": variant.method,
                    "joints": variant.joints,
                    "tau_over_t": variant.tau_over_t,
                    "disruption": name,
                    **_scores(batch, truth, scenario, config.tau_s, f, length),
                }
            )
    return rows


def _scores(
    batch: CentrelineBatch, truth: CentrelineBatch, scenario: Any, tau_s: float, f: float, length: float
) -> dict:
    pair = align(batch, truth)
    eps = np.sqrt(trapezoid((pair.x - pair.x_ref) ** 2 + (pair.y - pair.y_ref) ** 2, pair.s) / (pair.s[-1] - pair.s[0]))
    eps /= length
    keep = np.isin(batch.t_s, pair.t_s)
    lost = batch.lost[keep]
    t_us = scenario.events["t"]
    lo, hi = pair.t_s * 1e6 - tau_s * 5e5, pair.t_s * 1e6 + tau_s * 5e5
    has_events = np.searchsorted(t_us, hi) > np.searchsorted(t_us, lo)
    spans = scenario.spans_us
    end_s = max(s[1] for s in spans) * 1e-6 if spans else 0.0
    grace = 1.0 if scenario.start_offset_deg else 0.5
    r = recovery_scores(pair.t_s, eps, lost, has_events, end_s, 1.0 / f, grace)
    during = np.zeros(len(pair.t_s), dtype=bool)
    for a, b in spans:
        during |= (pair.t_s * 1e6 >= a) & (pair.t_s * 1e6 < b + 0.5e6 / f)  # and half a period after
    on = eps <= ON_FLAG
    return {
        "recovery_periods": r.recovery_periods,
        "max_eps_rms_over_l_after": r.max_eps_after,
        "false_lost": float(lost[on & ~during].mean()) if (on & ~during).any() else math.nan,
        "lost_during": float(lost[during].mean()) if during.any() else math.nan,
        "lost_hit": r.hit,
        "n_off": r.n_off,
        "lost_fraction": float(lost.mean()) if len(lost) else math.nan,
    }


def lost_summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per method and scenario, over the kinematics: worst recovery, worst error after, rates (pooled means)."""
    groups: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[(r["method"], r["disruption"])].append(r)

    def mean(values: list[float]) -> float:
        finite = [v for v in values if not math.isnan(v)]
        return float(np.mean(finite)) if finite else math.nan

    out = []
    for (method, name), group in sorted(groups.items()):
        out.append(
            {
                "method": method,
                "disruption": name,
                "recordings": len(group),
                # a recording never back is inf (empty in the CSV tables, so NaN when read back)
                "recovery_periods_max": max(
                    math.inf if math.isnan(r["recovery_periods"]) else r["recovery_periods"] for r in group
                ),
                "max_eps_rms_over_l_after": float(np.nanmax([r["max_eps_rms_over_l_after"] for r in group])),
                "false_lost": mean([r["false_lost"] for r in group]),
                "lost_during": mean([r["lost_during"] for r in group]),
                "lost_hit": mean([r["lost_hit"] for r in group]),
                "n_off": sum(r["n_off"] for r in group),
            }
        )
    return out


def lost_section(summary: Sequence[dict[str, Any]]) -> str:
    """The report's markdown section of part ``lost``."""

    def pct(v: float) -> str:
        return "-" if math.isnan(v) else f"{100 * v:.1f}"

    lines = [
        "## Loss of track, detected and recovered (issue 19)\n",
        "Targets: back on the flag (every later update ε_RMS ≤ 1 % L) within 0.5 T of the disruption's end "
        "(1 T from a chain started 90° off); `/lost` on ≤ 2 % of the updates on the flag outside the "
        "disruptions, and on most updates > 5 % L off. The paper's chain runs with the detector only "
        "(no re-acquisition). Worst over the kinematics; rates pooled.\n",
        "| method | disruption | back after (T), worst | max ε_RMS/L % after | /lost false % | /lost during % "
        "| /lost hit % (off updates) |",
        "|---|---|---|---|---|---|---|",
    ]
    for e in summary:
        rec = e["recovery_periods_max"]
        lines.append(
            f"| {e['method']} | {e['disruption']} | {f'{rec:.2f}' if math.isfinite(rec) else 'never'} "
            f"| {pct(e['max_eps_rms_over_l_after'])} | {pct(e['false_lost'])} | {pct(e['lost_during'])} "
            f"| {pct(e['lost_hit'])} ({e['n_off']}) |"
        )
    return "\n".join(lines) + "\n\n"
