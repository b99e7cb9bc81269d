"""Cut a camera stream into self-contained native-encoding packets, and decode them back.

Each packet is encoded by a fresh encoder whose time offset is the start of the time loop
(2**24 µs for EVT 3.0) holding its earliest event, so it starts with the time base and decodes
alone, whatever was lost before it; consecutive packets also concatenate into one valid stream
(a loop change looks like the camera's own time wrap, which decoders unwrap). Packets end on multiples of ``packet_us`` of camera time, or earlier when
they reach ``max_events``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.events import empty_events, empty_triggers
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import make_decoder
from flagtrack.drivers.formats.codec import LOOP_US, Encoder


@dataclass(frozen=True)
class PacketParams:
    """Packet size limits: ``packet_us`` of camera time, at most ``max_events`` events."""

    packet_us: int = 1000
    max_events: int = 65_536

    def __post_init__(self) -> None:
        if self.packet_us < 1 or self.max_events < 1:
            raise ValueError("packet_us and max_events must be positive")


@dataclass(frozen=True)
class Packet:
    """One encoded packet and what the bus message needs to say about it."""

    data: bytes
    t_first_us: int
    t_last_us: int
    n_events: int
    n_on: int
    n_triggers: int
    t_offset_us: int  # the loop start subtracted by this packet's encoder


class Packetizer:
    """Accumulates decoded events and emits packets whose time slot has closed.

    A slot ``[k packet_us, (k+1) packet_us)`` closes when a later event arrives or when the camera
    says its stream is complete past the slot end (``t_until_us``, e.g. a still flag: no events,
    but time goes on). Each packet's ``t_last_us`` is its completeness horizon: every event with
    ``t <= t_last_us`` is in it or in an earlier packet. When only time passes, an empty packet
    carries the horizon forward. Events are held as contiguous columns (the encoder runs about
    twice as fast on them as on the fields of an event array).

    Args:
        encoding: ``evt3`` or ``evt2``.
        width, height: sensor size (events outside are refused by the encoder).
        params: packet limits.
    """

    def __init__(self, encoding: str, width: int, height: int, params: PacketParams = PacketParams()) -> None:
        self.encoding = encoding
        self.width, self.height = width, height
        self.params = params
        self._cols = _Columns.empty()
        self._t_max = np.zeros(0, dtype=np.int64)  # running maximum of t (small steps back stay put)
        self._triggers = empty_triggers()
        self._horizon_us: int | None = None  # t_last_us of the last packet emitted

    @property
    def horizon_us(self) -> int:
        """Completeness horizon of the last packet emitted (-1 before the first)."""
        return -1 if self._horizon_us is None else self._horizon_us

    def push(self, events: np.ndarray, triggers: np.ndarray | None = None, t_until_us: int | None = None
             ) -> list[Packet]:
        """Add data (and, optionally, "complete before ``t_until_us``"); return the packets it closes."""
        if len(events):
            new = _Columns.of(events)
            t_max = np.maximum.accumulate(new.t)
            if len(self._t_max):
                np.maximum(t_max, self._t_max[-1], out=t_max)
            self._cols = self._cols.append(new)
            self._t_max = np.concatenate([self._t_max, t_max]) if len(self._t_max) else t_max
        if triggers is not None and len(triggers):
            self._triggers = np.concatenate([self._triggers, triggers])
        packet_us = self.params.packet_us
        known_until = max(int(self._t_max[-1]) if len(self._t_max) else -1,
                          -1 if t_until_us is None else int(t_until_us))
        closed_until = (known_until // packet_us) * packet_us  # slots ending at or before this are closed
        slots = self._t_max // packet_us
        n_closed = int(np.searchsorted(slots, closed_until // packet_us, side="left"))
        packets = []
        start = 0
        for cut in list(np.flatnonzero(np.diff(slots[:n_closed])) + 1) + ([n_closed] if n_closed else []):
            slot_end = (int(slots[start]) + 1) * packet_us
            packets += self._slot_packets(start, cut, slot_end - 1)
            start = cut
        self._cols = self._cols.tail(start)
        self._t_max = self._t_max[start:]
        if not packets and t_until_us is not None and closed_until - 1 > (self._horizon_us or -1) \
                and not len(self._t_max):
            packets.append(self._packet(self._cols, closed_until - 1))
        return packets

    def flush(self) -> list[Packet]:
        """Emit everything held (end of stream)."""
        if len(self._t_max) == 0 and len(self._triggers) == 0:
            return []
        t_last = max(int(self._t_max[-1]) if len(self._t_max) else -1,
                     int(self._triggers["t"].max()) if len(self._triggers) else -1)
        packets = self._slot_packets(0, len(self._t_max), t_last)
        self._cols, self._t_max = _Columns.empty(), self._t_max[:0]
        return packets

    def _slot_packets(self, start: int, stop: int, horizon_us: int) -> list[Packet]:
        """Packets of the held events [start:stop] (one slot), split at ``max_events``."""
        packets = []
        while stop - start > self.params.max_events:
            part = self._cols.slice(start, start + self.params.max_events)
            packets.append(self._packet(part, int(part.t.max()) - 1))
            start += self.params.max_events
        packets.append(self._packet(self._cols.slice(start, stop), horizon_us))
        return packets

    def _packet(self, cols: _Columns, horizon_us: int) -> Packet:
        take = self._triggers["t"] <= horizon_us
        triggers, self._triggers = self._triggers[take], self._triggers[~take]
        n = len(cols.t)
        t_first = min(int(cols.t.min()) if n else horizon_us, int(triggers["t"].min()) if len(triggers) else horizon_us)
        loop = LOOP_US[self.encoding]
        t_offset = (max(t_first, 0) // loop) * loop
        data = b""
        if n or len(triggers):
            encoder = Encoder(self.encoding, t_offset_us=t_offset, width=self.width, height=self.height)
            data = encoder.encode_columns(cols.t, cols.x, cols.y, cols.p, triggers)
        self._horizon_us = horizon_us
        first = int(cols.t[0]) if n else t_first
        return Packet(
            data=data, t_first_us=first if n else t_first, t_last_us=horizon_us, n_events=n,
            n_on=int(np.count_nonzero(cols.p)), n_triggers=len(triggers), t_offset_us=t_offset,
        )


@dataclass(frozen=True)
class _Columns:
    """Events as contiguous columns."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray

    @staticmethod
    def empty() -> _Columns:
        return _Columns(np.zeros(0, np.int64), np.zeros(0, np.uint16), np.zeros(0, np.uint16), np.zeros(0, np.uint8))

    @staticmethod
    def of(events: np.ndarray) -> _Columns:
        c = np.ascontiguousarray
        return _Columns(c(events["t"], dtype=np.int64), c(events["x"], dtype=np.uint16),
                        c(events["y"], dtype=np.uint16), c(events["p"], dtype=np.uint8))

    def append(self, other: _Columns) -> _Columns:
        if len(self.t) == 0:
            return other
        return _Columns(*(np.concatenate([a, b]) for a, b in zip(self.columns(), other.columns())))

    def slice(self, start: int, stop: int) -> _Columns:
        return _Columns(self.t[start:stop], self.x[start:stop], self.y[start:stop], self.p[start:stop])

    def tail(self, start: int) -> _Columns:
        return _Columns(*(a[start:].copy() for a in self.columns()))

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return self.t, self.x, self.y, self.p


def decode_packet(encoding: str, data: bytes, t_offset_us: int, *, source: str = "packet"
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Decode one self-contained packet (made by :class:`Packetizer`) to events and triggers.

    Raises:
        FormatError: unknown encoding or corrupt bytes (the message names ``source``).
    """
    if encoding not in LOOP_US:
        raise FormatError(f"unknown packet encoding {encoding!r}", path=source)
    decoder = make_decoder(encoding, t_offset_us=t_offset_us, strict=True, source=source)
    events, triggers = decoder.decode(data, trim=False)  # packets are decoded, used and dropped
    decoder.finish()
    return events, triggers


def stream_preamble(encoding: str, t_offset_us: int) -> bytes:
    """TIME_HIGH words that move a fresh decoder from time 0 to the start of ``t_offset_us``'s loop.

    Written before the first packet of a file, so a reader that starts at time 0 (every RAW reader)
    decodes the packets' times exactly: each loop is crossed as ``max`` then ``0``, which decoders
    read as one wrap of the time base.
    """
    loops = t_offset_us // LOOP_US[encoding]
    if t_offset_us % LOOP_US[encoding] or loops < 0:
        raise FormatError(f"time offset {t_offset_us} µs is not a whole number of {encoding} loops")
    if encoding == "evt3":
        pair = np.array([0x8FFF, 0x8000], dtype="<u2")
    else:
        pair = np.array([0x8FFFFFFF, 0x80000000], dtype="<u4")
    return np.tile(pair, loops).tobytes()
