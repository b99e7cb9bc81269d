"""``flagtrack reconstruct`` end to end: a real EVT 3.0 file in, the DESIGN.md HDF5 layout out; the
tracking options' effects, and the progress bar on a real pseudo-terminal."""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from tqdm import tqdm

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.centreline import CentrelineBatch
from flagtrack.daemon.core.tracker import Tracker
from flagtrack.daemon.tracking.section import TrackingConfig
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.fakes.terminal import run_on_a_terminal

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


TRACK_ARGS = ["--root", "120", "250", "--length", "180", "--tau", "0.0003"]
ARGS = [*TRACK_ARGS, "--no-progress"]


def test_layout_attributes_and_times(raw_file: Path, tmp_path: Path, events: np.ndarray) -> None:
    out = tmp_path / "out.h5"
    assert main(["reconstruct", str(raw_file), "-o", str(out), *ARGS]) == 0
    with h5py.File(out, "r") as f:
        assert set(f) == {"t", "s", "x", "y", "joints", "delta_rms", "n_events", "lost", "stale", "shed"}
        assert f["lost"].dtype == np.uint8 and f["lost"].shape == (f["t"].shape[0],)
        assert set(f["joints"]) == {"x", "y"}
        n_t = f["t"].shape[0]
        assert f["x"].shape == f["y"].shape == (n_t, 51) and f["joints/x"].shape == (n_t, 11)
        assert f["x"].dtype == np.float64 and f["n_events"].dtype == np.int64
    batch, attrs = read_centrelines(out)
    for key in (
        "root",
        "length",
        "direction_deg",
        "joints",
        "alpha",
        "angle_limit_deg",
        "tau_s",
        "dt_s",
        "ds",
        "method",
        "min_events",
        "refine_deg",
        "denoise_window_us",
        "lost_enabled",
        "lost_min_fit",
        "flagtrack_version",
    ):
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
    config.write_text(
        "viewer: {}\ntracker:\n  root: [120, 250]\n  length: 180\n  joints: 8\n  tau_s: 0.0005\n  method: paper\n"
    )
    out = tmp_path / "out.h5"
    assert (
        main(
            [
                "reconstruct",
                str(raw_file),
                "-o",
                str(out),
                "-c",
                str(config),
                "--joints",
                "12",
                "--t-start",
                "5.01",
                "--t-stop",
                "5.05",
                "--no-progress",
            ]
        )
        == 0
    )
    batch, attrs = read_centrelines(out)
    assert attrs["joints"] == 12 and attrs["method"] == "paper" and attrs["tau_s"] == 0.0005
    assert batch.joints_x.shape[1] == 13
    assert batch.t_s[0] == pytest.approx(5.01) and batch.t_s[-1] <= 5.05 + 1e-12


@pytest.mark.parametrize("method", ["paper", "robust"])
def test_npy_input_gives_the_raw_files_centrelines(
    raw_file: Path, events: np.ndarray, tmp_path: Path, method: str
) -> None:
    path = tmp_path / "flag.npy"
    write_events(path, events, width=640, height=480)
    from_npy, from_raw = tmp_path / "npy.h5", tmp_path / "raw.h5"
    assert main(["reconstruct", str(path), "-o", str(from_npy), *ARGS, "--method", method]) == 0
    assert main(["reconstruct", str(raw_file), "-o", str(from_raw), *ARGS, "--method", method]) == 0
    (npy, npy_attrs), (raw, raw_attrs) = read_centrelines(from_npy), read_centrelines(from_raw)
    assert npy_attrs["input_format"] != raw_attrs["input_format"]
    assert npy_attrs["events_in"] == raw_attrs["events_in"] == len(events)
    assert npy_attrs["events_kept"] == raw_attrs["events_kept"]
    assert len(npy) == len(raw) > 200
    for name in ("t_s", "x", "y", "joints_x", "joints_y", "delta_rms"):
        np.testing.assert_allclose(getattr(npy, name), getattr(raw, name), rtol=0, atol=1e-9, err_msg=name)
    np.testing.assert_array_equal(npy.n_events, raw.n_events)


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--length", "180"], "tracker.root"),
        (["--root", "1", "2", "--length", "180", "--alpha", "3"], "alpha"),
    ],
)
def test_errors_are_one_line(
    raw_file: Path, tmp_path: Path, extra: list[str], words: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["reconstruct", str(raw_file), "-o", str(tmp_path / "o.h5"), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("flagtrack reconstruct: error:") and words in err and "\n" not in err


@pytest.mark.filterwarnings("default::flagtrack.drivers.formats.codec.FormatWarning")  # shown, as outside tests
def test_a_truncated_file_is_reconstructed_with_a_one_line_warning(
    raw_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut = tmp_path / "cut.raw"
    cut.write_bytes(raw_file.read_bytes()[:-1])  # the last word is incomplete
    assert main(["reconstruct", str(cut), "-o", str(tmp_path / "o.h5"), "--no-progress", *ARGS]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert warning == [
        f"flagtrack reconstruct: warning: {cut}, byte {cut.stat().st_size - 1}: stream ends inside "
        "a 2-byte EVT 3.0 word (1 trailing bytes; truncated file?); kept the events before it"
    ]


def test_missing_input_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["reconstruct", str(tmp_path / "nope.raw"), "-o", str(tmp_path / "o.h5"), *ARGS]) == 2
    assert "nope.raw" in capsys.readouterr().err


# --- the tracking options and the progress bar -------------------------------------------------------------

FLAG_DOWN = WavyFlag(root=(320.0, 60.0), length=180.0, direction_deg=90.0)  # along +y: down the image


@pytest.fixture(scope="module")
def down_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    events = np.concatenate(
        list(line_events(FLAG_DOWN, 0, 30_000, 640, 480, QuickLineParams(events_per_px2=10), seed=12))
    )
    path = tmp_path_factory.mktemp("rec") / "down.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path


def _run(path: Path, out: Path, *extra: str) -> tuple[CentrelineBatch, dict]:
    assert main(["reconstruct", str(path), "-o", str(out), "--no-progress", *extra]) == 0
    return read_centrelines(out)


def test_direction_is_degrees_from_x_towards_y(down_file: Path, tmp_path: Path) -> None:
    """A flag hanging along +y (down the image) is tracked from the first update with --direction 90;
    with --direction -90 the paper's chain points up the image, away from every event, and stays
    there, while the robust method's says it lost the flag and finds it (issue 19)."""
    common = ("--root", "320", "60", "--length", "180", "--tau", "0.0003")
    down, attrs = _run(down_file, tmp_path / "down.h5", *common, "--direction", "90")
    assert attrs["direction_deg"] == 90.0
    x_ref, y_ref = FLAG_DOWN.positions(down.t_s, down.s)
    error = np.sqrt(np.mean((down.x - x_ref) ** 2 + (down.y - y_ref) ** 2, axis=1))
    assert error.max() < 0.01 * 180, error.max()  # every update, the first included
    assert np.all(np.diff(down.joints_y[0]) > 0) and down.joints_y[0, -1] > 60 + 150
    up, _ = _run(down_file, tmp_path / "up.h5", *common, "--direction", "-90", "--method", "paper")
    np.testing.assert_allclose(up.joints_x, 320.0, atol=1e-9)
    np.testing.assert_allclose(up.joints_y[:, -1], 60.0 - 180.0, atol=1e-9)
    assert not up.lost.any()  # the paper's method does not detect
    found, _ = _run(down_file, tmp_path / "found.h5", *common, "--direction", "-90")
    error = np.sqrt(np.mean((found.x - x_ref) ** 2 + (found.y - y_ref) ** 2, axis=1))
    assert found.lost[0] == 1 or error[0] < 0.01 * 180  # lost at the start, unless found in the first update
    assert error[5:].max() < 0.01 * 180 and not found.lost[5:].any(), (error[:10], found.lost[:10])


def test_dt_sets_the_number_of_updates_and_the_time_step(raw_file: Path, events: np.ndarray, tmp_path: Path) -> None:
    span_us = int(events["t"][-1] - events["t"][0])
    for dt_us in (300, 700, 150):  # 300: the default dt = tau; 150: overlapping windows
        batch, attrs = _run(raw_file, tmp_path / f"dt{dt_us}.h5", *ARGS, "--dt", f"{dt_us * 1e-6}")
        assert attrs["dt_s"] == pytest.approx(dt_us * 1e-6) and attrs["tau_s"] == pytest.approx(3e-4)
        # every window that starts at or before the last event: the first at the first event
        assert len(batch) == span_us // dt_us + 1, dt_us
        np.testing.assert_allclose(np.diff(batch.t_s), dt_us * 1e-6, atol=1e-9)
        assert batch.t_s[0] == pytest.approx(events["t"][0] / 1e6 + 1.5e-4)


@pytest.mark.parametrize(("ds", "n_s"), [("6", 31), ("4.5", 41), ("50", 5)])
def test_ds_sets_the_samples_of_the_centreline(raw_file: Path, tmp_path: Path, ds: str, n_s: int) -> None:
    batch, attrs = _run(raw_file, tmp_path / "ds.h5", *ARGS, "--ds", ds)
    assert attrs["ds"] == float(ds) and batch.x.shape[1] == batch.y.shape[1] == n_s
    np.testing.assert_allclose(batch.s, np.linspace(0.0, 180.0, n_s))
    np.testing.assert_allclose(np.diff(batch.s), 180.0 / (n_s - 1))
    lengths = np.hypot(np.diff(batch.x, axis=1), np.diff(batch.y, axis=1)).sum(axis=1)
    assert np.all(lengths <= 180.0 * (1 + 1e-6))  # a chord polyline of the length-L curve


def test_alpha_is_stored_and_changes_the_search_areas(raw_file: Path, tmp_path: Path) -> None:
    default, default_attrs = _run(raw_file, tmp_path / "a06.h5", *ARGS)
    narrow, attrs = _run(raw_file, tmp_path / "a03.h5", *ARGS, "--alpha", "0.3")
    assert default_attrs["alpha"] == 0.6 and attrs["alpha"] == 0.3
    assert len(narrow) == len(default)
    assert np.median(narrow.n_events) < 0.8 * np.median(default.n_events)  # smaller areas hold fewer events
    assert np.abs(narrow.x - default.x).max() > 0.05 and np.abs(narrow.y - default.y).max() > 0.05
    x_ref, y_ref = FLAG.positions(narrow.t_s, narrow.s)  # both still follow the flag
    assert np.abs(narrow.y - y_ref).max() < 5.0


def _run_on_a_terminal(raw_file: Path, out: Path, *extra: str, timeout_s: float = 60.0) -> str:
    """Run the command with stderr on a real pseudo-terminal (80 x 24); return what the terminal got."""
    argv = [sys.executable, "-m", "flagtrack.daemon", "reconstruct", str(raw_file), "-o", str(out), *TRACK_ARGS, *extra]
    return run_on_a_terminal(argv, timeout_s=timeout_s, exit_s=10)


def test_progress_bar_on_a_terminal_and_not_with_no_progress(raw_file: Path, tmp_path: Path) -> None:
    shown = _run_on_a_terminal(raw_file, tmp_path / "a.h5")
    size = tqdm.format_sizeof(raw_file.stat().st_size)  # e.g. 927k
    assert "flag.raw:" in shown and "%|" in shown and f"/{size} [" in shown, shown  # name, bar, file size
    assert "updates from" in shown  # the summary line
    hidden = _run_on_a_terminal(raw_file, tmp_path / "b.h5", "--no-progress")
    assert "updates from" in hidden and "%|" not in hidden and "flag.raw:" not in hidden, hidden
    assert read_centrelines(tmp_path / "a.h5")[0].t_s.tolist() == read_centrelines(tmp_path / "b.h5")[0].t_s.tolist()
