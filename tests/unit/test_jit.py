"""flagtrack.daemon.core.jit: numba's first call without SciPy's linalg (and without the garbage
collector), and SciPy intact afterwards."""

from __future__ import annotations

import subprocess
import sys

SCRIPT = """
import sys
import numpy as np
from flagtrack.daemon.core.events import make_events
from flagtrack.daemon.core.tracker import TrackerParams, track
from flagtrack.daemon.tracking.section import TrackingConfig

t = np.arange(2000, dtype=np.int64) * 5
events = make_events(t, 100 + (np.arange(2000) % 50), np.full(2000, 240), np.ones(2000))
batch = track(events, TrackingConfig(root=(100.0, 240.0), length=50.0).tracker_params())
assert len(batch.t_s) > 0
print("linalg_loaded_by_tracking", "scipy.linalg" in sys.modules)

import scipy.linalg
from scipy.optimize import brentq
print("scipy_linalg_works", bool(np.allclose(scipy.linalg.solve(np.eye(2), np.ones(2)), 1.0)),
      abs(brentq(lambda x: x - 1.0, 0.0, 2.0) - 1.0) < 1e-9)

from flagtrack.daemon.core.jit import njit

@njit
def dot(a, b):
    return np.dot(a, b)

print("compiled_dot", dot(np.ones(3), np.arange(3.0)))
import gc
print("gc_after_numba", gc.isenabled(), gc.get_freeze_count() > 10_000)
"""


def test_tracking_loads_no_scipy_linalg_and_scipy_works_after() -> None:
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=300, check=True)
    lines = dict(line.split(" ", 1) for line in out.stdout.splitlines())
    assert lines["linalg_loaded_by_tracking"] == "False"  # numba's BLAS probe did not import it (~0.15 s)
    assert lines["scipy_linalg_works"] == "True True"
    assert float(lines["compiled_dot"]) == 3.0  # numba's own np.dot still finds BLAS when it is compiled
    # numba's import ran without the collector, which is back on; its objects are frozen out of
    # later full collections (~0.1 s of every command)
    assert lines["gc_after_numba"] == "True True"
