"""``flagtrack reconstruct`` end to end: a real EVT 3.0 file in, the DESIGN.md HDF5 layout out."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.tracking_config import TrackingConfig
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag(root=(120.0, 250.0), length=180.0)
T0_US = 5_000_000


@pytest.fixture(scope="module")
def events() -> np.ndarray:
    params = QuickLineParams(events_per_px2=10, noise_rate_hz=1e5)
    return np.concatenate(list(line_events(FLAG, T0_US, T0_US + 80_000, 640, 480, params, seed=11)))


@pytest.fixture(scope="module")
def raw_file(events: np.ndarray, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "flag.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path


ARGS = ["--root", "120", "250", "--length", "180", "--tau", "0.0003", "--no-progress"]


def test_layout_attributes_and_times(raw_file: Path, tmp_path: Path, events: np.ndarray) -> None:
    out = tmp_path / "out.h5"
    assert main(["reconstruct", str(raw_file), "-o", str(out), *ARGS]) == 0
    with h5py.File(out, "r") as f:
        assert set(f) == {"t", "s", "x", "y", "joints", "delta_rms", "n_events"}
        assert set(f["joints"]) == {"x", "y"}
        n_t = f["t"].shape[0]
        assert f["x"].shape == f["y"].shape == (n_t, 51) and f["joints/x"].shape == (n_t, 11)
        assert f["x"].dtype == np.float64 and f["n_events"].dtype == np.int64
    batch, attrs = read_centrelines(out)
    for key in ("root", "length", "direction_deg", "joints", "alpha", "angle_limit_deg", "tau_s", "dt_s", "ds",
                "method", "min_events", "refine_deg", "denoise_window_us", "flagtrack_version"):
        assert key in attrs, key
    assert attrs["units"] == "px" and attrs["input_file"] == str(raw_file) and attrs["ds"] == pytest.approx(3.6)
    assert attrs["events_in"] == len(events)
    # /t: window centres on the recording's clock, seconds; the first window starts at the first event
    assert batch.t_s[0] == pytest.approx(events["t"][0] / 1e6 + 1.5e-4)
    np.testing.assert_allclose(np.diff(batch.t_s), 3e-4, atol=1e-9)
    np.testing.assert_allclose(batch.s, np.linspace(0, 180, 51))
    np.testing.assert_allclose(batch.joints_x[:, 0], 120.0)
    lengths = np.hypot(np.diff(batch.x, axis=1), np.diff(batch.y, axis=1)).sum(axis=1)
    np.testing.assert_allclose(lengths, 180.0, rtol=1e-6)
    assert np.nanmedian(batch.delta_rms) < 2.0 and np.median(batch.n_events) > 100


def test_file_equals_the_tracker_on_the_array(raw_file: Path, tmp_path: Path, events: np.ndarray) -> None:
    out = tmp_path / "out.h5"
    assert main(["reconstruct", str(raw_file), "-o", str(out), *ARGS]) == 0
    batch, _ = read_centrelines(out)
    params = TrackingConfig(root=(120, 250), length=180, tau_s=3e-4).tracker_params()
    tracker = Tracker(params, sensor_size=(640, 480))
    expected = CentrelineBatch.concatenate([tracker.feed(events), tracker.finish()])
    for name in ("t_s", "x", "y", "joints_x", "delta_rms"):
        np.testing.assert_allclose(getattr(batch, name), getattr(expected, name), atol=1e-9, err_msg=name)


def test_config_file_and_flags_that_override_it(raw_file: Path, tmp_path: Path) -> None:
    config = tmp_path / "rig.yaml"
    config.write_text("viewer: {}\ntracker:\n  root: [120, 250]\n  length: 180\n  joints: 8\n  tau_s: 0.0005\n"
                      "  method: paper\n")
    out = tmp_path / "out.h5"
    assert main(["reconstruct", str(raw_file), "-o", str(out), "-c", str(config), "--joints", "12",
                 "--t-start", "5.01", "--t-stop", "5.05", "--no-progress"]) == 0
    batch, attrs = read_centrelines(out)
    assert attrs["joints"] == 12 and attrs["method"] == "paper" and attrs["tau_s"] == 0.0005
    assert batch.joints_x.shape[1] == 13
    assert batch.t_s[0] == pytest.approx(5.01) and batch.t_s[-1] <= 5.05 + 1e-12


def test_npy_input(events: np.ndarray, tmp_path: Path) -> None:
    path = tmp_path / "flag.npy"
    write_events(path, events, width=640, height=480)
    out = tmp_path / "out.h5"
    assert main(["reconstruct", str(path), "-o", str(out), *ARGS, "--method", "paper"]) == 0
    assert len(read_centrelines(out)[0]) > 200


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--length", "180"], "tracker.root"),
        (["--root", "1", "2", "--length", "180", "--alpha", "3"], "alpha"),
    ],
)
def test_errors_are_one_line(raw_file: Path, tmp_path: Path, extra: list[str], words: str,
                             capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["reconstruct", str(raw_file), "-o", str(tmp_path / "o.h5"), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("flagtrack reconstruct: error:") and words in err and "\n" not in err


def test_a_truncated_file_is_reconstructed_with_a_one_line_warning(raw_file: Path, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    cut = tmp_path / "cut.raw"
    cut.write_bytes(raw_file.read_bytes()[:-1])  # the last word is incomplete
    assert main(["reconstruct", str(cut), "-o", str(tmp_path / "o.h5"), "--no-progress", *ARGS]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warning == [f"flagtrack reconstruct: warning: {cut}, byte {cut.stat().st_size - 1}: stream ends inside "
                       "a 2-byte EVT 3.0 word (1 trailing bytes; truncated file?); kept the events before it"]


def test_missing_input_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["reconstruct", str(tmp_path / "nope.raw"), "-o", str(tmp_path / "o.h5"), *ARGS]) == 2
    assert "nope.raw" in capsys.readouterr().err
