"""Loss of track in sweeps and feedback (issue 19): each point's lost fraction in the run log, the
summary CSV and the figure, ``suspect`` above the bound; the feedback loop holds while lost."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.services.supervisor.analysis import point_metrics
from flagtrack.daemon.services.supervisor.feedback import ControllerState, control_step, measured_amplitude
from flagtrack.daemon.services.supervisor.section import FeedbackConfig, SupervisorConfig
from flagtrack.daemon.sweep.plan import SpeedRange, SweepConfig, plan_points
from flagtrack.daemon.sweep.progress import PointFacts, is_suspect
from flagtrack.daemon.sweep.runlog import PointResult, RunLog, read_run
from flagtrack.daemon.sweep.summary import write_summary
from flagtrack.daemon.typed_yaml import from_mapping
from tests.fakes.helpers import rigid_flapping


def test_point_metrics_count_the_lost_updates() -> None:
    lost = np.zeros(1000, dtype=np.uint8)
    lost[100:180] = 1
    metrics = point_metrics([rigid_flapping(np.arange(len(lost)) * 1e-3, lost=lost)], 100.0, (0.0, 0.0), 0.0)
    assert metrics.lost_fraction == pytest.approx(0.08) and metrics.amplitude_over_l == pytest.approx(0.2, rel=0.05)
    assert (
        point_metrics(
            [rigid_flapping(np.arange(1000) * 1e-3, lost=np.zeros(1000, np.uint8))], 100.0, (0.0, 0.0), 0.0
        ).lost_fraction
        == 0.0
    )


@pytest.mark.parametrize(
    ("fraction", "bound", "suspect"),
    [(0.08, 0.05, True), (0.05, 0.05, False), (0.0, 0.0, False), (math.nan, 0.05, False)],
)
def test_a_point_is_suspect_above_the_bound(fraction: float, bound: float, suspect: bool) -> None:
    assert is_suspect(fraction, bound) is suspect


@pytest.mark.parametrize(
    ("reach", "suspect"), [(0.87, True), (1.04, True), (0.975, False), (1.02, False), (math.nan, False)]
)
def test_a_point_whose_chain_is_not_the_flags_length_is_suspect(reach: float, suspect: bool) -> None:
    assert is_suspect(0.0, 0.05, 0.0, "flapping", reach) is suspect


def test_the_bound_is_a_supervisor_key_with_a_default_of_5_percent() -> None:
    assert SupervisorConfig().suspect_lost_fraction == 0.05
    assert from_mapping(SupervisorConfig, {"suspect_lost_fraction": 0.1}).suspect_lost_fraction == 0.1
    with pytest.raises(ConfigError, match="suspect_lost_fraction"):
        from_mapping(SupervisorConfig, {"suspect_lost_fraction": 2.0}, key="supervisor")


def test_the_feedback_loop_holds_while_the_flag_is_lost() -> None:
    cfg = FeedbackConfig(target_amplitude_over_l=0.25, start_speed_mps=5.0)
    state = ControllerState(0.0, 5.0)
    moved = control_step(state, measured_amplitude(0.10, 0.01, cfg), 1.0, cfg)
    assert moved.speed_mps > state.speed_mps  # found: acts on the amplitude
    held = control_step(state, measured_amplitude(0.10, 0.30, cfg), 1.0, cfg)
    assert held == state  # lost in 30 % of the window: the output and the integral are held
    assert math.isnan(measured_amplitude(0.10, 0.06, cfg)) and measured_amplitude(0.1, math.nan, cfg) == 0.1


def _run(run_dir: Path, suspect: bool) -> Path:
    points = plan_points(SweepConfig(range=SpeedRange(4.0, 5.0, 1.0), settle_s=1, record_s=1))
    with RunLog.create(run_dir, run_id="r", config={}, plan=points, t_unix=1.0) as log:
        log.point(PointResult.planned(points[0], state="still", lost_fraction=0.0, event_rate_mev_s=0.1))
        log.point(
            PointResult.planned(
                points[1],
                state="flapping",
                amplitude_over_l=0.2,
                lost_fraction=0.3,
                suspect=suspect,
                event_rate_mev_s=2,
            )
        )
    return run_dir


def test_run_log_summary_and_figure_carry_the_lost_fraction_and_suspect(tmp_path: Path) -> None:
    _run(tmp_path / "a", suspect=True)
    latest = list(read_run(tmp_path / "a").latest_points().values())
    assert [(p.lost_fraction, p.suspect) for p in latest] == [(0.0, False), (0.3, True)]
    assert PointFacts.of(latest[1]).lost_fraction == 0.3
    csv_path, fig_path = write_summary(tmp_path / "a")
    with open(csv_path) as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["lost_fraction"], r["suspect"]) for r in rows] == [("0.0", "False"), ("0.3", "True")]
    _, unmarked = write_summary(_run(tmp_path / "b", suspect=False))
    assert fig_path.stat().st_size > 5000 and fig_path.read_bytes() != unmarked.read_bytes()  # the ring is drawn
