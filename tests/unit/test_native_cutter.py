"""NativeCutter: a camera's own EVT words cut into packets that decode alone, untouched, counted."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from flagtrack.drivers.formats import parse_raw_header, read_events, write_events
from flagtrack.drivers.formats.native import NativeCutter
from flagtrack.drivers.formats.packets import PacketParams, decode_packet
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events

RAW_FILES = [
    "expelliarmus_evt2_sample.raw",
    "expelliarmus_evt2_test_sparklers.raw",
    "expelliarmus_evt3_sample.raw",  # vectors, TIME_LOW stepping back
    "expelliarmus_evt3_test_pedestrians.raw",
]


def body(path: Path) -> bytes:
    data = path.read_bytes()
    return data[parse_raw_header(data[: 1 << 20])[1] :]


def cut(encoding: str, data: bytes, params: PacketParams, seed: int) -> list:
    """Push ``data`` in random pieces (odd sizes: words split across pushes) and flush."""
    cutter, rng, pos, packets = NativeCutter(encoding, params), np.random.default_rng(seed), 0, []
    while pos < len(data):
        step = int(rng.integers(1, 50_000))
        packets += cutter.push(data[pos : pos + step])
        pos += step
    return packets + cutter.flush()


def check(encoding: str, data: bytes, reference: np.ndarray, params: PacketParams) -> list:
    packets = cut(encoding, data, params, seed=len(data))
    assert b"".join(p.data[p.preamble_bytes :] for p in packets) == data  # the camera's bytes, untouched
    alone = [decode_packet(encoding, p.data, p.t_offset_us)[0] for p in packets]  # each decodes alone
    np.testing.assert_array_equal(np.concatenate(alone), reference)
    together = decode_packet(encoding, b"".join(p.data for p in packets), packets[0].t_offset_us)[0]
    np.testing.assert_array_equal(together, reference)  # as the tracker decodes a run, preambles and all
    assert [p.n_events for p in packets] == [len(e) for e in alone]  # counted from the words
    assert [p.n_on for p in packets] == [int(e["p"].sum()) for e in alone]
    horizons = [p.t_last_us for p in packets]
    assert horizons == sorted(horizons)
    return packets


@pytest.mark.shared_data
@pytest.mark.parametrize("name", RAW_FILES)
@pytest.mark.parametrize("params", [PacketParams(1000), PacketParams(100, 300)], ids=["1ms", "100us-300ev"])
def test_real_recordings_cut_decode_alone_and_join_to_the_camera_bytes(shared_real, name, params) -> None:
    encoding = "evt3" if "evt3" in name else "evt2"
    packets = check(encoding, body(shared_real / name), read_events(shared_real / name).events, params)
    assert len(packets) > 3
    if params.max_events < 1000:
        assert max(p.n_events for p in packets) <= params.max_events + 12  # one vector word at most beyond


@pytest.mark.parametrize("encoding", ["evt3", "evt2"])
def test_a_stream_across_time_loops_cuts_with_the_right_offsets(tmp_path, encoding) -> None:
    events = np.concatenate(list(line_events(WavyFlag(), 16_700_000, 16_900_000, 640, 480, QuickLineParams())))
    path = tmp_path / "wrap.raw"  # EVT 3.0's time base wraps at 16 777 216 us, inside this stream
    write_events(path, events, width=640, height=480, encoding=encoding)
    packets = check(encoding, body(path), events, PacketParams(1000))
    if encoding == "evt3":
        assert {p.t_offset_us for p in packets} == {0, 1 << 24}


def test_time_passing_without_events_closes_slots_and_moves_the_horizon() -> None:
    words = np.array([0x8000, 0x6010, 0x0005, 0x2007, 0x8001, 0x8002, 0x6003], dtype="<u2")  # TH, TL, Y, X, TH, TH, TL
    cutter = NativeCutter("evt3", PacketParams(1000))
    packets = cutter.push(words.tobytes())
    assert [p.n_events for p in packets] == [1, 0]  # each TIME_HIGH jumps 4 slots: one packet closes each time
    assert [p.t_last_us for p in packets] == [3999, 7999]  # complete up to the slot the new time opened
    assert packets[0].t_first_us == 0x10
    assert packets[1].data.startswith(np.array([0x8001], dtype="<u2").tobytes())  # the state words first


def test_unknown_encoding_is_refused() -> None:
    from flagtrack.daemon.errors import FormatError

    with pytest.raises(FormatError, match="evt21"):
        NativeCutter("evt21")
