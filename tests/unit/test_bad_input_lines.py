"""Bad input found by a review: one line, exit 2, nothing already written lost."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.drivers.formats.files import write_events


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_an_event_beyond_any_sensor_is_refused_and_an_earlier_output_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A headerless DAT (as OpenEB reads one) of random bytes has 14-bit pixels: the noise filter's map
    grew to 1 GB and its rebase to 5 GB, for 22 s, for 10 events."""
    raw = np.zeros(10, dtype=[("t", "<u4"), ("w", "<u4")])
    raw["t"] = np.arange(10) * 100
    raw["w"] = 10_000 | (20 << 14)  # x 10 000, y 20
    (tmp_path / "junk.dat").write_bytes(raw.tobytes())
    earlier = tmp_path / "out.h5"
    with h5py.File(earlier, "w") as f:  # (an earlier result: -o replaces one, and no other file)
        f.attrs["format"] = "flagtrack-centrelines"
    before = earlier.read_bytes()
    argv = ["reconstruct", str(tmp_path / "junk.dat"), "-o", str(earlier), "--root", "150", "240", "--length", "300"]
    assert main(argv) == 2
    line = _one_line(capsys)
    assert "junk.dat" in line and "(10000, 20): beyond any event sensor" in line, line
    assert earlier.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == [
        "junk.dat",
        "out.h5",
    ]


def test_an_output_a_command_did_not_check_is_still_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    events = np.zeros(5, EVENT_DTYPE)
    events["t"] = np.arange(5)
    write_events(tmp_path / "rec.raw", events, width=640, height=480)
    assert main(["events", "convert", str(tmp_path / "rec.raw"), str(tmp_path / "nowhere" / "t.npy")]) == 2
    line = _one_line(capsys)
    assert line.startswith("flagtrack events: error: ") and str(tmp_path / "nowhere" / "t.npy") in line, line


@pytest.mark.parametrize("width", ["99999999999999999999", "-640", "0", "8193"])
def test_a_header_size_no_sensor_has_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], width: str) -> None:
    """Beyond 64 bits it was an OverflowError (events info), a hang (up --replay); 0 or negative, a
    warning per event and exit 0."""
    events = np.zeros(5, EVENT_DTYPE)
    events["t"] = np.arange(5)
    path = tmp_path / "rec.raw"
    write_events(path, events, width=640, height=480)
    data = path.read_bytes()
    path.write_bytes(data.replace(b"width=640", f"width={width}".encode(), 1))
    assert main(["events", "info", str(path)]) == 2
    assert f"sensor size {width} x 480 in the header: not an event sensor's" in _one_line(capsys)


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--centrelines", "nowhere"], "--centrelines: nowhere: no such folder"),
        (["--x-over-l", "nan"], "--x-over-l: must be a positive number, got nan"),
        (["--max-lag-ms", "-5"], "--max-lag-ms"),
        (["--window", "0"], "--window"),
    ],
)
def test_validate_refuses_a_missing_centrelines_folder_and_bad_numbers_first(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], extra: list[str], words: str
) -> None:
    """A mistyped --centrelines folder rewrote a good validation.csv with "no centrelines file" at
    every point, exit 0."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "run.jsonl").write_text("")
    assert main(["validate", "run", *extra]) == 2
    assert words in _one_line(capsys)
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["run.jsonl"]


def test_a_binary_file_given_as_the_calibration_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It was a UnicodeDecodeError traceback (the -c loader already said "not UTF-8 text")."""
    (tmp_path / "cal.yaml").write_bytes(b"\x89HDF\r\n\x1a\n\xff\xfe")
    assert main(["calibrate", "map", str(tmp_path / "cal.yaml"), "1", "2"]) == 2
    assert "cal.yaml" in (line := _one_line(capsys)) and "not a calibration file (not UTF-8 text" in line, line


def test_control_out_onto_a_file_is_refused_before_the_rig_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """It failed once every service was up: three ERROR lines, then "flagtrack control: error", exit 1."""
    (tmp_path / "afile").write_text("kept")
    rig = Path(__file__).resolve().parents[2] / "deploy" / "rig-control-sim.yaml"
    assert main(["control", "-c", str(rig), "--out", str(tmp_path / "afile")]) == 2
    assert "--out" in _one_line(capsys) and (tmp_path / "afile").read_text() == "kept"
    assert main(["control", "-c", str(rig), "--out", str(tmp_path / "afile" / "run1")]) == 2  # under a file
    line = _one_line(capsys)
    assert "--out" in line and f"{tmp_path / 'afile'} is a file" in line, line


def test_no_updates_at_all_is_not_blamed_on_the_geometry(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty.csv").write_text("t,x,y,p\n")
    argv = ["reconstruct", str(tmp_path / "empty.csv"), "-o", str(tmp_path / "e.h5"), "--root", "150", "240"]
    assert main([*argv, "--length", "300"]) == 0
    err = capsys.readouterr().err
    assert "warning: the recording holds no events" in err and "geometry" not in err, err


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["calibrate", "REC", "--board", "9x6", "--square-mm", "-20", "-o", "c.yaml"], "--square-mm: must be a positive"),
        (["calibrate", "REC", "--board", "9x6", "--square-mm", "20", "--max-seconds", "nan", "-o", "c.yaml"],
         "--max-seconds"),
        (["calibrate", "REC", "--board", "99999999999999x2", "--square-mm", "20", "-o", "c.yaml"], "--board: 2 to 100"),
        (["calibrate", "REC", "--board", "9x6", "--square-mm", "20", "--size", "-1", "5", "-o", "c.yaml"], "--size"),
        (["simulate", "OUT", "--duration", "-1"], "--duration: must be above 0"),
        (["simulate", "OUT", "--shot-noise", "inf"], "--shot-noise"),
        (["simulate", "OUT", "--width", "99999999"], "a sensor of 16 to 8192 px"),
        (["simulate", "OUT", "--checkerboard", "--blink-ms", "nan"], "--blink-ms: must be a positive number"),
        (["simulate", "OUT", "--checkerboard", "--periods", "0"], "--periods: 1 to 1000"),
        (["aim", "--replay", "REC", "--sensor", "99999999", "99999999", "--snapshot", "a.png", "-q"], "--sensor"),
        (["aim", "--replay", "REC", "--speed", "nan", "--snapshot", "a.png", "-q"], "--speed must be 0 or more"),
        (["events", "info", "."], "is a directory, not an event file"),
        (["calibrate", "map"], "map needs a calibration file and pixel positions"),
        (["calibrate", "map", "REC", "nan", "inf"], "map: pixel positions must be finite"),
        (["up", "--replay", ".", "--exit-at-eof"], "--replay: .: is a directory, not a recording"),
        (["up", "--replay", "REC", "--root", "nan", "2", "--length", "100", "--exit-at-eof"],
         "--root: must be two finite numbers"),
    ],
)  # fmt: skip
def test_numbers_and_folders_a_command_cannot_use_are_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    """Tracebacks (a cv2.error, a 358 GiB or 71 PiB allocation) or a 0-event recording with exit 0."""
    monkeypatch.chdir(tmp_path)
    events = np.zeros(5, EVENT_DTYPE)
    events["t"] = np.arange(5)
    write_events(tmp_path / "rec.raw", events, width=640, height=480)
    argv = [str(tmp_path / "rec.raw") if a == "REC" else str(tmp_path / "out") if a == "OUT" else a for a in argv]
    assert main(argv) == 2
    assert words in _one_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.raw"]


@pytest.mark.parametrize("action", [["info"], ["convert", "--no-progress"]])
def test_events_refuses_a_pixel_beyond_any_sensor_as_reconstruct_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], action: list[str]
) -> None:
    """A random file read as a headerless DAT: `events info` said 625 events with t_first > t_last,
    exit 0 (--strict too); `convert` wrote pixels like (8537, 8979)."""
    raw = np.zeros(10, dtype=[("t", "<u4"), ("w", "<u4")])
    raw["t"] = np.arange(10) * 100
    raw["w"] = 10_000 | (20 << 14)
    (tmp_path / "junk.dat").write_bytes(raw.tobytes())
    outputs = [str(tmp_path / "junk.csv")] if action[0] == "convert" else []
    assert main(["events", action[0], str(tmp_path / "junk.dat"), *outputs, *action[1:]]) == 2
    line = _one_line(capsys)
    assert "junk.dat, byte 0: an event at pixel (10000, 20): beyond any event sensor" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["junk.dat"]  # no part of an output left


def test_a_replay_that_is_no_recording_is_one_line_before_the_rig_starts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The camera service failed on it once every service was up: an ERROR line, then exit 1."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "junk.raw").write_bytes(np.random.default_rng(1).bytes(20_000))
    assert main(["up", "--replay", "junk.raw", "--root", "100", "100", "--length", "50", "--exit-at-eof"]) == 2
    line = _one_line(capsys)
    assert line == "flagtrack up: error: --replay: junk.raw, byte 0: not a RAW file: no '%' header (encoding unknown)"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["junk.raw"]


@pytest.mark.parametrize("name", ["empty.dat", "empty.raw", "empty.npy", "empty.csv"])
def test_a_zero_byte_recording_is_one_line_whatever_its_format(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    """A 0-byte .dat read as 0 events with exit 0 where a .raw was an error."""
    (tmp_path / name).write_bytes(b"")
    assert main(["events", "info", str(tmp_path / name)]) == 2
    assert f"{name}: empty file (0 bytes)" in _one_line(capsys)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["control", "--duration", "nan"], "argument --duration: must be a time in [0, 604800] s, got nan"),
        (["control", "--duration", "inf"], "argument --duration: must be a time"),
        (["control", "--shutdown-timeout", "nan"], "argument --shutdown-timeout: must be a time"),
        (["sweep", "--shutdown-timeout", "-1"], "argument --shutdown-timeout: must be a time"),
        (["up", "--shutdown-timeout", "0"], "argument --shutdown-timeout: must be above 0 s"),
    ],
)
def test_a_time_option_that_never_ends_or_is_negative_is_refused(
    capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    """``control --duration nan`` ran 0 steps and said "finished"; ``--shutdown-timeout nan`` aborted
    the process (rc 134) at its stop."""
    rig = Path(__file__).resolve().parents[2] / "deploy" / "rig-control-sim.yaml"
    with pytest.raises(SystemExit) as stopped:
        main([argv[0], "-c", str(rig), *argv[1:]])
    err = capsys.readouterr().err.strip().splitlines()
    assert stopped.value.code == 2 and err[-1].startswith(f"flagtrack {argv[0]}: error: {words}"), err
    assert err[0].startswith("usage:") and not any("Traceback" in line for line in err)


@pytest.mark.parametrize(
    ("section", "key", "words"),
    [
        ("recorder", "min_free_mb", "min_free_mb must be >= 0, got -5.0"),
        ("recorder", "drain_timeout_s", "drain_timeout_s must be positive"),
        ("supervisor", "recorder_timeout_s", "recorder_timeout_s must be positive, got (3.0, 0.2, 20.0, -5.0)"),
        ("supervisor", "startup_timeout_s", "must be positive, got (3.0, 0.2, -5.0, 10.0)"),
    ],
)
def test_config_check_refuses_negative_timeouts_and_free_space(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], section: str, key: str, words: str
) -> None:
    """They passed ``config check``; at run time a -5 s timeout failed every point at once."""
    import yaml

    rig = yaml.safe_load((Path(__file__).resolve().parents[2] / "deploy" / "rig-sensor-sim.yaml").read_text())
    rig.setdefault(section, {})[key] = -5
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    assert main(["config", "check", str(path)]) == 2
    line = _one_line(capsys)
    assert f"key '{section}'" in line and words in line, line


@pytest.mark.parametrize(
    ("option", "words"),
    [
        (["--t-stop", "0.5"], "--t-stop (tracker.t_stop_s) 0.5 s is before its first event"),
        (["--t-start", "3"], "--t-start (tracker.t_start_s) 3 s is after its last event"),
    ],  # fmt: skip
)
def test_a_time_window_outside_the_recording_says_where_its_events_are(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], option: list[str], words: str
) -> None:
    rows = "".join(f"{1_000_000 + 100 * i},{150 + i % 50},240,1\n" for i in range(2000))
    (tmp_path / "late.csv").write_text("t,x,y,p\n" + rows)
    argv = ["reconstruct", str(tmp_path / "late.csv"), "-o", str(tmp_path / "e.h5"), "--root", "150", "240"]
    assert main([*argv, "--length", "300", *option]) == 0
    err = capsys.readouterr().err
    assert words in err and "the recording's events run from 1 s to 1.1999 s" in err, err
