"""The packetizer: self-contained packets that partition the stream, cut by time slot and size."""

from __future__ import annotations

import numpy as np
import pytest

from flagtrack.daemon.core.events import TRIGGER_DTYPE, make_events
from flagtrack.daemon.errors import FormatError
from flagtrack.daemon.schema import EventPacket
from flagtrack.daemon.services.sequence import packet_problem
from flagtrack.drivers.formats.codec import LOOP_US, Encoder
from flagtrack.drivers.formats.packets import Packetizer, PacketParams, decode_packet, slot_table


def stream(n: int = 40_000, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Events over ~20 ms with repeated times, small steps back and a time-loop crossing; triggers."""
    rng = np.random.default_rng(seed)
    t = 16_770_000 + np.sort(rng.integers(0, 20_000, n))
    t[7::131] -= 2  # small steps back, as sensors make
    events = make_events(t, rng.integers(0, 640, n), rng.integers(0, 480, n), rng.integers(0, 2, n))
    triggers = np.zeros(60, dtype=TRIGGER_DTYPE)
    triggers["t"] = np.sort(rng.integers(16_770_000, 16_790_000, 60))
    triggers["channel"] = rng.integers(0, 3, 60)
    triggers["edge"] = rng.integers(0, 2, 60)
    return events, triggers


@pytest.mark.parametrize("encoding", ["evt3", "evt2"])
@pytest.mark.parametrize("params", [PacketParams(), PacketParams(packet_us=250, max_events=700)])
def test_packets_partition_the_stream_and_decode_alone(encoding: str, params: PacketParams) -> None:
    events, triggers = stream()
    packetizer = Packetizer(encoding, 640, 480, params)
    packets = []
    cuts = [0, 1, 5_000, 5_001, 17_000, 33_333, len(events)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        late = triggers["t"] >= (events["t"][a] if a else 0)
        early = triggers["t"] < (events["t"][b] if b < len(events) else 1 << 60)
        packets += packetizer.push(events[a:b], triggers[late & early], t_until_us=int(events["t"][b - 1]))
    packets += packetizer.flush()

    got_events, got_triggers = [], []
    running_max = -1
    for packet in packets:
        ev, tr = decode_packet(encoding, packet.data, packet.t_offset_us)
        assert (len(ev), len(tr), packet.n_on) == (packet.n_events, packet.n_triggers, int(np.count_nonzero(ev["p"])))
        loop = LOOP_US[encoding]
        times = np.concatenate([ev["t"], tr["t"]])
        if len(times):
            assert packet.t_offset_us == times.min() // loop * loop
            assert times.max() <= packet.t_last_us  # the horizon covers the packet
            fresh = Encoder(encoding, t_offset_us=packet.t_offset_us, width=640, height=480)
            assert fresh.encode(ev, tr) == packet.data  # what a fresh encoder makes of it
        assert packet.n_events <= params.max_events
        if len(ev):
            maxima = np.maximum.accumulate(np.concatenate([[running_max], ev["t"]]))[1:]
            if packet.n_events < params.max_events:  # whole slots: one slot of the running maximum
                assert len(np.unique(maxima // params.packet_us)) == 1
            running_max = int(maxima[-1])
        got_events.append(ev)
        got_triggers.append(tr)
    np.testing.assert_array_equal(np.concatenate(got_events), events)
    np.testing.assert_array_equal(np.sort(np.concatenate(got_triggers)["t"]), triggers["t"])
    assert all(a.t_last_us <= b.t_last_us for a, b in zip(packets, packets[1:]) if b.n_events < params.max_events)


def test_an_event_outside_the_sensor_is_named() -> None:
    events = make_events([1_000, 1_010, 1_020], [5, 700, 6], [5, 5, 5], [1, 1, 1])
    packetizer = Packetizer("evt3", 640, 480)
    with pytest.raises(FormatError, match=r"event 1 .*'x': 700"):
        packetizer.push(events, None, t_until_us=3_000)


def test_packets_that_need_more_room_than_usual_are_still_encoded() -> None:
    """Sensor jitter across a time-base step (the time high word repeats for every event) and a
    trigger many time loops before an event need more words than the usual bound."""
    n = 200
    jitter = make_events(
        np.where(np.arange(n) % 2 == 0, 4096, 4095), np.arange(n) % 640, np.arange(n) % 480, np.ones(n)
    )
    packets = Packetizer("evt3", 640, 480).push(jitter, None, t_until_us=5_000)
    assert [p.n_events for p in packets] == [n]
    np.testing.assert_array_equal(decode_packet("evt3", packets[0].data, packets[0].t_offset_us)[0], jitter)

    trigger = np.zeros(1, dtype=TRIGGER_DTYPE)  # at t = 0, then an event 600 s (36 EVT 3.0 loops) later
    late = make_events([600_000_000], [1], [1], [1])
    after = make_events([600_002_500], [2], [2], [0])
    packetizer = Packetizer("evt3", 640, 480)
    packets = packetizer.push(late, trigger, t_until_us=600_001_000) + packetizer.push(after, None, 600_003_000)
    assert [(p.n_events, p.n_triggers) for p in packets] == [(1, 1), (1, 0)]
    events, triggers = decode_packet("evt3", packets[0].data, packets[0].t_offset_us)
    np.testing.assert_array_equal(events, late)
    np.testing.assert_array_equal(triggers, trigger)
    np.testing.assert_array_equal(decode_packet("evt3", packets[1].data, packets[1].t_offset_us)[0], after)


def test_a_packet_starting_with_a_trigger_of_the_loop_before_passes_the_bus_check() -> None:
    """A held trigger in one time loop and the packet's events in the next: the packet's first time
    is the trigger's, the one its offset was taken from, so the tracker and the recorder place it
    (the demo once lost such a packet at 67 s: offset 3 loops, first event in the 4th)."""
    loop_us = 1 << 24
    trigger = np.zeros(1, dtype=TRIGGER_DTYPE)
    trigger["t"] = 4 * loop_us - 700_000
    events = make_events([4 * loop_us + 50_000, 4 * loop_us + 50_500], [5, 6], [5, 6], [1, 0])
    packetizer = Packetizer("evt3", 640, 480)
    packets = packetizer.push(events, trigger, t_until_us=4 * loop_us + 51_000)
    assert packets[0].n_triggers == 1
    assert packets[0].t_first_us == trigger["t"][0]
    for packet in packets:
        message = EventPacket(
            camera_id="cam0",
            seq=0,
            t_first_us=packet.t_first_us,
            t_last_us=packet.t_last_us,
            n_events=packet.n_events,
            width=640,
            height=480,
            encoding="evt3",
            sent_ns=0,
            data=packet.data,
            t_offset_us=packet.t_offset_us,
            n_triggers=packet.n_triggers,
        )
        assert packet_problem(message) is None


def test_an_encoding_without_encoder_is_refused_up_front() -> None:
    with pytest.raises(FormatError, match="cannot encode 'evt21'"):
        Packetizer("evt21", 640, 480)


@pytest.mark.parametrize("seed", range(6))
def test_slot_table_matches_the_running_maximum_rule(seed: int) -> None:
    """Runs of one slot of the running maximum, on an event field as it is (strided), with steps back,
    negative times, gaps of several slots and a maximum carried in from before."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000))
    t = np.cumsum(rng.integers(-40, 60, n)) + int(rng.integers(-5000, 5000))
    t[rng.integers(0, n, 5)] += rng.integers(0, 4000, 5)  # jumps over several slots
    events = make_events(t, np.zeros(n), np.zeros(n), np.zeros(n))
    slot_us = int(rng.choice([1, 7, 250, 1000]))
    before = int(t[0]) + int(rng.integers(-300, 300))
    starts, slots, maxima = slot_table(events["t"], before, slot_us)

    running = np.maximum.accumulate(np.concatenate([[before], t]))[1:]
    slot_of = running // slot_us
    expected_starts = np.flatnonzero(np.concatenate([[True], slot_of[1:] != slot_of[:-1]]))
    np.testing.assert_array_equal(starts, np.append(expected_starts, n))
    np.testing.assert_array_equal(slots, slot_of[expected_starts])
    np.testing.assert_array_equal(maxima, running[np.append(expected_starts[1:], n) - 1])
