"""`flagtrack bench soak` for one minute (the 10-minute figure is in docs/reliability.md): the rig's
processes over a router at a modest rate lose nothing, record every event sent, and keep their memory."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.slow
def test_a_short_soak_loses_nothing(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "flagtrack.daemon", "bench", "soak", "--minutes", "0.1", "--rate", "0.5",
         "--cache", str(tmp_path), "--json"],
        capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    for key in ("minutes", "rate_mev_s", "lost_packets", "events_sent", "events_recorded", "rss_growth_mb",
                "latency_p99_ms"):  # fmt: skip
        assert key in result, key  # the keys the issue names
    assert result["minutes"] == 0.1 and result["rate_mev_s"] == 0.5
    assert result["events_sent"] > 0.8 * 0.5e6 * 6  # the camera kept its rate (6 s)
    assert result["lost_packets"] == 0 and result["events_recorded"] == result["events_sent"]
    assert set(result["rss_growth_mb_by_process"]) == {"router", "tracker", "recorder", "supervisor", "camera", "bench"}
    assert 0 <= result["rss_growth_mb"] < 50
    assert len(result["latency_p99_ms_per_minute"]) == 1 and math.isfinite(result["latency_p99_ms"])
