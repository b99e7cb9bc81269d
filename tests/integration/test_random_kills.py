"""Random kills (issue 20): a sweep on the simulated rig killed with SIGKILL at random moments and
resumed each time with `flagtrack sweep --resume` completes with no point lost or repeated, every
.raw readable, the tunnel stopped by its own watchdog after each kill. The full 20-kill run is
`flagtrack bench kills` (figures in docs/reliability.md); here 2 kills on a 3-point plan."""

from __future__ import annotations

from pathlib import Path

import pytest

from flagtrack.daemon.bench.kills import random_kills


@pytest.mark.slow
def test_a_sweep_killed_at_random_moments_and_resumed_completes_whole(tmp_path: Path) -> None:
    report = random_kills(tmp_path, kills=2, seed=7, speeds=(4.0, 5.5), record_s=1.0)
    assert report.problems == [], report.problems
    assert report.kills == 2 and report.sessions == 3 and report.points == 3 and report.raw_files == 3
    assert report.watchdog_trips == 2 and report.max_zero_after_kill_s < 5.0
