"""PacketSequence: a packet's place in its stream from its number and stream id."""

from __future__ import annotations

import pytest

from flagtrack.daemon.services.sequence import REORDER_WINDOW, Arrival, PacketSequence

N, G, L, S = Arrival.NEXT, Arrival.GAP, Arrival.LATE, Arrival.NEW_STREAM


@pytest.mark.parametrize(
    ("packets", "want"),
    [
        ([(0, 5), (1, 5), (2, 5)], [N, N, N]),
        ([(0, 5), (1, 5), (4, 5)], [N, N, (G, 2)]),
        ([(0, 5), (1, 5), (2, 5), (1, 5), (3, 5)], [N, N, N, L, N]),  # a duplicate
        ([(0, 5), (2, 5), (1, 5), (3, 5)], [N, (G, 1), L, N]),  # a swapped pair: the late one is dropped
        ([(0, 5), (500, 5), (3, 5)], [N, (G, 499), L]),  # with ids, far behind is still late
        ([(0, 5), (1, 5), (40, 6)], [N, N, S]),  # another id: a restarted camera, whatever its number
        ([(9, 5), (0, 0)], [N, S]),  # an older peer after a newer one
        # older peers (id 0): back to 0, or further back than the window, is a new stream
        ([(0, 0), (1, 0), (2, 0), (1, 0)], [N, N, N, L]),
        ([(0, 0), (1, 0), (2, 0), (0, 0)], [N, N, N, S]),
        ([(0, 0), (REORDER_WINDOW + 10, 0), (5, 0)], [N, (G, REORDER_WINDOW + 9), S]),
        ([(0, 0), (REORDER_WINDOW + 10, 0), (11, 0)], [N, (G, REORDER_WINDOW + 9), L]),
    ],
)
def test_arrivals(packets: list[tuple[int, int]], want: list) -> None:
    seq = PacketSequence()
    got = [seq.arrive(number, stream_id) for number, stream_id in packets]
    assert got == [w if isinstance(w, tuple) else (w, 0) for w in want]


def test_a_late_packet_changes_nothing_and_classify_follows_nothing() -> None:
    seq = PacketSequence()
    seq.arrive(0, 1)
    seq.arrive(1, 1)
    assert seq.arrive(0, 1) == (L, 0) and seq.next_seq == 2
    assert seq.classify(7, 1) == (G, 5) and seq.next_seq == 2
    seq.restart()
    assert seq.arrive(3, 9) == (N, 0) and (seq.stream_id, seq.next_seq) == (9, 4)


def _packet(t_first_us: int, t_offset_us: int, n_events: int = 10, encoding: str = "evt3"):
    from flagtrack.daemon.schema import EventPacket

    return EventPacket("cam0", 7, t_first_us, t_first_us + 999, n_events, 640, 480, encoding, 0, t_offset_us)


@pytest.mark.parametrize(
    ("t_first_us", "t_offset_us", "n_events", "words"),
    [
        (5_000_000, 0, 10, None),
        (20_000_000, 1 << 24, 10, None),  # the second EVT 3.0 loop
        (20_000_000, 1000 << 24, 10, "does not hold its first event"),  # a thousand loops off
        (5_000_000, 1 << 24, 10, "does not hold its first event"),  # after its first event
        (5_000_000, 12345, 10, "not a whole number"),
        (40_000_000, 0, 0, None),  # an empty end of stream: nothing to place
    ],
)
def test_packet_problem(t_first_us: int, t_offset_us: int, n_events: int, words: str | None) -> None:
    from flagtrack.daemon.services.sequence import packet_problem

    problem = packet_problem(_packet(t_first_us, t_offset_us, n_events))
    assert problem is None if words is None else words in problem
