"""Joining consecutive packets at a low event rate: the same stream, fewer and longer packets."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.drivers.formats import write_events
from flagtrack.drivers.formats.native import NativeCutter
from flagtrack.drivers.formats.packets import Packet, Packetizer, PacketJoiner, PacketParams, decode_packet
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events


def wavy(t0: int, t1: int) -> np.ndarray:
    return np.concatenate(list(line_events(WavyFlag(), t0, t1, 640, 480, QuickLineParams())))


def join(packets: list[Packet], joiner: PacketJoiner, per_push: int = 3) -> list[tuple[Packet, int]]:
    """Push ``packets`` a few at a time, each batch arriving at its index (ns), then flush."""
    out = []
    for i in range(0, len(packets), per_push):
        out += joiner.push(packets[i : i + per_push], arrival_ns=i)
    return out + joiner.flush()


def check_joined(encoding: str, cut: list[Packet], joined: list[tuple[Packet, int]], max_us: int) -> None:
    assert sum(p.n_events for p, _ in joined) == sum(p.n_events for p in cut)
    for packet, _ in joined:  # each joined packet decodes alone to its parts' events
        events = decode_packet(encoding, packet.data, packet.t_offset_us)[0]
        assert len(events) == packet.n_events and int(events["p"].sum()) == packet.n_on
        assert packet.t_last_us - packet.t_first_us < max_us
    alone = np.concatenate([decode_packet(encoding, p.data, p.t_offset_us)[0] for p in cut])
    together = np.concatenate([decode_packet(encoding, p.data, p.t_offset_us)[0] for p, _ in joined])
    np.testing.assert_array_equal(together, alone)
    horizons = [p.t_last_us for p, _ in joined]
    assert horizons == sorted(horizons) and horizons[-1] == cut[-1].t_last_us


@pytest.mark.parametrize("encoding", ["evt3", "evt2"])
def test_native_packets_join_to_the_camera_bytes_and_not_across_a_time_loop(tmp_path, encoding) -> None:
    events = wavy(16_700_000, 16_900_000)  # EVT 3.0's time base wraps at 16 777 216 us, inside this stream
    path = tmp_path / "wrap.raw"
    write_events(path, events, width=640, height=480, encoding=encoding)
    data = path.read_bytes()
    body = data[data.index(b"\n% end\n") + len(b"\n% end\n") :]
    cutter = NativeCutter(encoding, PacketParams(1000))
    cut = cutter.push(body) + cutter.flush()
    joined = join(cut, PacketJoiner(min_events=4000, max_us=4000))
    assert len(joined) < len(cut) / 2  # this flag's ~1 000 events per ms: about 4 packets in one
    check_joined(encoding, cut, joined, 4000)
    assert b"".join(p.data[p.preamble_bytes :] for p, _ in joined) == body  # still the camera's bytes
    for packet, _ in joined:  # never two time loops in one packet (it has one t_offset_us)
        parts = [c for c in cut if packet.t_first_us <= c.t_first_us <= packet.t_last_us]
        assert {c.t_offset_us for c in parts} == {packet.t_offset_us}


def test_packetizer_packets_join_and_the_arrival_is_the_first_parts() -> None:
    events = wavy(0, 100_000)
    packetizer = Packetizer("evt3", 640, 480, PacketParams(1000))
    cut = packetizer.push(events, t_until_us=100_000) + packetizer.flush()
    joined = join(cut, PacketJoiner(min_events=2500, max_us=4000), per_push=1)
    check_joined("evt3", cut, joined, 4000)
    firsts = {p.t_first_us: i for i, p in enumerate(cut)}
    assert all(arrival == firsts[p.t_first_us] for p, arrival in joined)  # its events waited from then on
    assert all(p.n_events < 2500 + max(c.n_events for c in cut) for p, _ in joined)


def test_zero_min_events_leaves_the_packets_as_cut() -> None:
    events = wavy(0, 20_000)
    packetizer = Packetizer("evt2", 640, 480, PacketParams(1000))
    cut = packetizer.push(events, t_until_us=20_000) + packetizer.flush()
    assert [p for p, _ in join(cut, PacketJoiner(min_events=0, max_us=4000))] == cut
