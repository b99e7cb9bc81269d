"""Every real recording in ../shared/data/real decodes to exactly the camera maker's events.

REFERENCE.json (see SOURCES.md there) holds, per file, what the maker's own decoder gives:
count, first and last 3 events, on/off counts, ranges, and a SHA-256 over t (int64), x, y
(uint16) and p (uint8) in file order. The tests skip with a reason when ../shared is absent.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from flagtrack.daemon.cli import main
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import FormatWarning, make_decoder, open_events, read_events, write_events
from flagtrack.drivers.formats.raw_file import RawReader

pytestmark = pytest.mark.shared_data

FILES = [
    "expelliarmus_evt2_sample.raw",
    "expelliarmus_evt2_test_sparklers.raw",
    "expelliarmus_evt3_sample.raw",
    "expelliarmus_evt3_test_pedestrians.raw",
    "expelliarmus_dat_test_NCARS.dat",
    "tonic_sample_ncars.dat",
    "tonic_sample.aedat4",
    "aestream_davis.aedat4",
]
GEOMETRY = {  # SOURCES.md: from the camera (RAW headers have none), the AEDAT4 header, or unknown (DAT)
    "expelliarmus_evt2_sample.raw": (640, 480),
    "expelliarmus_evt2_test_sparklers.raw": (640, 480),
    "expelliarmus_evt3_sample.raw": (1280, 720),
    "expelliarmus_evt3_test_pedestrians.raw": (1280, 720),
    "expelliarmus_dat_test_NCARS.dat": (None, None),
    "tonic_sample_ncars.dat": (None, None),
    "tonic_sample.aedat4": (320, 240),
    "aestream_davis.aedat4": (346, 260),
}


def digest(events: np.ndarray) -> str:
    h = hashlib.sha256()
    for name, dtype in (("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")):
        h.update(np.ascontiguousarray(events[name], dtype=dtype).tobytes())
    return h.hexdigest()


def rows(events: np.ndarray) -> list[list[int]]:
    return [[int(e["t"]), int(e["x"]), int(e["y"]), int(e["p"])] for e in events]


@pytest.mark.parametrize("name", FILES)
def test_decodes_to_the_reference_events(name: str, shared_real: Path, reference_values: dict) -> None:
    ref = reference_values[name]
    rec = read_events(shared_real / name, strict=True)
    ev = rec.events
    assert len(ev) == ref["events"]
    assert rows(ev[:3]) == ref["first3_t_x_y_p"] and rows(ev[-3:]) == ref["last3_t_x_y_p"]
    assert digest(ev) == ref["sha256_t_i8_x_u2_y_u2_p_u1"]
    assert int(ev["p"].sum()) == ref["on"] and len(ev) - int(ev["p"].sum()) == ref["off"]
    assert [int(ev["x"].min()), int(ev["x"].max())] == ref["x_range"]
    assert [int(ev["y"].min()), int(ev["y"].max())] == ref["y_range"]
    assert bool(np.all(np.diff(ev["t"]) >= 0)) == ref["t_nondecreasing"]
    assert (rec.info.width, rec.info.height) == GEOMETRY[name]
    if "resolution" in ref:
        assert [rec.info.width, rec.info.height] == ref["resolution"]
    assert len(rec.triggers) == 0  # no external triggers in any of them (APS markers are not)


@pytest.mark.parametrize("name", FILES)
def test_small_chunks_give_the_same_events(name: str, shared_real: Path, reference_values: dict) -> None:
    with open_events(shared_real / name, strict=True, chunk_bytes=4096) as reader:
        chunks = list(reader)
    events = np.concatenate([c.events for c in chunks])
    assert len(chunks) > 3 and digest(events) == reference_values[name]["sha256_t_i8_x_u2_y_u2_p_u1"]


@pytest.mark.parametrize("name", [f for f in FILES if f.endswith(".raw")])
def test_live_decoder_on_random_packets(name: str, shared_real: Path, reference_values: dict) -> None:
    reader = RawReader(shared_real / name)
    data = (shared_real / name).read_bytes()[reader.body_offset :]
    decoder = make_decoder(reader.info.encoding, width=reader.info.width, height=reader.info.height)
    rng = np.random.default_rng(0)
    parts, pos = [], 0
    while pos < len(data):
        step = int(rng.integers(1, 20_000))
        parts.append(decoder.decode(data[pos : pos + step])[0])
        pos += step
    decoder.finish()
    assert digest(np.concatenate(parts)) == reference_values[name]["sha256_t_i8_x_u2_y_u2_p_u1"]


@pytest.mark.parametrize(
    ("name", "encoding"),
    [
        ("expelliarmus_evt3_sample.raw", "evt2"),
        ("expelliarmus_evt2_test_sparklers.raw", "evt3"),
        ("aestream_davis.aedat4", "evt3"),
    ],
)
def test_rewritten_recordings_read_back_identical(
    name: str, encoding: str, shared_real: Path, reference_values: dict, tmp_path: Path
) -> None:
    rec = read_events(shared_real / name)
    out = tmp_path / "re.raw"
    write_events(out, rec.events, width=rec.info.width, height=rec.info.height, encoding=encoding)
    assert digest(read_events(out, strict=True).events) == reference_values[name]["sha256_t_i8_x_u2_y_u2_p_u1"]


def test_info_command_prints_the_reference_figures(
    shared_real: Path, reference_values: dict, capsys: pytest.CaptureFixture
) -> None:
    name = "expelliarmus_evt3_sample.raw"
    assert main(["events", "info", str(shared_real / name), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    ref = reference_values[name]
    assert info == {
        "format": "raw",
        "encoding": "evt3",
        "width": 1280,
        "height": 720,
        "events": ref["events"],
        "on": ref["on"],
        "off": ref["off"],
        "t_first_us": ref["t_first_us"],
        "t_last_us": ref["t_last_us"],
    }


@pytest.mark.parametrize("name", ["expelliarmus_evt2_sample.raw", "aestream_davis.aedat4", "tonic_sample_ncars.dat"])
def test_truncated_copy_reports_offset_and_keeps_earlier_events(name: str, shared_real: Path, tmp_path: Path) -> None:
    data = (shared_real / name).read_bytes()
    cut = tmp_path / name
    cut.write_bytes(data[: len(data) // 2 + 1])
    with pytest.raises(FormatError) as err:
        read_events(cut, strict=True)
    assert err.value.path == str(cut) and err.value.offset is not None and 0 < err.value.offset <= len(data) // 2
    with pytest.warns(FormatWarning):
        partial = read_events(cut).events
    whole = read_events(shared_real / name).events
    assert 0 < len(partial) < len(whole)
    np.testing.assert_array_equal(partial, whole[: len(partial)])
