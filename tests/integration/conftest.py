"""Fixtures shared by the integration tests."""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag(length=200.0, root=(100.0, 240.0))


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 0.2 s EVT 3.0 recording of a wavy flag (root (100, 240), length 200) with 1e5 ev/s of noise."""
    path = tmp_path_factory.mktemp("up") / "flag.raw"
    events = np.concatenate(list(line_events(FLAG, 0, 200_000, 640, 480, QuickLineParams(noise_rate_hz=1e5))))
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path


@pytest.fixture(scope="session")
def quick_demo(tmp_path_factory: pytest.TempPathFactory) -> subprocess.CompletedProcess[str]:
    """``flagtrack demo --quick --headless --json --out DIR``, run once for the tests that read it
    (test_demo checks what it prints and writes, test_viewer_rrd its .rrd), also when pytest-xdist
    runs them in two worker processes: the first to get here runs it, under a lock in the folder
    the workers share, and leaves its outcome there for the other."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # (each worker's folder is in the run's one)
    outcome = root / "quick_demo.json"
    with open(root / "quick_demo.lock", "w") as lock:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX)  # (released when the file closes)
        if not outcome.exists():
            out = root / "quick_demo" / "demo"
            out.parent.mkdir(exist_ok=True)
            demo = ["demo", "--quick", "--headless", "--json", "--out", str(out)]
            done = subprocess.run(
                [sys.executable, "-m", "flagtrack.daemon", *demo],
                capture_output=True,
                text=True,
                timeout=300,
            )
            fields = {"args": done.args, "returncode": done.returncode, "stdout": done.stdout, "stderr": done.stderr}
            outcome.write_text(json.dumps(fields))
    return subprocess.CompletedProcess(**json.loads(outcome.read_text()))
