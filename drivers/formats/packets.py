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

from flagtrack.daemon.core.events import empty_triggers
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import _timebase as tb
from flagtrack.drivers.formats import make_decoder
from flagtrack.drivers.formats._packet_kernels import encode_packets, packet_words, slot_runs
from flagtrack.drivers.formats.codec import LOOP_US, Encoder

_WORD_DTYPE = {"evt3": "<u2", "evt2": "<u4"}
MAX_OFFSET_US = 366 * 86_400_000_000
"""The largest time offset a packet may carry, a year of camera time: its stream preamble is then at
most 7.5 MB (EVT 3.0, 4 bytes per 16.8 s loop). Beyond, a forged offset would make the preamble
hundreds of MB (decades: 7 GB)."""


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
    preamble_bytes: int = 0  # state words before the camera's own (native packets, drivers/formats/native.py)


class Packetizer:
    """Accumulates decoded events and emits packets whose time slot has closed.

    A slot ``[k packet_us, (k+1) packet_us)`` closes when a later event arrives or when the camera
    says its stream is complete past the slot end (``t_until_us``, e.g. a still flag: no events,
    but time goes on). Each packet's ``t_last_us`` is its completeness horizon: every event with
    ``t <= t_last_us`` is in it or in an earlier packet, except the late events of a sensor whose
    times step back. An event's slot is that of the latest time seen so far (sensors step back by
    a few µs; a late event joins the current slot), so horizons never go back; the tracker allows
    for the steps back it has seen. When only time passes, an empty packet carries the horizon
    forward. Events are held as contiguous columns (the encoder runs about twice as fast on them as
    on the fields of an event array).

    Args:
        encoding: ``evt3`` or ``evt2``.
        width, height: sensor size (events outside are refused by the encoder).
        params: packet limits.
    """

    def __init__(self, encoding: str, width: int, height: int, params: PacketParams = PacketParams()) -> None:
        if encoding not in _WORD_DTYPE:
            raise FormatError(f"cannot encode {encoding!r} (encoders: evt2, evt3)")
        self.encoding = encoding
        self.width, self.height = width, height
        self.params = params
        self._cols = _HeldColumns()
        self._max_before = np.iinfo(np.int64).min  # running maximum of t before the held events
        self._triggers = empty_triggers()
        self._horizon_us: int | None = None  # t_last_us of the last packet emitted

    @property
    def horizon_us(self) -> int:
        """Completeness horizon of the last packet emitted (-1 before the first)."""
        return -1 if self._horizon_us is None else self._horizon_us

    def push(
        self, events: np.ndarray, triggers: np.ndarray | None = None, t_until_us: int | None = None
    ) -> list[Packet]:
        """Add data (and, optionally, "complete before ``t_until_us``"); return the packets it closes."""
        if len(events):
            self._cols.append(events)
        if triggers is not None and len(triggers):
            self._triggers = np.concatenate([self._triggers, triggers])
        packet_us = self.params.packet_us
        n_held = self._cols.n
        run_starts, run_slots, run_maxima = slot_table(self._cols.t, self._max_before, packet_us)
        n_runs = len(run_slots)
        known_until = max(int(run_maxima[n_runs - 1]) if n_runs else -1, -1 if t_until_us is None else int(t_until_us))
        closed_slot = known_until // packet_us  # slots before this one are closed
        n_closed_runs = int(np.searchsorted(run_slots, closed_slot, side="left"))
        segments: list[tuple[int, int, int]] = []
        for q in range(n_closed_runs):
            segments += self._slot_segments(
                int(run_starts[q]), int(run_starts[q + 1]), (int(run_slots[q]) + 1) * packet_us - 1
            )
        start = segments[-1][1] if segments else 0
        if (
            not segments
            and t_until_us is not None
            and closed_slot * packet_us - 1 > (self._horizon_us or -1)
            and n_held == 0
        ):
            segments.append((0, 0, closed_slot * packet_us - 1))  # only time passed: an empty packet
        packets = self._packets(segments)
        if n_closed_runs:
            self._max_before = int(run_maxima[n_closed_runs - 1])
        self._cols.drop_front(start)
        return packets

    def flush(self) -> list[Packet]:
        """Emit everything held (end of stream)."""
        n_held = self._cols.n
        if n_held == 0 and len(self._triggers) == 0:
            return []
        t_last = max(
            max(self._max_before, int(self._cols.t.max())) if n_held else -1,
            int(self._triggers["t"].max()) if len(self._triggers) else -1,
        )
        packets = self._packets(self._slot_segments(0, n_held, t_last))
        self._cols.drop_front(n_held)
        return packets

    def _slot_segments(self, start: int, stop: int, horizon_us: int) -> list[tuple[int, int, int]]:
        """(start, stop, horizon) of the packets of the held events [start:stop] (one slot), split at
        ``max_events``."""
        segments = []
        while stop - start > self.params.max_events:
            cut = start + self.params.max_events
            segments.append((start, cut, int(self._cols.t[start:cut].max()) - 1))
            start = cut
        segments.append((start, stop, horizon_us))
        return segments

    def _packets(self, segments: list[tuple[int, int, int]]) -> list[Packet]:
        """Encode the held events of each segment, with the held triggers up to its horizon, in one
        compiled call; each packet is what a fresh encoder makes of it (see :func:`_packet`)."""
        if not segments:
            return []
        starts, stops, horizons = (np.array(column, dtype=np.int64) for column in zip(*segments))
        triggers, tr_bounds = self._take_triggers(horizons)
        cols, n_packets = self._cols.view(), len(segments)
        n_triggers = np.diff(tr_bounds)
        out_ends, t_offsets, n_on = (np.zeros(n_packets, dtype=np.int64) for _ in range(3))
        data: list[bytes] = []
        q0 = 0
        while q0 < n_packets:
            out = np.empty(packet_words(stops[q0:] - starts[q0:], n_triggers[q0:]), dtype=_WORD_DTYPE[self.encoding])
            done, status = encode_packets(
                self.encoding == "evt3",
                cols.t,
                cols.x,
                cols.y,
                cols.p,
                starts[q0:],
                stops[q0:],
                horizons[q0:],
                triggers["t"],
                triggers["channel"],
                triggers["edge"],
                tr_bounds[q0:-1],
                tr_bounds[q0 + 1 :],
                LOOP_US[self.encoding],
                self.width,
                self.height,
                out,
                out_ends[q0:],
                t_offsets[q0:],
                n_on[q0:],
            )
            word = 0
            for q in range(q0, q0 + done):
                data.append(out[word : out_ends[q]].tobytes())
                word = int(out_ends[q])
            q0 += done
            if status != tb.OK:
                # packet q0 did not fit the room the batch allows (time jumps or jitter across a time-base
                # step cost more words per event) or holds a bad event: a fresh encoder grows its output
                # as needed, and raises a FormatError naming the event and the reason
                data.append(
                    self._packet(
                        cols.slice(int(starts[q0]), int(stops[q0])),
                        triggers[tr_bounds[q0] : tr_bounds[q0 + 1]],
                        int(t_offsets[q0]),
                    )
                )
                q0 += 1
        self._horizon_us = int(horizons[-1])
        packets = []
        for q in range(n_packets):
            i0, i1, n_tr = int(starts[q]), int(stops[q]), int(n_triggers[q])
            # the earliest time, events and triggers alike: the one the time offset was taken from
            t_first = int(cols.t[i0:i1].min()) if i1 > i0 else int(horizons[q])
            if n_tr:
                t_first = min(t_first, int(triggers["t"][tr_bounds[q] : tr_bounds[q + 1]].min()))
            packets.append(
                Packet(
                    data=data[q],
                    t_first_us=t_first,
                    t_last_us=int(horizons[q]),
                    n_events=i1 - i0,
                    n_on=int(n_on[q]),
                    n_triggers=n_tr,
                    t_offset_us=int(t_offsets[q]),
                )
            )
        return packets

    def _take_triggers(self, horizons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The held triggers each packet takes (those up to its horizon not taken by an earlier one),
        grouped by packet in held order, and the group bounds (n_packets + 1,); the rest stay held."""
        held = self._triggers
        if len(held) == 0:
            return held, np.zeros(len(horizons) + 1, dtype=np.int64)
        packet_of = np.searchsorted(np.maximum.accumulate(horizons), held["t"], side="left")
        taken = packet_of < len(horizons)
        order = np.argsort(packet_of[taken], kind="stable")
        self._triggers = held[~taken]
        counts = np.bincount(packet_of[taken], minlength=len(horizons))
        return held[taken][order], np.concatenate([[0], np.cumsum(counts)])

    def _packet(self, cols: _Columns, triggers: np.ndarray, t_offset_us: int) -> bytes:
        """One packet's bytes by a fresh :class:`Encoder` (raises its FormatError on a bad event)."""
        encoder = Encoder(self.encoding, t_offset_us=t_offset_us, width=self.width, height=self.height)
        return encoder.encode_columns(cols.t, cols.x, cols.y, cols.p, triggers)


@dataclass(frozen=True)
class _Columns:
    """Events as contiguous columns."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray

    def slice(self, start: int, stop: int) -> _Columns:
        return _Columns(self.t[start:stop], self.x[start:stop], self.y[start:stop], self.p[start:stop])


class _HeldColumns:
    """The events a packetizer holds, as contiguous columns in buffers that grow as needed: new
    events are copied in field by field (no concatenation with those held), and the events packed
    are dropped in place."""

    def __init__(self) -> None:
        self._buffers: tuple[np.ndarray, ...] = (
            np.empty(0, np.int64),
            np.empty(0, np.uint16),
            np.empty(0, np.uint16),
            np.empty(0, np.uint8),
        )
        self.n = 0

    @property
    def t(self) -> np.ndarray:
        return self._buffers[0][: self.n]

    def view(self) -> _Columns:
        """The held events (views: valid until the next append or drop)."""
        return _Columns(*(buffer[: self.n] for buffer in self._buffers))

    def append(self, events: np.ndarray) -> None:
        need = self.n + len(events)
        if need > len(self._buffers[0]):
            capacity = max(need, 2 * len(self._buffers[0]), 4096)
            grown = tuple(np.empty(capacity, dtype=buffer.dtype) for buffer in self._buffers)
            for new, old in zip(grown, self._buffers):
                new[: self.n] = old[: self.n]
            self._buffers = grown
        for buffer, name in zip(self._buffers, ("t", "x", "y", "p")):
            buffer[self.n : need] = events[name]
        self.n = need

    def drop_front(self, start: int) -> None:
        """Keep the events from ``start`` on, moved to the front."""
        keep = self.n - start
        if keep > 0 and start > 0:
            for buffer in self._buffers:
                buffer[:keep] = buffer[start : self.n]  # numpy copies overlapping ranges correctly
        self.n = max(keep, 0)


class PacketJoiner:
    """Consecutive packets joined while they hold fewer than ``min_events`` events, up to ``max_us``
    of camera time: at a low event rate, fewer and longer packets (each costs its consumers a
    message, a decode and a call whatever it holds); at a high one, the packets as cut.

    A joined packet is the first packet whole followed by the others' words after their state
    preamble (:attr:`Packet.preamble_bytes`): the same stream, byte for byte. ``push`` returns
    ``(packet, arrival_ns)`` pairs, each with the arrival of its first part (its events waited in
    the camera from then on); packets of another time loop are not joined.
    """

    def __init__(self, min_events: int, max_us: int) -> None:
        self.min_events, self.max_us = min_events, max_us
        self._held: list[Packet] = []
        self._arrival_ns = 0

    def push(self, packets: list[Packet], arrival_ns: int) -> list[tuple[Packet, int]]:
        """Take ``packets`` (arrived at ``arrival_ns``); return those ready, joined."""
        out: list[tuple[Packet, int]] = []
        for packet in packets:
            held = self._held
            if held and (
                packet.t_offset_us != held[0].t_offset_us or packet.t_last_us - held[0].t_first_us >= self.max_us
            ):
                out += self.flush()
            if not self._held:
                self._arrival_ns = arrival_ns
            self._held.append(packet)
            span_us = packet.t_last_us - self._held[0].t_first_us + 1
            if span_us >= self.max_us or sum(p.n_events for p in self._held) >= self.min_events:
                out += self.flush()
        return out

    def flush(self) -> list[tuple[Packet, int]]:
        """The packets held, joined (none if none is)."""
        held, self._held = self._held, []
        if not held:
            return []
        if len(held) == 1:
            return [(held[0], self._arrival_ns)]
        first = held[0]
        joined = Packet(
            data=first.data + b"".join(p.data[p.preamble_bytes :] for p in held[1:]),
            t_first_us=first.t_first_us,
            t_last_us=held[-1].t_last_us,
            n_events=sum(p.n_events for p in held),
            n_on=sum(p.n_on for p in held),
            n_triggers=sum(p.n_triggers for p in held),
            t_offset_us=first.t_offset_us,
            preamble_bytes=first.preamble_bytes,
        )
        return [(joined, self._arrival_ns)]


def slot_table(t: np.ndarray, running_max: int, slot_us: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut events into runs of one time slot: slot = (running maximum of t, from ``running_max`` on) // ``slot_us``.

    Returns:
        (first index of each run, followed by ``len(t)``; slot of each run; running maximum at
        each run's last event).
    """
    n = len(t)
    starts, slots, maxima = (np.empty(n + 1, dtype=np.int64) for _ in range(3))
    if t.dtype != np.int64:
        t = t.astype(np.int64)
    n_runs = slot_runs(t, running_max, slot_us, starts, slots, maxima)  # strided (an event field) as it is
    starts[n_runs] = n
    return starts[: n_runs + 1], slots[:n_runs], maxima[:n_runs]


def decode_packet(
    encoding: str, data: bytes, t_offset_us: int, *, source: str = "packet"
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

    Raises:
        FormatError: an offset that is not a whole number of loops, or beyond :data:`MAX_OFFSET_US`.
    """
    loops = t_offset_us // LOOP_US[encoding]
    if t_offset_us % LOOP_US[encoding] or loops < 0:
        raise FormatError(f"time offset {t_offset_us} µs is not a whole number of {encoding} loops")
    if t_offset_us > MAX_OFFSET_US:
        raise FormatError(f"time offset {t_offset_us} µs is more than a year of camera time ({MAX_OFFSET_US} µs)")
    if encoding == "evt3":
        pair = np.array([0x8FFF, 0x8000], dtype="<u2")
    else:
        pair = np.array([0x8FFFFFFF, 0x80000000], dtype="<u4")
    return np.tile(pair, loops).tobytes()
