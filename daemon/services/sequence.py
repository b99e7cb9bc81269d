"""Camera packets in their stream (tracker, recorder): whether a packet's times can be placed at all
(:func:`packet_problem`), and where it falls, from its sequence number and stream id.

A camera service numbers its packets from 0 and stamps them with a ``stream_id`` drawn when it
starts (``EventPacket.stream_id``), so a restarted camera is a new stream whatever its numbers. A
packet of the same stream whose number is behind the next one expected is a duplicate or came late
(Zenoh can deliver a sample twice when routers overlap): it is counted and dropped, not taken for a
restart. Packets of peers that send no id (``stream_id`` 0, older flagtrack) fall back on the
numbers: back to 0, or more than ``REORDER_WINDOW`` behind, is a new stream.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from flagtrack.daemon.schema import EventPacket
from flagtrack.drivers.formats.codec import LOOP_US
from flagtrack.drivers.formats.packets import MAX_OFFSET_US

_SLACK_US = 10_000  # a packet's first event may follow its earliest by a sensor's step back
MAX_JUMP_US = 3_600_000_000
"""A packet's times may run at most an hour past the stream's horizon so far (and past its own first
event): the tracker walks its windows through the time between (0.5 s of work per hour of camera
time, a day's jump 19 s, decades never ends), so a packet beyond cannot be placed."""


def packet_problem(packet: EventPacket, horizon_us: int | None = None) -> str | None:
    """Why a packet's events cannot be placed in time (its encoding, time offset or a jump ahead), or None. O(1).

    The time offset is the start of the encoding's time loop of the packet's earliest event, so
    its first event lies within a loop after it: a packet claiming another offset (a whole number of
    loops off, or not a whole number at all) would decode to times seconds or hours away. A packet
    without events or triggers (a horizon carried forward, an end of stream) has nothing to place;
    but no packet's horizon (``t_last_us``) may run more than :data:`MAX_JUMP_US` past its first
    event or past ``horizon_us``, the stream's horizon so far (None: the first packet of a stream),
    nor may its offset lie beyond :data:`~flagtrack.drivers.formats.packets.MAX_OFFSET_US`.
    """
    loop_us = LOOP_US.get(packet.encoding)
    if loop_us is None:
        return f"packet {packet.seq}: unknown encoding {packet.encoding!r}"
    offset = packet.t_offset_us
    if offset < 0 or offset % loop_us:
        return f"packet {packet.seq}: time offset {offset} µs is not a whole number of {packet.encoding} loops"
    if offset > MAX_OFFSET_US:
        return f"packet {packet.seq}: time offset {offset} µs is more than a year of camera time"
    holds_times = packet.n_events > 0 or packet.n_triggers > 0
    if holds_times and not 0 <= packet.t_first_us - offset < loop_us + _SLACK_US:
        return f"packet {packet.seq}: time offset {offset} µs does not hold its first event at {packet.t_first_us} µs"
    start = max(horizon_us, packet.t_first_us) if horizon_us is not None else packet.t_first_us
    past_start = holds_times and packet.t_last_us - start > MAX_JUMP_US
    if past_start or (horizon_us is not None and packet.t_last_us - horizon_us > MAX_JUMP_US):
        return (
            f"packet {packet.seq}: its horizon {packet.t_last_us} µs is more than an hour past "
            f"{'the stream so far' if horizon_us is not None else 'its first event'} ({start} µs)"
        )
    return None


REORDER_WINDOW = 64
"""Without stream ids: a packet at most this far behind is late, further behind a new stream."""


class Arrival(enum.Enum):
    """What a packet is to the stream followed so far."""

    NEXT = "next"  # the one expected (or the first one)
    GAP = "gap"  # packets are missing before it
    LATE = "late"  # a duplicate or late packet of this stream: drop it
    NEW_STREAM = "new stream"  # the camera restarted


@dataclass
class PacketSequence:
    """The stream followed and the next sequence number expected (``None``: no packet yet), and the
    stream's horizon so far (``horizon_us``: the latest ``t_last_us`` of its packets that were used,
    :meth:`follow_horizon`; ``None`` at the start of a stream)."""

    stream_id: int = 0
    next_seq: int | None = None
    horizon_us: int | None = None

    def follow_horizon(self, t_last_us: int) -> None:
        """A packet of the stream was used: its horizon is the stream's if later."""
        self.horizon_us = t_last_us if self.horizon_us is None else max(self.horizon_us, t_last_us)

    def classify(self, seq: int, stream_id: int = 0) -> tuple[Arrival, int]:
        """What a packet would be, without following it; (arrival, packets missing before it). O(1)."""
        expected = self.next_seq
        if expected is None:
            return Arrival.NEXT, 0
        if stream_id != self.stream_id:
            return Arrival.NEW_STREAM, 0
        if seq >= expected:
            return (Arrival.NEXT, 0) if seq == expected else (Arrival.GAP, seq - expected)
        if stream_id != 0 or (seq > 0 and seq >= expected - REORDER_WINDOW):
            return Arrival.LATE, 0
        return Arrival.NEW_STREAM, 0

    def arrive(self, seq: int, stream_id: int = 0) -> tuple[Arrival, int]:
        """:meth:`classify` a packet and follow it (a LATE one changes nothing)."""
        arrival, missing = self.classify(seq, stream_id)
        if arrival is Arrival.NEW_STREAM or self.next_seq is None:
            self.horizon_us = None
        if arrival is not Arrival.LATE:
            self.stream_id, self.next_seq = stream_id, seq + 1
        return arrival, missing

    def restart(self) -> None:
        """Forget the stream (after its end): the next packet starts a new one."""
        self.stream_id, self.next_seq, self.horizon_us = 0, None, None
