"""The flag's state cycle by cycle (daemon/core/flagstate.py): one state per flapping cycle with that
cycle's figures made by the per-point functions, states at a fixed rate when still, lost and stale
updates counted not measured, the same states whatever the batching."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.flagstate import CycleState, FlagStateTracker, StateParams
from flagtrack.daemon.services.supervisor.analysis import point_metrics

L, ROOT = 300.0, (150.0, 240.0)
S = np.linspace(0.0, L, 31)


def flag(
    t_s: np.ndarray, amplitude_over_l: float, f_hz: float, noise_px: float = 0.3, seed: int = 1
) -> CentrelineBatch:
    """A flag along x flapping as a wave travelling to its tip, sampled at ``t_s``."""
    rng = np.random.default_rng(seed)
    phase = 2 * np.pi * f_hz * t_s[:, None] - np.pi * S[None, :] / L
    y = ROOT[1] + amplitude_over_l * L * (S / L)[None, :] ** 2 * np.sin(phase) + rng.normal(0, noise_px, phase.shape)
    x = ROOT[0] + np.broadcast_to(S, y.shape).copy()
    n = len(t_s)
    return CentrelineBatch(t_s, S, x, y, x[:, ::10], y[:, ::10], np.zeros(n), np.zeros(n, dtype=np.int64))


def states_of(batch: CentrelineBatch, size: int, params: StateParams | None = None) -> list[CycleState]:
    tracker = FlagStateTracker(params or StateParams(L, ROOT, 0.0))
    out: list[CycleState] = []
    for start in range(0, len(batch), size):
        part = batch.select(slice(start, start + size))
        out += [(t := s).__class__(**{**t.__dict__, "index": start + t.index}) for s in tracker.push(part)]
    return out


def test_one_state_per_cycle_with_that_cycles_figures() -> None:
    t = np.arange(0.0, 3.0, 5e-4)
    states = states_of(flag(t, 0.25, 11.3), 64)
    cycles = [s for s in states if s.completes_cycle]
    # one per cycle, from the first crossing once the centre's average has run its 0.5 s
    assert len(cycles) == round((cycles[-1].cycle_end_s - cycles[0].cycle_start_s) * 11.3)
    assert cycles[0].cycle_start_s < 0.5 + 2 / 11.3
    assert all(s.flapping for s in cycles)
    assert np.median([s.frequency_hz for s in cycles]) == pytest.approx(11.3, rel=2e-3)
    assert np.median([s.amplitude_over_l for s in cycles]) == pytest.approx(0.25, rel=0.02)
    assert all(0.0 <= s.phase_rad < 0.2 for s in cycles)  # completed at the upward crossing: phase ~ 0
    assert all(0.2 < s.twi < 1.0 for s in cycles)  # a travelling wave
    gaps = np.diff([s.t_s for s in cycles])
    assert np.all(gaps < 0.1)  # at least once per cycle (88 ms)


def test_a_cycles_amplitude_is_the_per_point_figure_of_its_updates_and_f_agrees_over_a_stretch() -> None:
    t = np.arange(0.0, 3.0, 5e-4)
    batch = flag(t, 0.2, 9.7)
    cycles = [s for s in states_of(batch, 100) if s.completes_cycle]
    for state in cycles:
        rows = (batch.t_s >= state.cycle_start_s) & (batch.t_s <= state.cycle_end_s)
        offline = point_metrics([batch.select(rows)], L, ROOT, 0.0)
        assert state.amplitude_over_l == pytest.approx(offline.amplitude_over_l, rel=1e-12)
        assert state.updates == int(rows.sum())
    first, last = cycles[0], cycles[-1]
    stretch = (batch.t_s >= first.cycle_start_s) & (batch.t_s <= last.cycle_end_s)
    offline = point_metrics([batch.select(stretch)], L, ROOT, 0.0)
    cycles_per_s = len(cycles) / (last.cycle_end_s - first.cycle_start_s)
    assert cycles_per_s == pytest.approx(offline.frequency_hz, rel=0.01)


def test_a_still_flag_makes_states_at_the_interval_and_no_cycle() -> None:
    t = np.arange(0.0, 2.0, 1e-3)
    states = states_of(flag(t, 0.0, 10.0, noise_px=0.5), 50, StateParams(L, ROOT, 0.0, interval_s=0.1))
    assert states and not any(s.completes_cycle or s.flapping for s in states)
    assert np.diff([s.t_s for s in states]) == pytest.approx(0.1, abs=1.5e-3)
    assert all(math.isnan(s.frequency_hz) and math.isnan(s.phase_rad) for s in states)
    assert all(s.amplitude_over_l < 0.01 for s in states)


def test_lost_and_stale_updates_are_counted_not_measured() -> None:
    t = np.arange(0.0, 2.0, 5e-4)
    clean = flag(t, 0.25, 10.0)
    lost = np.zeros(len(t), np.uint8)
    lost[::10] = 1
    y = clean.y.copy()
    y[lost == 1, -1] += 200.0  # a lost update's shape is wild: it must not count in A/L
    batch = CentrelineBatch(
        clean.t_s, clean.s, clean.x, y, clean.joints_x, clean.joints_y, clean.delta_rms, clean.n_events, lost
    )
    cycles = [s for s in states_of(batch, 64) if s.completes_cycle]
    assert np.median([s.lost_fraction for s in cycles]) == pytest.approx(0.1, abs=0.01)
    assert max(s.amplitude_over_l for s in cycles) < 0.27
    assert all(s.stale_fraction == 0.0 for s in cycles)


@pytest.mark.parametrize("size", [7, 333, 6000])
def test_the_states_do_not_depend_on_how_the_updates_are_batched(size: int) -> None:
    batch = flag(np.arange(0.0, 1.5, 5e-4), 0.22, 12.0)
    reference = states_of(batch, 50)
    got = states_of(batch, size)
    assert [(s.t_s, s.completes_cycle) for s in got] == [(s.t_s, s.completes_cycle) for s in reference]
    assert [s.amplitude_over_l for s in got] == pytest.approx([s.amplitude_over_l for s in reference], rel=1e-12)


def test_a_new_stream_starts_again() -> None:
    tracker = FlagStateTracker(StateParams(L, ROOT, 0.0))
    tracker.push(flag(np.arange(0.0, 1.0, 5e-4), 0.25, 10.0))
    again = tracker.push(flag(np.arange(0.0, 0.05, 5e-4), 0.25, 10.0))  # time went back: a restarted camera
    assert not any(s.completes_cycle for s in again)  # no cycle across the restart


def test_bad_parameters_are_refused() -> None:
    with pytest.raises(ValueError, match="history_s"):
        StateParams(L, history_s=0.5, max_cycle_s=1.0)
    with pytest.raises(ValueError, match="positive"):
        StateParams(0.0)


def test_a_cycle_across_a_gap_is_no_cycle() -> None:
    t = np.arange(0.0, 2.0, 5e-4)
    keep = (t < 1.0) | (t > 1.03)  # 30 ms of updates missing (a camera that skipped ahead)
    states = states_of(flag(t, 0.25, 10.0).select(keep), 64)
    cycles = [s for s in states if s.completes_cycle]
    assert all(s.frequency_hz == pytest.approx(10.0, rel=0.01) for s in cycles)
    assert not any(s.cycle_start_s < 1.0 < s.cycle_end_s for s in cycles)


def test_a_stretch_of_jumping_shapes_makes_no_cycle() -> None:
    t = np.arange(0.0, 2.0, 5e-4)
    batch = flag(t, 0.25, 10.0)
    y = batch.y.copy()
    glitch = (t > 1.012) & (t < 1.03)  # the tip jumps across its centre and back (a stale shape let go)
    y[glitch, -1] = ROOT[1] - np.sign(y[glitch, -1] - ROOT[1]) * 60.0
    jumpy = CentrelineBatch(t, batch.s, batch.x, y, batch.joints_x, batch.joints_y, batch.delta_rms, batch.n_events)
    cycles = [s for s in states_of(jumpy, 64) if s.completes_cycle]
    assert all(s.frequency_hz == pytest.approx(10.0, rel=0.02) for s in cycles)
    assert any(s.cycle_start_s > 1.03 for s in cycles)  # and the cycles after it count again
