"""Ahead-of-time kernels (daemon/core/aot.py): built once by ``flagtrack reconstruct``, then used
without importing numba, with the same output as the numba path."""

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.bench.reconstruct import LENGTH, ROOT, TAU_S, make_recording


def _reconstruct(path: Path, out: Path, env: dict[str, str], *python_flags: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, *python_flags, "-m", "flagtrack.daemon", "reconstruct", str(path), "-o", str(out),
           "--root", str(ROOT[0]), str(ROOT[1]), "--length", str(LENGTH), "--tau", str(TAU_S), "--no-progress"]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600, check=True)


@pytest.mark.slow
def test_aot_build_then_native_run_matches_numba(tmp_path: Path) -> None:
    recording = tmp_path / "flap.raw"
    make_recording(recording, 0.1)  # ~0.6 M events: enough to trigger the build
    env = {**os.environ, "FLAGTRACK_AOT_DIR": str(tmp_path / "aot")}
    first = _reconstruct(recording, tmp_path / "first.h5", env)
    assert "ahead of time" in first.stderr
    assert list((tmp_path / "aot").glob("flagtrack_aot_*.pkl"))
    native = _reconstruct(recording, tmp_path / "native.h5", env, "-X", "importtime")
    imported = {line.rsplit("|", 1)[-1].strip() for line in native.stderr.splitlines() if "|" in line}
    assert "numba" not in imported
    assert "ahead of time" not in native.stderr  # nothing new to build
    jit_run = _reconstruct(recording, tmp_path / "jit.h5", {**env, "FLAGTRACK_AOT": "0"})
    assert "ahead of time" not in jit_run.stderr
    with h5py.File(tmp_path / "native.h5") as a, h5py.File(tmp_path / "jit.h5") as b:
        for name in ("t", "x", "y", "delta_rms", "n_events", "joints/x", "joints/y"):
            np.testing.assert_array_equal(a[name][()], b[name][()], err_msg=name)
