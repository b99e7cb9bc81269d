"""`flagtrack geometry` on real files: JSON, the tracker section it writes (loaded by the tracker's
own loader, then tracked by `flagtrack reconstruct`), a calibration, and recordings with no flag."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from flagtrack.daemon.core.events import EVENT_DTYPE
from flagtrack.daemon.tracking.setup import load_tracking_config_file, tracking_setup
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag(length=220.0, root=(480.0, 120.0), direction_deg=150.0, amp_rad=0.8)
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


def flagtrack(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "flagtrack.daemon", *args], capture_output=True, text=True, timeout=300, cwd=cwd
    )


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """flag.raw (0.25 s of FLAG with 1 Hz a pixel of noise), noise.raw, empty.raw, cal.yaml."""
    out = tmp_path_factory.mktemp("geometry")
    params = QuickLineParams(events_per_px2=4.0, noise_rate_hz=640 * 480 * 1.0)
    events = np.concatenate(list(line_events(FLAG, 0, 250_000, 640, 480, params)))
    write_events(out / "flag.raw", events, width=640, height=480, encoding="evt3")
    rng = np.random.default_rng(0)
    noise = np.zeros(300_000, dtype=EVENT_DTYPE)
    noise["t"] = np.sort(rng.integers(0, 1_000_000, len(noise)))
    noise["x"], noise["y"], noise["p"] = rng.integers(0, 640, len(noise)), rng.integers(0, 480, len(noise)), 1
    write_events(out / "noise.raw", noise, width=640, height=480, encoding="evt3")
    write_events(out / "empty.raw", np.zeros(0, dtype=EVENT_DTYPE), width=640, height=480, encoding="evt3")
    (out / "cal.yaml").write_text(yaml.safe_dump(CALIBRATION))
    return out


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_json_then_the_tracker_section_tracks_the_flag(folder: Path) -> None:
    result = flagtrack("geometry", str(folder / "flag.raw"), "--json", "-o", str(folder / "tracker.yaml"))
    assert result.returncode == 0, result.stderr
    found = json.loads(result.stdout)
    assert {"root", "direction_deg", "length", "units", "warnings", "root_gap"} <= set(found)
    assert found["units"] == "px"
    assert math.dist(found["root"], FLAG.root) < 0.02 * FLAG.length
    assert abs((found["direction_deg"] - FLAG.direction_deg + 180) % 360 - 180) < 2.0
    assert abs(found["length"] / FLAG.length - 1) < 0.03
    # the file loads through the tracker's own loader, as `reconstruct -c` and the rig read it
    config = load_tracking_config_file(folder / "tracker.yaml")
    tracking_setup(config)
    assert config.root == tuple(found["root"]) and config.length == found["length"]
    assert config.direction_deg == found["direction_deg"]
    out = folder / "track.h5"
    rec = flagtrack("reconstruct", str(folder / "flag.raw"), "-o", str(out), "-c", str(folder / "tracker.yaml"))
    assert rec.returncode == 0, rec.stderr
    with h5py.File(out) as f:
        lost = f["lost"][()]
        t, x, y = f["t"][()], f["x"][()][:, -1], f["y"][()][:, -1]
    assert lost.mean() < 0.05
    tx, ty = FLAG.positions(t, np.array([FLAG.length]))
    tip_error = np.hypot(x - tx[:, 0], y - ty[:, 0])
    assert np.median(tip_error) < 0.05 * FLAG.length


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_plain_output_gives_the_reconstruct_options(folder: Path) -> None:
    result = flagtrack("geometry", str(folder / "flag.raw"))
    assert result.returncode == 0, result.stderr
    assert "root" in result.stdout and "direction" in result.stdout and "length" in result.stdout
    options = result.stdout.strip().splitlines()[-1].split()
    at = options.index("--root")
    assert math.dist((float(options[at + 1]), float(options[at + 2])), FLAG.root) < 0.02 * FLAG.length
    assert abs(float(options[options.index("--length") + 1]) / FLAG.length - 1) < 0.03
    assert "--direction" in options


@pytest.mark.slow
@pytest.mark.timeout(1200)
def test_with_a_calibration_the_figures_are_in_its_units(folder: Path) -> None:
    (folder / "sub").mkdir(exist_ok=True)
    result = flagtrack(
        "geometry", "flag.raw", "--calibration", "cal.yaml", "--json", "-o", "sub/tracker.yaml", cwd=folder
    )
    assert result.returncode == 0, result.stderr
    found = json.loads(result.stdout)
    assert found["units"] == "m"
    assert math.dist(found["root"], (FLAG.root[0] * M_PER_PX, FLAG.root[1] * M_PER_PX)) < 0.02 * FLAG.length * M_PER_PX
    assert abs(found["length"] / (FLAG.length * M_PER_PX) - 1) < 0.03
    written = yaml.safe_load((folder / "sub" / "tracker.yaml").read_text())["tracker"]
    assert written["calibration"] == "../cal.yaml"  # relative to the config's folder, as the loader reads it
    config = load_tracking_config_file(folder / "sub" / "tracker.yaml")
    assert tracking_setup(config).units == "m"


@pytest.mark.parametrize("name", ["noise.raw", "empty.raw"])
def test_a_recording_without_a_flag_is_one_line_and_exit_2(folder: Path, name: str) -> None:
    result = flagtrack("geometry", str(folder / name), "-o", str(folder / "none.yaml"))
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "no flag" in lines[0] and name in lines[0]
    assert result.stdout == "" and not (folder / "none.yaml").exists()


@pytest.mark.shared_data
@pytest.mark.parametrize(
    "name",
    [
        "tonic_sample.aedat4",
        "tonic_sample_ncars.dat",
        "aestream_davis.aedat4",
        "expelliarmus_dat_test_NCARS.dat",
        "expelliarmus_evt2_sample.raw",
        "expelliarmus_evt2_test_sparklers.raw",
        "expelliarmus_evt3_sample.raw",
        "expelliarmus_evt3_test_pedestrians.raw",
    ],
)
def test_real_recordings_of_other_scenes_are_no_flag(shared_real: Path, tmp_path: Path, name: str) -> None:
    """Every real sensor's recording of other scenes (the team's reference files; none has a flag):
    too few events, nothing that flaps, a line longer than the sensor's diagonal, a far end that
    barely moves, a length that changes from window to window, a root off the sensor."""
    result = flagtrack("geometry", str(shared_real / name), "--json", cwd=tmp_path)
    assert result.returncode == 2 and result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "no flag found" in lines[0] and name in lines[0], result.stderr


def test_a_missing_file_is_one_line_and_exit_2(folder: Path) -> None:
    result = flagtrack("geometry", str(folder / "absent.raw"))
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1 and "absent.raw" in result.stderr
