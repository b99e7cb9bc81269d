"""``flagtrack bench live``'s derived figures and how it prints them (no processes)."""

from __future__ import annotations

import argparse
import os
from typing import Any

import numpy as np
import pytest

from flagtrack.daemon.bench import live_figures, live_print
from flagtrack.daemon.core.centreline import CentrelineBatch


def _results(per_event: dict[str, float], missing: int) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    run = {
        "updates": 8000,
        "missing_packets": missing,
        "kept_up": True,
        "publish_p50_ms": 1.0,
        "publish_p99_ms": 2.0,
        "p50_ms": 1.5,
        "p99_ms": 2.5,
        "cpu_cores": {"camera": 0.5, "tracker": 1.25, "bench": 0.02},
    }
    results = {
        "events": 80_000_000,
        "file_rate_mev_s": 40.0,
        "kernels": "compiled ahead of time",
        "sustained_mev_s": 36.0,
        "wakeup_late_p50_ms": 0.1,
        "wakeup_late_p99_ms": 0.2,
        "bus_packets": 4001,
        "bus_p50_ms": 0.3,
        "bus_p99_ms": 1.8,
        "cpu_ns_per_event": per_event,
        "cpu_ceiling_mev_s": 2e3 / sum(per_event.values()) if per_event else None,
    }
    return results, {"throughput": run, "realtime": run, "latency": run}


def _throughput(missing: int, complete: bool = True) -> dict[str, Any]:
    cores = {"camera": 0.5, "tracker": 1.25, "bench": 0.02}
    return {"complete": complete, "elapsed_s": 2.0, "missing_packets": missing, "cpu_cores": cores}


def test_cpu_per_event_is_the_cores_over_the_sustained_rate() -> None:
    figures = live_figures.throughput_figures(_throughput(missing=0), 72_000_000)  # 36 Mev/s
    assert figures["sustained_mev_s"] == pytest.approx(36.0)
    ns = {"camera": 0.5e3 / 36.0, "tracker": 1.25e3 / 36.0}  # (not the bench's own process)
    assert figures["cpu_ns_per_event"] == pytest.approx(ns)
    cores = os.cpu_count() or 1
    assert figures["cpu_ceiling_mev_s"] == pytest.approx(cores * 1e3 / sum(ns.values()))


def test_a_run_that_lost_packets_gives_no_cost_per_event() -> None:
    # the file outran the tracker's queue: its rate counts events the tracker never saw
    figures = live_figures.throughput_figures(_throughput(missing=859), 72_000_000)
    assert figures["sustained_mev_s"] == pytest.approx(36.0)
    assert figures["cpu_ns_per_event"] == {} and figures["cpu_ceiling_mev_s"] is None
    unfinished = live_figures.throughput_figures(_throughput(missing=0, complete=False), 72_000_000)
    assert unfinished == {"sustained_mev_s": None, "cpu_ns_per_event": {}, "cpu_ceiling_mev_s": None}


@pytest.mark.parametrize("lossless", [True, False])
def test_the_ceiling_is_printed_only_from_a_lossless_run(lossless: bool, capsys: pytest.CaptureFixture) -> None:
    per_event = {"camera": 13.9, "tracker": 34.7} if lossless else {}
    results, runs = _results(per_event, missing=0 if lossless else 859)
    args = argparse.Namespace(tau=2.5e-4, packet_us=1000, latency_rate=20.0, secure=False)
    live_print.print_plain(args, results, runs)
    out = capsys.readouterr().out
    assert "the bus alone at 20 Mev/s (camera -> a subscriber, no tracker, 4001 packets): p50 0.30 ms" in out
    assert ("carry at most 41.2 Mev/s" in out) is lossless
    assert ("CPU per event: not measured (the throughput run lost packets" in out) is not lossless


def test_no_ceiling_from_a_run_too_short_for_a_clock_tick_of_cpu() -> None:
    throughput = {**_throughput(missing=0), "cpu_cores": {"camera": 0.0, "tracker": 0.0, "bench": 0.0}}
    figures = live_figures.throughput_figures(throughput, 72_000_000)
    assert figures["cpu_ns_per_event"] == {"camera": 0.0, "tracker": 0.0}
    assert figures["cpu_ceiling_mev_s"] is None  # not a division by zero


def test_p50_p99_of_no_latencies_is_nan() -> None:
    p50, p99 = live_figures.p50_p99([])
    assert p50 != p50 and p99 != p99  # NaN
    assert live_figures.p50_p99([1.0, 2.0, 3.0]) == pytest.approx((2.0, 2.98))


def _lines(t_s: np.ndarray, offset: float) -> CentrelineBatch:
    n, s = len(t_s), np.linspace(0.0, 200.0, 51)
    x = np.tile(s, (n, 1)) + offset
    return CentrelineBatch(
        t_s=t_s,
        s=s,
        x=x,
        y=np.zeros((n, 51)),
        joints_x=np.zeros((n, 11)),
        joints_y=np.zeros((n, 11)),
        delta_rms=np.zeros(n),
        n_events=np.zeros(n, dtype=np.int64),
    )


def test_accuracy_is_the_largest_eps_over_l_at_the_live_updates_times() -> None:
    offline = _lines(np.arange(10) * 2.5e-4, 0.0)
    live = _lines(np.arange(2, 10, 2) * 2.5e-4, 0.0)  # every other update (the rest were shed)
    live.x[-1] += 1.0  # one update 1 px (0.5 % of L) off along its whole length
    assert live_figures.max_eps_over_l(live, offline, 200.0) == pytest.approx(0.005)
    assert live_figures.max_eps_over_l(_lines(np.array([9e-3]), 0.0), offline, 200.0) is None  # no common time


def test_the_recorded_file_is_compared_by_its_events_not_its_chunks(tmp_path) -> None:
    from flagtrack.drivers.formats import write_events
    from flagtrack.drivers.sim.quickline import WavyFlag, line_events

    events = np.concatenate(list(line_events(WavyFlag(), 0, 20_000, 640, 480)))
    write_events(tmp_path / "a.raw", events, width=640, height=480)
    write_events(tmp_path / "b.raw", events, width=640, height=480, encoding="evt2")  # other bytes, same events
    write_events(tmp_path / "c.raw", events[:-1], width=640, height=480)
    a, b, c = (live_figures.events_digest(tmp_path / f"{name}.raw") for name in "abc")
    assert a == b and a[0] == len(events) and c != a


def test_kept_up_compares_the_last_tenth_with_the_first_or_the_budget() -> None:
    steady = np.full(100, 5.0)
    growing = np.linspace(5.0, 500.0, 100)  # a backlog adds to every update
    shedding = np.concatenate([np.full(50, 5.0), np.full(50, 45.0)])  # held under a 50 ms budget
    assert live_figures.tenths_ms(growing) == (float(np.median(growing[:10])), float(np.median(growing[-10:])))
    assert all(np.isnan(live_figures.tenths_ms(np.zeros(0))))
    assert live_figures.kept_up(steady, missing=0) and not live_figures.kept_up(steady, missing=1)
    assert not live_figures.kept_up(growing, missing=0, max_lag_ms=50.0)
    assert not live_figures.kept_up(shedding, missing=0) and live_figures.kept_up(shedding, 0, max_lag_ms=50.0)
    assert not live_figures.kept_up(np.zeros(0), missing=0)
