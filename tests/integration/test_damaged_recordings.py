"""A damaged recording through the commands: `reconstruct` and `batch reconstruct` keep what is readable
and say what they skipped (also in the centreline file); `--strict` refuses with one line."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.integration.test_up import TRACKER_ARGS, flagtrack


@pytest.fixture(scope="module")
def damaged(recording: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int]:
    """The 0.2 s recording with a reserved EVT 3.0 word in the middle; (file, offset of that word)."""
    data = bytearray(recording.read_bytes())
    body = data.index(b"% end\n") + 6
    at = body + (len(data) - body) // 4 * 2
    data[at : at + 2] = (0xC123).to_bytes(2, "little")
    path = tmp_path_factory.mktemp("damaged") / "damaged.raw"
    path.write_bytes(bytes(data))
    return path, at


def test_reconstruct_keeps_the_rest_and_says_what_it_skipped(damaged: tuple[Path, int], tmp_path: Path) -> None:
    path, at = damaged
    out = tmp_path / "c.h5"
    done = flagtrack("reconstruct", str(path), "-o", str(out), *TRACKER_ARGS, "--no-progress")
    assert done.returncode == 0, done.stderr
    assert f"{path}: damaged: skipped bytes {at}-" in done.stderr
    with h5py.File(out) as f:
        skipped = f.attrs["input_skipped_bytes"]
        assert skipped.shape == (1, 2) and skipped[0, 0] == at
        assert f.attrs["input_events_lost_at_most"] > 0
        t = f["t"][()]
    assert t[-1] > 0.19  # tracked to the end of the 0.2 s recording, not to the damage at ~0.1 s
    assert np.all(np.diff(t) > 0)

    refused = flagtrack("reconstruct", str(path), "-o", str(tmp_path / "s.h5"), *TRACKER_ARGS, "--strict")
    assert refused.returncode != 0
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}, byte {at}" in lines[0] and "reserved type 0xc" in lines[0]
    assert "Traceback" not in refused.stderr


def test_batch_strict_fails_the_damaged_input_only(damaged: tuple[Path, int], recording: Path, tmp_path: Path) -> None:
    path, at = damaged
    for strict, status in ((False, "done"), (True, "failed")):
        out = tmp_path / f"out-{strict}"
        args = ["batch", "reconstruct", str(path), str(recording), "-o", str(out), *TRACKER_ARGS, "-j", "1"]
        result = flagtrack(*args, "--json", "--no-progress", *(["--strict"] if strict else []))
        rows = {Path(r["input"]).name: r for r in json.loads(result.stdout)["rows"]}
        assert rows["flag.raw"]["status"] == "done", rows
        assert rows["damaged.raw"]["status"] == status, rows
        if strict:
            assert f"byte {at}" in rows["damaged.raw"]["error"]
        else:
            assert f"bytes {at}-" in result.stderr  # the warning is reported with its input


def test_a_file_damaged_in_many_places_gives_ten_warnings_and_a_count(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A 100 kB stretch of noise gave 160 warning lines from `events info`, and `reconstruct` one line
    listing 155 byte ranges; -v still shows each."""
    from flagtrack.daemon.cli import main

    data = bytearray(recording.read_bytes())
    body = data.index(b"% end\n") + 6
    for at in range(body + 2048, len(data) - 2, 2048):  # a reserved word every 2 kB
        data[at : at + 2] = (0xC123).to_bytes(2, "little")
    path = tmp_path / "damaged.raw"
    path.write_bytes(bytes(data))
    assert main(["-v", "events", "info", str(path)]) == 0
    every = len([line for line in capsys.readouterr().err.splitlines() if "warning: " in line])
    assert every > 15  # (a stretch skipped runs to the next time base: some words fall in one)
    assert main(["events", "info", str(path)]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len([line for line in err if "warning: " in line]) == 10
    hidden = f"flagtrack events: {every - 10} more warnings not shown (flagtrack -v events ... shows each)"
    assert err[-1] == hidden, err[-1]
    done = flagtrack("reconstruct", str(path), "-o", str(tmp_path / "c.h5"), "--root", "100", "240", "--length", "200")
    assert done.returncode == 0, done.stderr
    damaged = [line for line in done.stderr.splitlines() if ": damaged: skipped bytes" in line]
    assert len(damaged) == 1 and f"and {every - 5} more stretches up to byte" in damaged[0], damaged
