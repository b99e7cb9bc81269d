"""``flagtrack events info|convert`` and ``flagtrack bench decode`` end to end (small files)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.core.events import make_events
from flagtrack.drivers.formats import read_events, write_events


@pytest.fixture
def recording(tmp_path: Path) -> tuple[Path, np.ndarray]:
    rng = np.random.default_rng(5)
    n = 5000
    events = make_events(
        np.cumsum(rng.integers(0, 3, n)) + 7, rng.integers(0, 320, n), rng.integers(0, 240, n), rng.integers(0, 2, n)
    )
    path = tmp_path / "rec.raw"
    write_events(path, events, width=320, height=240, encoding="evt2")
    return path, events


def test_info_json_has_exactly_the_documented_keys(
    recording: tuple[Path, np.ndarray], capsys: pytest.CaptureFixture
) -> None:
    path, events = recording
    assert main(["events", "info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    on = int(events["p"].sum())
    assert info == {
        "format": "raw",
        "encoding": "evt2",
        "width": 320,
        "height": 240,
        "events": len(events),
        "on": on,
        "off": len(events) - on,
        "t_first_us": int(events["t"][0]),
        "t_last_us": int(events["t"][-1]),
    }


def test_convert_through_every_format_and_back(recording: tuple[Path, np.ndarray], tmp_path: Path) -> None:
    path, events = recording
    chain = [path, tmp_path / "a.csv", tmp_path / "b.npy", tmp_path / "c.dat", tmp_path / "d.raw"]
    for source, target in zip(chain[:-1], chain[1:]):
        extra = ["--width", "320", "--height", "240"] if source.suffix == ".npy" else []
        assert main(["events", "convert", str(source), str(target), "--no-progress", *extra]) == 0
    rec = read_events(chain[-1], strict=True)
    np.testing.assert_array_equal(rec.events, events)
    assert (rec.info.encoding, rec.info.width, rec.info.height) == ("evt3", 320, 240)
    assert main(["events", "convert", str(path), str(tmp_path / "e.raw"), "--encoding", "evt3", "--no-progress"]) == 0
    np.testing.assert_array_equal(read_events(tmp_path / "e.raw").events, events)


def test_errors_are_one_line_naming_the_file(
    recording: tuple[Path, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    path, _ = recording
    cut = tmp_path / "cut.raw"
    cut.write_bytes(path.read_bytes()[:-1])
    assert main(["events", "info", str(cut), "--strict"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(cut) in err and "byte" in err
    assert main(["events", "info", str(cut), "--json"]) == 0  # not strict: warns, keeps the events before
    captured = capsys.readouterr()
    assert "warning" in captured.err and str(cut) in captured.err
    assert json.loads(captured.out)["events"] == 4999
    npy = tmp_path / "x.npy"
    write_events(npy, read_events(path).events, width=None, height=None)
    assert main(["events", "convert", str(npy), str(tmp_path / "x.raw"), "--no-progress"]) == 2
    assert "--width" in capsys.readouterr().err


def test_bench_decode_runs_and_checks_exactness(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    pytest.importorskip("faery")
    assert main(["bench", "decode", "--events", "20000", "--repeat", "1", "--cache", str(tmp_path), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["encoding"] for r in rows] == ["evt2", "evt3"]
    for row in rows:
        assert row["events"] == 20000 and row["flagtrack_exact"]
        assert row["flagtrack_mev_s"] > 0 and row["reference"] in ("evt3", "faery")
