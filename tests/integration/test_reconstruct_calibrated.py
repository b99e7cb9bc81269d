"""`reconstruct --calibration` and `up --replay --calibration`: events mapped to metres before tracking."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.quickline import WavyFlag, line_events

M_PER_PX = 0.0005
CALIBRATION = {
    "format": "flagtrack-calibration",
    "version": 1,
    "units": "m",
    "image_size": [640, 480],
    "degree": 1,
    "forward": {
        "degree": 1,
        "centre": [0.0, 0.0],
        "scale": 1.0,
        "exponents": [[0, 0], [1, 0], [0, 1]],
        "x": [0.0, M_PER_PX, 0.0],
        "y": [0.0, 0.0, M_PER_PX],
    },
    "inverse": {
        "degree": 1,
        "centre": [0.0, 0.0],
        "scale": 1.0,
        "exponents": [[0, 0], [1, 0], [0, 1]],
        "x": [0.0, 1 / M_PER_PX, 0.0],
        "y": [0.0, 0.0, 1 / M_PER_PX],
    },
}


def flagtrack(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "flagtrack.daemon", *args], capture_output=True, text=True, timeout=120
    )


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("cal")
    events = np.concatenate(list(line_events(WavyFlag(length=200.0, root=(100.0, 240.0)), 0, 100_000, 640, 480)))
    write_events(folder / "flag.raw", events, width=640, height=480, encoding="evt3")
    (folder / "cal.yaml").write_text(yaml.safe_dump(CALIBRATION))
    return folder / "flag.raw"


def test_calibrated_reconstruction_is_the_pixel_one_in_metres(recording: Path, tmp_path: Path) -> None:
    px, m = tmp_path / "px.h5", tmp_path / "m.h5"
    assert (
        flagtrack("reconstruct", str(recording), "-o", str(px), "--root", "100", "240", "--length", "200").returncode
        == 0
    )
    result = flagtrack(
        "reconstruct",
        str(recording),
        "-o",
        str(m),
        "--calibration",
        str(recording.parent / "cal.yaml"),
        "--root",
        str(100 * M_PER_PX),
        str(240 * M_PER_PX),
        "--length",
        str(200 * M_PER_PX),
    )
    assert result.returncode == 0, result.stderr
    with h5py.File(px) as a, h5py.File(m) as b:
        assert a.attrs["units"] == "px" and b.attrs["units"] == "m" and b.attrs["calibration_degree"] == 1
        assert "flagtrack-calibration" in b.attrs["calibration_yaml"]
        np.testing.assert_allclose(b["x"][()], a["x"][()] * M_PER_PX, atol=2e-3 * 200 * M_PER_PX)
        np.testing.assert_allclose(b["y"][()], a["y"][()] * M_PER_PX, atol=2e-3 * 200 * M_PER_PX)


def test_relative_calibration_path_in_a_config_is_taken_from_the_config_folder(recording: Path, tmp_path: Path) -> None:
    config = recording.parent / "track.yaml"
    config.write_text(yaml.safe_dump({"tracker": {"calibration": "cal.yaml", "root": [0.05, 0.12], "length": 0.1}}))
    out = tmp_path / "m.h5"
    result = subprocess.run(
        [sys.executable, "-m", "flagtrack.daemon", "reconstruct", str(recording), "-o", str(out), "-c", str(config)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    with h5py.File(out) as f:
        assert f.attrs["units"] == "m"


def test_a_broken_calibration_file_is_one_clear_line(recording: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("format: something-else\n")
    result = flagtrack(
        "reconstruct",
        str(recording),
        "-o",
        str(tmp_path / "x.h5"),
        "--calibration",
        str(bad),
        "--root",
        "0",
        "0",
        "--length",
        "0.1",
    )
    assert result.returncode == 2 and str(bad) in result.stderr and "not a calibration file" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_every_centreline_file_says_how_it_was_made(recording: Path, tmp_path: Path) -> None:
    """The recorder's centreline file (one per sweep point), `up --centrelines` and `reconstruct` carry
    the same processing attributes, calibration included, and the same centrelines."""
    rig = tmp_path / "rig.yaml"
    rig.write_text(
        yaml.safe_dump(
            {
                "camera": {"adapter": "replay", "replay": {"path": str(recording), "speed": 0.0}},
                "tracker": {
                    "calibration": str(recording.parent / "cal.yaml"),
                    "root": [0.05, 0.12],
                    "length": 0.1,
                    "tau_s": 0.0003,
                },
                "recorder": {"directory": str(tmp_path / "rec"), "path": "point1", "centrelines": True},
                "services": ["camera", "tracker", "recorder"],
            }
        )
    )
    up = flagtrack("up", "-c", str(rig), "--exit-at-eof", "--centrelines", str(tmp_path / "up.h5"))
    assert up.returncode == 0, up.stderr
    rec = flagtrack("reconstruct", str(recording), "-c", str(rig), "-o", str(tmp_path / "offline.h5"))
    assert rec.returncode == 0, rec.stderr
    # what differs by path: the input, its damage (offline) and the gaps of the stream (live)
    provenance = {"input_file", "input_format", "events_in", "events_kept", "source"}
    provenance |= {"input_skipped_bytes", "input_events_lost_at_most", "gaps_t_s"}
    provenance |= {"chain_reach"}  # (offline: what the events said of the chain's length, not how it was made)
    files = [tmp_path / "offline.h5", tmp_path / "rec" / "point1_centrelines.h5", tmp_path / "up.h5"]
    with h5py.File(files[0]) as offline:
        expected = {k: v for k, v in offline.attrs.items() if k not in provenance}
        t_offline = offline["t"][()]
    assert expected["units"] == "m" and "calibration_yaml" in expected and "denoise_max_neighbours" in expected
    for path in files[1:]:
        with h5py.File(path) as f:
            got = {k: v for k, v in f.attrs.items() if k not in provenance}
            assert sorted(got) == sorted(expected), path
            for name, value in expected.items():
                assert np.array_equal(np.asarray(got[name]), np.asarray(value)), (path, name)
            np.testing.assert_allclose(f["t"][()], t_offline, rtol=0, atol=1e-9)


@pytest.mark.parametrize("how", ["option", "config", "geometry", "config check"])
def test_a_calibration_made_on_another_sensor_is_refused(recording: Path, tmp_path: Path, how: str) -> None:
    """A 1280 x 720 calibration on the 640 x 480 recording: one line naming it and both sizes, exit 2
    (before, its pixels were mapped as they came, and the tracker tracked in the wrong place)."""
    hd = tmp_path / "hd.yaml"
    hd.write_text(yaml.safe_dump({**CALIBRATION, "image_size": [1280, 720]}))
    tracker = {"root": [0.05, 0.12], "length": 0.1, "direction_deg": 0.0, "calibration": str(hd)}
    config = tmp_path / "rig.yaml"
    config.write_text(yaml.safe_dump({"tracker": tracker}))
    out = str(tmp_path / "out.h5")
    argv = {
        "option": ["reconstruct", str(recording), "-o", out, "--calibration", str(hd), "--root", "0.05", "0.12",
                   "--length", "0.1", "--direction", "0"],
        "config": ["reconstruct", str(recording), "-o", out, "-c", str(config)],
        "geometry": ["geometry", str(recording), "--calibration", str(hd)],
        "config check": ["config", "check", str(config)],
    }[how]  # fmt: skip
    if how == "config check":
        rig = {"camera": {"adapter": "replay", "replay": {"path": str(recording)}}, "tracker": tracker}
        config.write_text(yaml.safe_dump({**rig, "services": ["camera", "tracker"]}))
    done = flagtrack(*argv)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert "hd.yaml: made on a 1280 x 720 sensor, not the 640 x 480 sensor of" in lines[0]
    assert ("--calibration" if how in ("option", "geometry") else "'tracker.calibration'") in lines[0]
    assert not Path(out).exists()
    hd.write_text(yaml.safe_dump(CALIBRATION))  # the same, made on this sensor: the refusal is the size alone
    again = flagtrack(*argv)
    assert "made on" not in again.stderr
    assert again.returncode == 0 or (how == "geometry" and "no flag found" in again.stderr)  # (0.1 s: no period)
