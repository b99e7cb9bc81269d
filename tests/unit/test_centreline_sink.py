"""The centreline sink: one shape check, batched appends, one attribute rule, atomic outputs, crash safety."""

from __future__ import annotations

import subprocess
import sys
import types
from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import centreline
from flagtrack.drivers.formats.centreline import (
    CentrelineShapeError,
    CentrelineSink,
    centreline_attrs,
    read_centrelines,
)
from tests.unit.test_centreline_file import make_batch

FIELDS = ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms", "n_events")


def assert_series_equal(got: CentrelineBatch, want: CentrelineBatch) -> None:
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    np.testing.assert_array_equal(got.s, want.s)


@pytest.fixture
def appends(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The sizes of the HDF5 appends the sinks make."""
    sizes: list[int] = []
    append = centreline.CentrelineWriter.append

    def counted(self: centreline.CentrelineWriter, batch: CentrelineBatch) -> None:
        sizes.append(len(batch))
        append(self, batch)

    monkeypatch.setattr(centreline.CentrelineWriter, "append", counted)
    return sizes


def test_a_batch_of_another_shape_is_refused_and_nothing_of_it_written(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    a, c = make_batch(4), make_batch(3, t0=2.0)
    with CentrelineSink(path, {"units": "px"}) as sink:
        sink.add(a)
        with pytest.raises(
            CentrelineShapeError, match="7 samples and 11 joints does not fit the file's 51 samples and 11 joints"
        ) as refused:
            sink.add(make_batch(5, n_s=7, t0=1.0))
        assert isinstance(refused.value, FormatError) and str(path) in str(refused.value)
        assert refused.value.got == (7, 11) and refused.value.want == (51, 11)
        with pytest.raises(CentrelineShapeError, match="51 samples and 4 joints"):
            sink.add(make_batch(5, n_j=3, t0=1.0))
        assert sink.n_pending == 4
        sink.add(c)
    got, _ = read_centrelines(path)
    assert_series_equal(got, CentrelineBatch.concatenate([a, c]))


def test_batches_are_appended_together_at_the_bound_or_on_flush(tmp_path: Path, appends: list[int]) -> None:
    """Ten batches of 3 with a bound of 8: an append at 9 and at 18 and 27 updates, none in between;
    flush() appends the rest; the file holds all 30 in order."""
    path = tmp_path / "c.h5"
    batches = [make_batch(3, t0=i) for i in range(10)]
    with CentrelineSink(path, {"units": "px"}, max_pending=8) as sink:
        for batch in batches[:2]:
            sink.add(batch)
        assert appends == [] and sink.n_updates == 0 and sink.n_pending == 6
        with h5py.File(path, "r") as f:  # created at the first batch, nothing in it yet
            assert f["t"].shape == (0,) and f["x"].shape == (0, 51)
        for batch in batches[2:]:
            sink.add(batch)
        assert appends == [9, 9, 9] and sink.n_updates == 27 and sink.n_pending == 3
        sink.flush()
        assert appends == [9, 9, 9, 3] and sink.n_pending == 0
        with h5py.File(path, "r") as f:
            np.testing.assert_array_equal(f["t"][()], CentrelineBatch.concatenate(batches).t_s)
        sink.flush()  # nothing pending: no append
    assert appends == [9, 9, 9, 3]
    got, _ = read_centrelines(path)
    assert_series_equal(got, CentrelineBatch.concatenate(batches))


def test_pending_batches_are_appended_once_the_interval_has_passed(
    tmp_path: Path, appends: list[int], monkeypatch: pytest.MonkeyPatch
) -> None:
    now_s = [100.0]
    clock = types.SimpleNamespace(monotonic=lambda: now_s[0])  # (a stalled host moves no interval)
    monkeypatch.setattr(centreline, "time", clock)
    with CentrelineSink(tmp_path / "c.h5", {"units": "px"}, flush_interval_s=0.2) as sink:
        sink.add(make_batch(3))
        sink.add(make_batch(2, t0=1.0))
        now_s[0] += 0.19
        sink.flush_if_due()
        assert appends == []
        now_s[0] += 0.01
        sink.flush_if_due()  # a caller's loop, without a batch
        assert appends == [5]
        sink.add(make_batch(4, t0=2.0))
        now_s[0] += 0.25
        sink.add(make_batch(1, t0=3.0))  # add checks the interval too
        assert appends == [5, 5]


def test_every_file_carries_the_processing_parameters_units_input_and_version(tmp_path: Path) -> None:
    """The provenance given at construction, the units and source of the first batch (over the
    mapping's units), values known only at the end (before and after the file opens)."""
    processing = {"alpha": 0.6, "root": [1.0, 2.0], "refine_deg": None, "units": "m"}
    calibration = {"calibration_degree": 3, "calibration_yaml": "degree: 3\n"}
    attrs = centreline_attrs(
        processing, units="m", input_file="/data/run.raw", calibration=calibration, input_format="raw"
    )
    assert attrs == {**processing, **calibration, "input_format": "raw", "input_file": "/data/run.raw"}
    path = tmp_path / "c.h5"
    with CentrelineSink(path, {**processing, **calibration, "input_file": "run.raw"}) as sink:
        sink.set_attrs({"early": 1})
        sink.add(make_batch(0), units="px", source="tracker")  # empty: the units still count
        sink.add(make_batch(3), units="furlong", source="other")
        sink.set_attrs({"events_in": 10, "events_kept": 7})
    _, got = read_centrelines(path)
    assert set(got) == {
        "alpha",
        "root",
        "units",
        "input_file",
        "source",
        "flagtrack_version",
        "calibration_degree",
        "calibration_yaml",
        "early",
        "events_in",
        "events_kept",
        "format",
        "format_version",
        "calibration_units",  # the plane unit of a file made with a calibration
    }  # refine_deg is unset (None): absent, not the text 'null'
    assert got["units"] == "px" and got["calibration_units"] == "px"
    assert got["units"] == "px" and got["source"] == "tracker" and got["input_file"] == "run.raw"
    assert got["alpha"] == 0.6 and list(got["root"]) == [1.0, 2.0] and got.get("refine_deg") is None
    assert got["calibration_yaml"] == "degree: 3\n" and got["events_kept"] == 7
    assert centreline_attrs({}, units="px")["input_file"] is None  # every file says what it came from, if anything


def test_a_file_needs_its_units(tmp_path: Path) -> None:
    sink = CentrelineSink(tmp_path / "c.h5", {"alpha": 0.6})
    with pytest.raises(ValueError, match="units"):
        sink.add(make_batch(2))


def test_the_shape_given_up_front_is_checked_and_written_even_without_updates(tmp_path: Path) -> None:
    """reconstruct knows s and N_j before any update: a recording without one still gets a valid
    (empty) file; a sink that never learnt a shape leaves none; an empty first batch sets the shape."""
    s = np.linspace(0, 1, 51)
    with CentrelineSink(tmp_path / "known.h5", {"units": "px"}, s=s, n_joints=10) as sink:
        with pytest.raises(CentrelineShapeError):
            sink.add(make_batch(2, n_j=4))
    got, attrs = read_centrelines(tmp_path / "known.h5")
    assert len(got) == 0 and got.x.shape == (0, 51) and got.joints_x.shape == (0, 11) and attrs["units"] == "px"
    with CentrelineSink(tmp_path / "never.h5", {"units": "px"}):
        pass
    assert not (tmp_path / "never.h5").exists()
    with CentrelineSink(tmp_path / "empty.h5", {"units": "px"}) as sink:
        sink.add(make_batch(0, n_s=7))
        with pytest.raises(CentrelineShapeError):
            sink.add(make_batch(2))
    assert read_centrelines(tmp_path / "empty.h5")[0].x.shape == (0, 7)


def test_close_is_idempotent_and_final(tmp_path: Path) -> None:
    sink = CentrelineSink(tmp_path / "c.h5", {"units": "px"})
    sink.add(make_batch(3))
    sink.close()
    sink.close()
    with pytest.raises(ValueError, match="closed"):
        sink.add(make_batch(3))
    assert len(read_centrelines(tmp_path / "c.h5")[0]) == 3


def test_an_atomic_sink_shows_its_file_only_once_closed(tmp_path: Path) -> None:
    """Nothing at the path while writing (a temporary file beside it), the whole file after close,
    no temporary file left; an exception leaving the block removes it, and an older file at the path
    is left as it was."""
    path = tmp_path / "out" / "c.h5"
    a = make_batch(5)
    with CentrelineSink(path, {"units": "px"}, atomic=True) as sink:
        sink.add(a)
        sink.flush()
        assert not path.exists()
        names = [p.name for p in path.parent.iterdir()]
        assert len(names) == 1 and names[0].startswith(".c.h5.") and names[0].endswith(".tmp")
    assert_series_equal(read_centrelines(path)[0], a)
    assert [p.name for p in path.parent.iterdir()] == ["c.h5"]

    with (
        pytest.raises(RuntimeError, match="tracker failed"),
        CentrelineSink(path, {"units": "px"}, atomic=True) as sink,
    ):
        sink.add(make_batch(7))
        sink.flush()
        raise RuntimeError("tracker failed")
    assert [p.name for p in path.parent.iterdir()] == ["c.h5"]
    assert_series_equal(read_centrelines(path)[0], a)


def test_a_non_atomic_sink_leaving_with_an_exception_keeps_every_update(tmp_path: Path) -> None:
    path = tmp_path / "c.h5"
    with pytest.raises(RuntimeError), CentrelineSink(path, {"units": "px"}) as sink:
        sink.add(make_batch(4))
        raise RuntimeError("stop")
    assert len(read_centrelines(path)[0]) == 4


def test_a_crash_keeps_what_was_flushed(tmp_path: Path) -> None:
    """A process that dies (no close, no exception handling) after a flush and one more add: the
    file reads back with the flushed updates and its attributes."""
    path = tmp_path / "c.h5"
    script = f"""
import os
from flagtrack.drivers.formats.centreline import CentrelineSink
from tests.unit.test_centreline_file import make_batch
sink = CentrelineSink({str(path)!r}, {{"units": "px", "alpha": 0.6}})
sink.add(make_batch(5))
sink.add(make_batch(2, t0=1.0))
sink.flush()
sink.add(make_batch(3, t0=2.0))
os._exit(1)
"""
    root = Path(__file__).resolve().parents[2]
    crashed = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, timeout=120)
    assert crashed.returncode == 1, crashed.stderr
    got, attrs = read_centrelines(path)
    assert_series_equal(got, CentrelineBatch.concatenate([make_batch(5), make_batch(2, t0=1.0)]))
    assert attrs["alpha"] == 0.6 and attrs["units"] == "px"
