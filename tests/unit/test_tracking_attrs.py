"""The processing parameters a centreline file records (TrackingConfig.attrs) and the denoise keys."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.core.windows import WindowSegment as SegmentConfig
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.tracking.section import Method, TrackingConfig, load_tracking_config


def test_attrs_hold_effective_values() -> None:
    attrs = TrackingConfig(root=(10.0, 20.0), length=200.0, joints=8, ds=3.0).attrs()
    assert attrs["link_lengths"] == [25.0] * 8
    assert attrs["ds"] == 3.0
    assert attrs["s_step"] == pytest.approx(200.0 / 67)  # ceil(200 / 3) = 67 steps of /s
    assert attrs["rel_tol"] == pytest.approx(1e-9)
    assert attrs["denoise_block_us"] == 2000 and "3x3" in attrs["denoise_neighbourhood"]
    assert (attrs["schedule_t_from_s"], attrs["schedule_dt_s"], attrs["schedule_tau_s"]) == ([0.0], [2.5e-4], [2.5e-4])


def test_s_step_matches_the_tracker_samples() -> None:
    config = TrackingConfig(root=(0.0, 0.0), length=200.0, ds=3.0)
    s = config.tracker_params().s
    assert np.diff(s) == pytest.approx(config.attrs()["s_step"])


def test_schedule_attrs_are_numeric_vectors_and_first_segment_values() -> None:
    schedule = (SegmentConfig(0.0, 5e-3, 5e-3), SegmentConfig(2.5, 3e-4, 6e-4))
    attrs = TrackingConfig(root=(0, 0), length=100, tau_s=1.0, dt_s=2.0, schedule=schedule).attrs()
    assert (attrs["dt_s"], attrs["tau_s"]) == (5e-3, 5e-3)
    assert attrs["schedule_t_from_s"] == [0.0, 2.5]
    assert attrs["schedule_dt_s"] == [5e-3, 3e-4]
    assert attrs["schedule_tau_s"] == [5e-3, 6e-4]


def test_given_link_lengths_are_kept() -> None:
    attrs = TrackingConfig(root=(0, 0), length=3.0, joints=2, link_lengths=(1.0, 2.0)).attrs()
    assert list(attrs["link_lengths"]) == [1.0, 2.0]


def test_denoise_block_us_reaches_the_filter(tmp_path: Path) -> None:
    path = tmp_path / "t.yaml"
    path.write_text("tracker: {root: [0, 0], length: 10, denoise: {block_us: 5000, max_neighbours: 2}}\n")
    params = load_tracking_config(path).tracker_params(path=str(path))
    assert params.denoise.block_us == 5000 and params.denoise.max_neighbours == 2


def test_bad_denoise_block_us_names_the_key(tmp_path: Path) -> None:
    path = tmp_path / "t.yaml"
    path.write_text("tracker: {root: [0, 0], length: 10, denoise: {block_us: 0}}\n")
    with pytest.raises(ConfigError, match=r"tracker\.denoise.*block_us must be positive"):
        load_tracking_config(path).tracker_params(path=str(path))


def test_paper_method_records_no_denoise() -> None:
    attrs = TrackingConfig(root=(0, 0), length=100, method=Method.PAPER).attrs()
    assert attrs["denoise_enabled"] is False and attrs["refine_deg"] is None and attrs["min_events"] == 1
