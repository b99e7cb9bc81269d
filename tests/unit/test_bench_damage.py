"""`flagtrack bench damage`: flipped bits read both ways; resynchronising keeps at least as much."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flagtrack.daemon.bench.damage import measure
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.quickline import WavyFlag, line_events


def test_resynchronising_keeps_what_stopping_loses(tmp_path: Path) -> None:
    events = np.concatenate(list(line_events(WavyFlag(length=200.0, root=(100.0, 240.0)), 0, 100_000, 640, 480)))
    files = []
    for encoding in ("evt3", "evt2"):
        files.append(tmp_path / f"{encoding}.raw")
        write_events(files[-1], events, width=640, height=480, encoding=encoding)
    result = measure(files, tries=24, seed=2)
    assert result["tries"] == 24 and result["files"] == ["evt3.raw", "evt2.raw"]
    assert result["tries_cut_short_when_stopping"] > 0  # the flips did hit: stopping lost the rest
    assert result["stop_kept_median_of_those"] < 0.9
    assert result["resync_kept_median_of_those"] > 0.95
    assert result["resync_tries_below_99pct"] <= result["stop_tries_below_99pct"]
    assert result["resync_tries_with_skips"] >= 1 and result["resync_one_flip_tries_lost_beyond_bound"] == 0
