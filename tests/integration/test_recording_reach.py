"""A live tracker's centrelines set against the first events of their recording (a sweep point's
``chain_reach``): the same figure as ``reconstruct``'s, from a bounded read."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.tracking.offline import reconstruct_file
from flagtrack.daemon.tracking.reach import recording_reach
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.daemon.tracking.setup import tracking_setup
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag(root=(120.0, 250.0), length=180.0)


@pytest.fixture(scope="module")
def raw_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    params = QuickLineParams(events_per_px2=10, noise_rate_hz=1e5)
    events = np.concatenate(list(line_events(FLAG, 0, 80_000, 640, 480, params, seed=3)))
    path = tmp_path_factory.mktemp("rec") / "flag.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path


@pytest.mark.parametrize("length", [180.0, 207.0])
def test_the_recordings_reach_is_the_reconstructions(raw_file: Path, tmp_path: Path, length: float) -> None:
    setup = tracking_setup(dataclasses.replace(TrackingConfig(), root=FLAG.root, length=length, tau_s=3e-4))
    summary = reconstruct_file(raw_file, tmp_path / "out.h5", setup)
    updates, _ = read_centrelines(tmp_path / "out.h5")
    reach = recording_reach(raw_file, updates, setup)
    assert reach is not None and summary.reach is not None
    assert reach.reach == pytest.approx(FLAG.length / length, abs=0.01)
    assert reach.reach == pytest.approx(summary.reach.reach, abs=0.005)


def test_updates_of_another_time_say_nothing(raw_file: Path, tmp_path: Path) -> None:
    setup = tracking_setup(dataclasses.replace(TrackingConfig(), root=FLAG.root, length=180.0, tau_s=3e-4))
    reconstruct_file(raw_file, tmp_path / "out.h5", setup)
    updates, _ = read_centrelines(tmp_path / "out.h5")
    later = dataclasses.replace(updates, t_s=updates.t_s + 10.0)
    assert recording_reach(raw_file, later, setup) is None
