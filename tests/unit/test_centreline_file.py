"""Centreline HDF5 files: exact round trip, incremental appends, clear errors."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats.centreline import CentrelineWriter, read_centrelines


def make_batch(n_t: int, n_s: int = 51, n_j: int = 10, t0: float = 0.0) -> CentrelineBatch:
    rng = np.random.default_rng(n_t)
    return CentrelineBatch(
        t_s=t0 + np.arange(n_t) * 1e-3,
        s=np.linspace(0, 1, n_s),
        x=rng.normal(size=(n_t, n_s)),
        y=rng.normal(size=(n_t, n_s)),
        joints_x=rng.normal(size=(n_t, n_j + 1)),
        joints_y=rng.normal(size=(n_t, n_j + 1)),
        delta_rms=rng.random(n_t),
        n_events=rng.integers(0, 100, n_t),
    )


def test_appends_round_trip_exactly(tmp_path: Path) -> None:
    a, b = make_batch(5), make_batch(7, t0=1.0)
    path = tmp_path / "c.h5"
    with CentrelineWriter(path, a.s, 10, {"units": "px", "alpha": 0.6, "root": [1.0, 2.0]}) as writer:
        writer.append(a)
        writer.append(b)
    got, attrs = read_centrelines(path)
    want = CentrelineBatch.concatenate([a, b])
    for name in ("t_s", "s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    assert attrs["units"] == "px" and attrs["alpha"] == 0.6 and list(attrs["root"]) == [1.0, 2.0]
    assert "flagtrack_version" in attrs
    with h5py.File(path) as f:
        assert f["n_events"].dtype == np.int64 and f["joints/x"].shape == (12, 11)


def test_shape_mismatch_is_refused() -> None:
    batch = make_batch(3)
    with pytest.raises(ValueError, match="x has shape"):
        CentrelineBatch(
            batch.t_s, batch.s, batch.x[:, :3], batch.y, batch.joints_x, batch.joints_y, batch.delta_rms, batch.n_events
        )


def test_not_a_centreline_file(tmp_path: Path) -> None:
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(FormatError, match="junk.h5"):
        read_centrelines(junk)
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["s"] = np.zeros(3)
    with pytest.raises(FormatError, match="missing /t"):
        read_centrelines(tmp_path / "other.h5")
