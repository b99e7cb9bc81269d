"""``flagtrack aim`` as a real process: headless snapshot and JSON from a recording (no Rerun, no
display), the focus figure ordering recordings by their blur, the real recordings, the simulated
camera of a rig for a bounded time and until Ctrl-C, a Rerun file, and one-line errors."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.events import make_events
from flagtrack.drivers.formats import read_events, write_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events
from tests.fakes.helpers import wait_until

HOT = ((40, 50), (600, 400), (320, 100))  # pixels firing at 2 kHz in the recordings
KEYS = {
    "source", "sensor", "t_end_s", "window_ms", "events_in_window", "events", "events_outside_sensor",
    "event_rate_hz", "rate_span_s", "line_width_px", "line_width_spread_px", "line_places", "line_note",
    "n_hot_pixels", "hot_pixels", "chain", "calibration", "snapshot",
}  # fmt: skip
HEADLESS = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
WITH_IMPORTS = (
    "import sys; from flagtrack.daemon.cli import main; code = main(sys.argv[1:]); "
    "print('imported:', sorted({'rerun', 'matplotlib'} & set(sys.modules)), file=sys.stderr); sys.exit(code)"
)


def write_recording(path: Path, blur_px: float, duration_us: int = 600_000) -> Path:
    """A slowly flapping 300 px flag (root (150, 240)) whose line is spread across by ``blur_px``,
    1 Mev/s of line events, 20 kev/s of noise and the hot pixels of HOT, as EVT 3.0."""
    flag = WavyFlag(length=300.0, root=(150.0, 240.0), frequency_hz=4.0, amp_rad=0.3)
    params = QuickLineParams(events_per_px2=30.0, line_width_px=blur_px, noise_rate_hz=20_000.0)
    events = [*line_events(flag, 0, duration_us, 640, 480, params, seed=1)]
    t = np.arange(0, duration_us, 500)
    events += [make_events(t, np.full(len(t), x), np.full(len(t), y), np.ones(len(t))) for x, y in HOT]
    merged = np.concatenate(events)
    write_events(path, merged[np.argsort(merged["t"], kind="stable")], width=640, height=480, encoding="evt3")
    return path


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[float, Path]:
    folder = tmp_path_factory.mktemp("aim")
    return {blur: write_recording(folder / f"blur{blur}.raw", blur) for blur in (0.5, 1.0, 2.0, 3.0)}


def aim(*args: str, env: dict[str, str] | None = None, timeout_s: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", WITH_IMPORTS, "aim", *args],
        capture_output=True, text=True, timeout=timeout_s, env=env or HEADLESS,
    )  # fmt: skip


def aim_here(capsys: pytest.CaptureFixture[str], *args: str) -> dict:
    """Run ``flagtrack aim ... --json`` in this process (a run here is the same code with no start-up)."""
    code = main(["aim", *args, "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


def read_png(path: Path) -> np.ndarray:
    from matplotlib.image import imread

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return imread(path)


def test_snapshot_and_json_headless_without_rerun(recordings: dict[float, Path], tmp_path: Path) -> None:
    """The issue's target: `aim --replay REC --snapshot OUT.png` with no display; --json on stdout."""
    png = tmp_path / "sub" / "aim.png"
    done = aim("--replay", str(recordings[1.0]), "--snapshot", str(png), "--json", "--root", "150", "240",
               "--length", "300", "--window-ms", "5")  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "imported: ['matplotlib']" in done.stderr  # rerun never imported, no viewer spawned
    figures = json.loads(done.stdout)
    assert set(figures) == KEYS
    assert figures["sensor"] == [640, 480] and figures["window_ms"] == 5.0 and figures["snapshot"] == str(png)
    truth = read_events(recordings[1.0]).events
    assert figures["events"] == len(truth) and figures["events_outside_sensor"] == 0
    assert figures["t_end_s"] == pytest.approx((int(truth["t"].max()) + 1) * 1e-6)
    t_end_us = int(truth["t"].max()) + 1
    assert figures["events_in_window"] == np.count_nonzero(truth["t"] >= t_end_us - 5_000)
    in_span = np.count_nonzero(truth["t"] >= t_end_us - round(figures["rate_span_s"] * 1e6))
    assert 0.9 <= figures["rate_span_s"] <= 1.0 or figures["rate_span_s"] == pytest.approx(0.6, abs=1e-6)
    assert figures["event_rate_hz"] == pytest.approx(in_span / figures["rate_span_s"], rel=1e-3)
    assert {(p["x"], p["y"]) for p in figures["hot_pixels"]} == set(HOT) and figures["n_hot_pixels"] == 3
    assert all(p["rate_hz"] == pytest.approx(2000, rel=0.02) for p in figures["hot_pixels"])
    assert 1.5 < figures["line_width_px"] < 5 and figures["line_places"] >= 50
    assert figures["chain"] == {
        "root": [150.0, 240.0],
        "direction_deg": 0.0,
        "length": 300.0,
        "joints": 10,
        "units": "px",
    }
    image = read_png(png)
    assert image.shape[:2] == (890, 1000)
    rgb = image[..., :3]
    assert rgb.std() > 0.05  # not blank
    red = (rgb[..., 0] > 0.8) & (rgb[..., 1] < 0.3) & (rgb[..., 2] < 0.3)
    green = (rgb[..., 1] > 0.8) & (rgb[..., 0] < 0.3) & (rgb[..., 2] < 0.3)
    yellow = (rgb[..., 0] > 0.8) & (rgb[..., 1] > 0.8) & (rgb[..., 2] < 0.3)
    assert red.sum() > 50 and green.sum() > 50 and yellow.sum() > 200  # hot pixels, line places, chain


def test_the_focus_figure_orders_recordings_by_their_blur(
    recordings: dict[float, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    widths = [aim_here(capsys, "--replay", str(path), "--window-ms", "5")["line_width_px"]
              for _, path in sorted(recordings.items())]  # fmt: skip
    assert all(a < b for a, b in zip(widths, widths[1:], strict=False)), widths


def test_the_figures_print_as_a_few_lines(recordings: dict[float, Path]) -> None:
    done = aim("--replay", str(recordings[2.0]))
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert 4 <= len(lines) <= 8
    assert lines[1].startswith("event rate: ") and lines[2].startswith("line width: ")
    assert lines[3].startswith("hot pixels: 3: ") and "(40, 50) 2000 Hz" in lines[3]
    assert "no display" in done.stderr  # where a window would have been: said, not failed


@pytest.mark.shared_data
def test_every_real_recording(
    shared_real: Path, reference_values: dict, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each real recording: every event read, the end and the rate as the maker's decoder has them."""
    for name, ref in reference_values.items():
        path = shared_real / name
        extra = [] if path.suffix != ".dat" else ["--sensor", str(ref["x_range"][1] + 1), str(ref["y_range"][1] + 1)]
        png = tmp_path / f"{name}.png"
        figures = aim_here(capsys, "--replay", str(path), "--snapshot", str(png), *extra)
        assert figures["events"] == ref["events"] and figures["events_outside_sensor"] == 0, name
        assert figures["t_end_s"] == pytest.approx((ref["t_max_us"] + 1) * 1e-6, abs=1e-6), name
        span_us = ref["t_max_us"] + 1 - ref["t_min_us"]
        if span_us < 900_000:  # the whole recording is in the rate window
            assert figures["event_rate_hz"] == pytest.approx(ref["events"] / (span_us * 1e-6), rel=1e-6), name
        assert read_png(png)[..., :3].std() > 0.01, name


def sim_rig(tmp_path: Path) -> Path:
    rig = tmp_path / "rig.yaml"
    rig.write_text(
        "rig: aimtest\n"
        "camera: {id: cam0, adapter: simulated, simulated: {speed_mps: 6.0, root_px: [150, 240], length_px: 300}}\n"
        "tracker: {root: [150, 240], length: 300}\n"
        f"viewer: {{sink: rrd, rrd_path: {tmp_path / 'rig-live.rrd'}}}\n"
    )
    return rig


def test_the_rigs_simulated_camera_for_a_bounded_time_into_a_rerun_file(tmp_path: Path) -> None:
    rrd = tmp_path / "aim.rrd"
    done = aim("-c", str(sim_rig(tmp_path)), "--duration", "2", "--rrd", str(rrd), "--json")
    assert done.returncode == 0, done.stderr
    figures = json.loads(done.stdout)
    assert figures["source"] == "camera cam0 (simulated)" and figures["event_rate_hz"] > 0
    assert figures["chain"]["root"] == [150.0, 240.0]
    status = [line for line in done.stderr.splitlines() if line.startswith("t ")]
    assert status and all("rate" in line and "line width" in line for line in status)
    assert not (tmp_path / "rig-live.rrd").exists()  # the rig's own file is left alone
    from rerun.chunk import RrdReader

    entities = set(RrdReader(rrd).store().schema().entity_paths())
    expected = {"image", "chain", "joints", "search_areas", "line_width", "hot_pixels"}
    assert {f"/aim/camera/{name}" for name in expected} <= entities
    assert {"/aim/plots/event_rate_hz", "/aim/figures"} <= entities


def test_ctrl_c_ends_a_live_run_with_its_figures(tmp_path: Path) -> None:
    png = tmp_path / "end.png"
    proc = subprocess.Popen(
        [sys.executable, "-m", "flagtrack.daemon", "aim", "-c", str(sim_rig(tmp_path)), "--json", "--snapshot", str(png)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=HEADLESS,
    )  # fmt: skip
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stderr.readline, "")), daemon=True)
    reader.start()
    try:
        wait_until(lambda: any(line.startswith("t ") for line in lines), 120, "a status line", poll_s=0.1)
    finally:
        proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=60)
    reader.join(timeout=10)
    assert proc.returncode == 0, "".join(lines)
    assert set(json.loads(out)) == KEYS and read_png(png).shape[:2] == (890, 1000)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--replay", "{tmp}/missing.raw"], "--replay {tmp}/missing.raw: no such file"),
        (["--replay", "{tmp}"], "--replay {tmp}: is a folder, not a file"),
        (["-c", "{tmp}/missing.yaml"], "-c {tmp}/missing.yaml: no such file"),
        (["-c", "{tmp}"], "-c {tmp}: is a folder, not a file"),
        (["-c", "{tmp}/bad-rig.yaml"], "key 'camera.adapter'"),
        (["--replay", "{rec}", "--viewer", "window"], "argument --viewer: invalid choice: 'window'"),
        (["--replay", "{rec}", "--window-ms", "abc"], "argument --window-ms: invalid float value: 'abc'"),
        (["--replay", "{rec}", "--window-ms", "0"], "--window-ms must be more than 0"),
        (["--replay", "{rec}", "--hot-factor", "0.5"], "--hot-factor/--hot-min-rate: factor must be more than 1"),
        (["--replay", "{rec}", "--length", "-3", "--root", "1", "2"], "key 'tracker': length must be positive"),
        (["--replay", "{rec}", "--snapshot", "{tmp}"], "--snapshot"),
        ([], "give a rig config (-c RIG.yaml) or a recording (--replay REC)"),
        (["--replay", "{tmp}/notes.txt"], "unknown event file type '.txt'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    args: list[str], says: str, recordings: dict[float, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "notes.txt").write_text("not events\n")
    (tmp_path / "bad-rig.yaml").write_text("camera: {adapter: webcam}\n")
    fill = {"tmp": str(tmp_path), "rec": str(recordings[0.5])}
    argv = ["aim", *(a.format(**fill) for a in args)]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and err.startswith("flagtrack aim: error: "), err
    assert says.format(**fill) in err


def test_a_hardware_camera_through_its_sdk(
    fake_nd, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The rig's Prophesee camera (the fake neuromorphic-drivers SDK): the device's EVT 3.0 bytes are
    decoded, every event the sensor produced is counted, the flapping line is measured. The rig's root
    is off this sensor: aim is where that is seen and fixed (`up` refuses it), so it opens anyway."""
    fake = fake_nd._fake.plug(fake_nd.FakeCamera(duration_us=150_000, seed=5))
    rig = tmp_path / "rig.yaml"
    rig.write_text(
        'camera: {id: cam0, adapter: prophesee, hardware: {serial: "00050423", stall_timeout_s: 30}}\n'
        "tracker: {root: [1500, 240], length: 300}\n"
    )
    monkeypatch.delenv("DISPLAY", raising=False)
    figures = aim_here(capsys, "-c", str(rig), "--duration", "3", "--window-ms", "20")
    assert figures["source"] == "camera cam0 (prophesee)"
    assert figures["events"] == len(fake.sent_events) > 1000
    assert figures["t_end_s"] >= fake.sent_events["t"][-1] * 1e-6
    assert figures["event_rate_hz"] > 0 and figures["line_width_px"] is not None


CALIBRATION = {  # 0.5 mm per pixel, plane axes along the image's
    "format": "flagtrack-calibration", "version": 1, "units": "m", "image_size": [640, 480], "degree": 1,
    "forward": {"degree": 1, "centre": [0.0, 0.0], "scale": 1.0, "exponents": [[0, 0], [1, 0], [0, 1]],
                "x": [0.0, 0.0005, 0.0], "y": [0.0, 0.0, 0.0005]},
    "inverse": {"degree": 1, "centre": [0.0, 0.0], "scale": 1.0, "exponents": [[0, 0], [1, 0], [0, 1]],
                "x": [0.0, 2000.0, 0.0], "y": [0.0, 0.0, 2000.0]},
}  # fmt: skip


def test_a_calibrated_chain_and_the_calibrations_grid(
    recordings: dict[float, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The rig's tracker section in metres with its calibration (relative to the rig file): the chain
    and a grid every 5 cm are drawn over the image (the grid's dotted lines every 100 px)."""
    import yaml

    (tmp_path / "cal.yaml").write_text(yaml.safe_dump(CALIBRATION))
    rig = tmp_path / "rig.yaml"
    rig.write_text("tracker: {root: [0.075, 0.12], length: 0.15, calibration: cal.yaml}\n")
    png = tmp_path / "cal.png"
    figures = aim_here(capsys, "-c", str(rig), "--replay", str(recordings[1.0]), "--snapshot", str(png))
    assert figures["chain"] == {"root": [0.075, 0.12], "direction_deg": 0.0, "length": 0.15, "joints": 10, "units": "m"}
    assert figures["calibration"] == {"path": str(tmp_path / "cal.yaml"), "units": "m", "grid_step": 0.05}
    rgb = read_png(png)[..., :3]
    yellow = (rgb[..., 0] > 0.8) & (rgb[..., 1] > 0.8) & (rgb[..., 2] < 0.3)
    assert yellow.sum() > 200  # the chain, drawn in pixels
