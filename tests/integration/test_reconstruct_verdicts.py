"""``flagtrack reconstruct`` says what it found (issue 30): the shares of found / lost / stale updates, a
warning naming the geometry when most found no flag, and one line with exit 2, before any work, for
paths and parameters it cannot use."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.drivers.formats import write_events
from flagtrack.drivers.formats.centreline import read_centrelines
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

FLAG = WavyFlag(root=(120.0, 250.0), length=180.0)
GEOMETRY = ["--length", "180", "--tau", "0.0003", "--no-progress"]


@pytest.fixture(scope="module")
def raw_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    params = QuickLineParams(events_per_px2=10, noise_rate_hz=1e5)
    events = np.concatenate(list(line_events(FLAG, 0, 80_000, 640, 480, params, seed=11)))
    path = tmp_path_factory.mktemp("rec") / "flag.raw"
    write_events(path, events, width=640, height=480, encoding="evt3")
    return path


def _run(capsys: pytest.CaptureFixture, *argv: str | Path) -> tuple[int, list[str]]:
    status = main(["reconstruct", *map(str, argv)])
    return status, capsys.readouterr().err.strip().splitlines()


def test_the_run_ends_with_the_shares_of_verdicts(raw_file: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out.h5"
    status, lines = _run(capsys, raw_file, "-o", out, "--root", "120", "250", *GEOMETRY)
    batch, _ = read_centrelines(out)
    assert status == 0 and lines[-1].startswith(f"{out}: ") and lines[-1].endswith(f"of {len(batch)} updates")
    found = 100 * np.mean((batch.lost == 0) & (batch.stale == 0))
    assert f"{found:.1f} % found" in lines[-1] and "lost" in lines[-1] and "stale" in lines[-1]
    assert found > 90 and not any("warning" in line for line in lines)


def test_a_recording_with_no_flag_where_the_geometry_says_is_said_out_loud(
    raw_file: Path, tmp_path: Path, capsys
) -> None:
    out = tmp_path / "out.h5"
    status, lines = _run(capsys, raw_file, "-o", out, "--root", "250", "120", *GEOMETRY)  # x and y swapped
    assert status == 0
    assert lines[-1].startswith("warning: most updates found no flag") and "--root, --length, --direction" in lines[-1]
    batch, _ = read_centrelines(out)
    assert np.mean(batch.lost | batch.stale) > 0.5


@pytest.mark.parametrize(
    ("length", "words"),
    [
        (
            "210",
            "warning: the chain's last 14 % had no events: from this root the flag looks about 180 px long, not 210",
        ),
        (
            "160",
            "warning: the flag's events reach 12 % past the chain's tip: from this root the flag looks about 180 px",
        ),
    ],
)
def test_a_chain_longer_or_shorter_than_the_flag_is_said_though_all_is_found(
    raw_file: Path, tmp_path: Path, capsys, length: str, words: str
) -> None:
    """Every update finds the flag (the chain's links near the tip lie on its events) while the chain
    runs on past the tip, or stops short of it; the events' reach along the chain says so."""
    out = tmp_path / "out.h5"
    status, lines = _run(capsys, raw_file, "-o", out, "--root", "120", "250", "--length", length, *GEOMETRY[2:])
    assert status == 0 and "100.0 % found" in lines[-2], lines
    assert lines[-1].startswith(words) and lines[-1].endswith("check --length (and the root)"), lines
    with h5py.File(out) as f:
        assert f.attrs["chain_reach"] == pytest.approx(180 / float(length), abs=0.01)


def test_the_chains_reach_goes_into_the_file(raw_file: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out.h5"
    status, _ = _run(capsys, raw_file, "-o", out, "--root", "120", "250", *GEOMETRY)
    with h5py.File(out) as f:
        assert status == 0 and f.attrs["chain_reach"] == pytest.approx(1.0, abs=0.01)


def test_a_start_before_a_unix_time_clock_tracks_from_the_first_event(raw_file: Path, tmp_path: Path, capsys) -> None:
    """``--t-start 0`` on a recording whose clock is Unix time (aedat4's): the windows before its first
    event hold nothing and are not made (it hung, making 6e12 of them); a time in that clock is taken."""
    from flagtrack.drivers.formats import read_events

    events = read_events(raw_file).events
    events["t"] += 1_605_537_493_000_000
    shifted = tmp_path / "unix.npy"
    write_events(shifted, events, width=640, height=480)
    outs = [tmp_path / f"{i}.h5" for i in range(3)]
    for out, start in zip(outs, ([], ["--t-start", "0"], ["--t-start", "1605537493.04"])):
        status, lines = _run(capsys, shifted, "-o", out, "--root", "120", "250", *start, *GEOMETRY)
        assert status == 0 and not any("warning" in line for line in lines), lines
    whole, from_zero, later = (read_centrelines(out)[0] for out in outs)
    assert abs(len(from_zero) - len(whole)) <= 1 and 120 <= len(later) <= len(whole) / 2 + 1
    assert later.t_s[0] == pytest.approx(1605537493.04, abs=1e-6)


@pytest.mark.parametrize(
    ("root", "words"),
    [(["1e9", "1e9"], "--root: (1e+09, 1e+09) is off the 640 x 480 sensor"), (["nan", "nan"], "--root: must be two")],
)
def test_a_root_off_the_sensor_is_refused_before_any_work(raw_file: Path, tmp_path: Path, capsys, root, words) -> None:
    out = tmp_path / "out.h5"
    status, lines = _run(capsys, raw_file, "-o", out, "--root", *root, *GEOMETRY)
    assert status == 2 and len(lines) == 1 and lines[0].startswith(f"flagtrack reconstruct: error: {words}")
    assert not out.exists()


def test_a_root_off_the_sensor_from_the_config_names_its_key(raw_file: Path, tmp_path: Path, capsys) -> None:
    config = tmp_path / "rig.yaml"
    config.write_text("tracker: {root: [-50, 240], length: 180}\n")
    status, lines = _run(capsys, raw_file, "-o", tmp_path / "o.h5", "-c", config, "--no-progress")
    assert status == 2 and len(lines) == 1 and f"file {config}, key 'tracker.root'" in lines[0]


@pytest.mark.parametrize("case", ["input is a directory", "output is a directory", "missing folder", "same file"])
def test_paths_it_cannot_use_are_refused_in_one_line(raw_file: Path, tmp_path: Path, capsys, case: str) -> None:
    events, out, words = raw_file, tmp_path / "out.h5", ""
    if case == "input is a directory":
        events, words = tmp_path, f"{tmp_path}: is a directory"
    elif case == "output is a directory":
        out, words = tmp_path, f"-o {tmp_path}: is a directory"
    elif case == "missing folder":
        out, words = tmp_path / "nope" / "out.h5", f"folder {tmp_path / 'nope'} does not exist"
    else:
        copy = tmp_path / "copy.raw"
        copy.write_bytes(raw_file.read_bytes())
        events, out, words = copy, copy, "is the event file itself"
    before = events.read_bytes() if events.is_file() else None
    status, lines = _run(capsys, events, "-o", out, "--root", "120", "250", *GEOMETRY)
    assert status == 2 and len(lines) == 1 and words in lines[0], lines
    assert before is None or events.read_bytes() == before  # nothing recorded is lost


def test_the_file_holds_stale_and_an_old_file_reads_as_0(raw_file: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out.h5"
    _run(capsys, raw_file, "-o", out, "--root", "120", "250", *GEOMETRY)
    with h5py.File(out, "a") as f:
        assert f["stale"].dtype == np.uint8 and f["stale"].shape == f["t"].shape
        del f["stale"]  # a file written before /stale
    old, _ = read_centrelines(out)
    assert old.stale.dtype == np.uint8 and not old.stale.any()
