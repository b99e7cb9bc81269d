"""Stateful streaming codecs for Prophesee EVT 2.0 / 2.1 / 3.0 byte streams.

A :class:`Decoder` turns bytes into events as they arrive (file blocks or live packets): it keeps
a partial word and the time state between calls, so decoding a stream in pieces of any size gives
exactly what decoding it at once gives. An :class:`Encoder` does the reverse, so that consecutive
packets concatenate into one valid stream.

Time: EVT streams carry time modulo a loop (2**24 µs for EVT 3.0, 2**34 µs for EVT 2.x) and a
decoder unwraps it from the first TIME_HIGH on, in loop 0. An encoder therefore subtracts a time
offset, a whole number of loops (by default the loop of the first time it sees, see
:attr:`Encoder.t_offset_us`), and a decoder given the same ``t_offset_us`` adds it back. RAW files
written by flagtrack keep it in the header line ``% t_offset_us``.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from flagtrack.daemon.core.events import EVENT_DTYPE, TRIGGER_DTYPE, empty_events, empty_triggers
from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats import _timebase as tb
from flagtrack.drivers.formats._evt2_kernels import decode_evt2, decode_evt21, encode_evt2
from flagtrack.drivers.formats._evt3_kernels import decode_evt3, encode_evt3

ENCODINGS = ("evt2", "evt21", "evt3")
WORD_BYTES = {"evt2": 4, "evt21": 8, "evt3": 2}
EVENTS_PER_WORD = {"evt2": 1, "evt21": 32, "evt3": 12}
LOOP_US = {"evt2": 1 << 34, "evt21": 1 << 34, "evt3": 1 << 24}
NAMES = {"evt2": "EVT 2.0", "evt21": "EVT 2.1", "evt3": "EVT 3.0"}
RESERVED_TYPES = {
    "evt2": [2, 3, 4, 5, 6, 7, 9, 11, 12, 13],
    "evt21": [2, 3, 4, 5, 6, 7, 9, 11, 12, 13],
    "evt3": [9, 11, 12, 13],
}
SENSOR_LIMIT = 2048
"""Coordinates carry 11 bits in every EVT format."""


class FormatWarning(UserWarning):
    """A fault in an event stream that was skipped or cut short instead of raised (non-strict)."""


TIME_HIGH_BITS = {"evt2": (6, 28), "evt21": (6, 28), "evt3": (12, 12)}
"""(shift, bits) of a TIME_HIGH word's value: its unit is ``2**shift`` µs, it wraps after ``2**bits`` units."""
RESYNC_WINDOW_US = 1 << 20
"""A TIME_HIGH at most this far (about 1 s) after the last good one resynchronises at once; a farther
one only when the next two TIME_HIGH words follow it within this window (the stream is clean again)."""


def unwrap_units(prev_units: int, raw: int, bits: int) -> int:
    """The absolute TIME_HIGH units of value ``raw`` after ``prev_units``, by OpenEB's threshold rule
    (a drop to within :data:`~._timebase.LOOP_THRESHOLD_UNITS` of a whole loop is a wrap)."""
    period = 1 << bits
    loop, prev_raw = divmod(prev_units, period)
    if prev_raw > raw and prev_raw - raw >= period - 1 - tb.LOOP_THRESHOLD_UNITS:
        loop += 1
    return loop * period + raw


@dataclass(frozen=True)
class SkippedRange:
    """Bytes ``[start, end)`` of a file skipped after a fault, holding at most ``events_at_most`` events."""

    start: int
    end: int
    events_at_most: int
    reason: str


def check_encoding(encoding: str | None, source: str | None = None) -> str:
    """Return ``encoding`` if it is one of :data:`ENCODINGS`, else raise FormatError."""
    if encoding not in ENCODINGS:
        raise FormatError(f"unknown encoding {encoding!r} (known: {', '.join(ENCODINGS)})", path=source)
    return encoding


def event_views(events: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two int64 views for the kernels' stores into an EVENT_DTYPE array of n + 1 records.

    ``tt[i]`` is record i's time; ``xyp[i]`` covers its x, y, p and the first 3 bytes of record
    i + 1 (rewritten by the next time store), so n events can be stored, two stores each.
    """
    buffer = events.view(np.uint8)
    n, size = len(events) - 1, EVENT_DTYPE.itemsize
    tt = np.ndarray(shape=(n,), dtype="<i8", buffer=buffer, offset=0, strides=(size,))
    xyp = np.ndarray(shape=(n,), dtype="<i8", buffer=buffer, offset=8, strides=(size,))
    return tt, xyp


_SMALL_BUFFER = 1 << 18  # events (3.4 MB): a piece of a buffer this small is kept as it is (no copy to trim it)


class Decoder:
    """Incremental decoder of one EVT byte stream.

    Args:
        encoding: ``"evt2"``, ``"evt21"`` or ``"evt3"``.
        width, height: sensor size; events outside it are faults. None: only the 11-bit limit.
        t_offset_us: added to every decoded time (the stream's encoder offset, a whole number of loops).
        strict: on a fault (reserved word, event outside the sensor), raise :class:`FormatError`
            (True; the rest of that call's data is dropped, the state stays usable for the next
            call) or warn with :class:`FormatWarning`, skip the word and go on (False).
        resync: (not strict) after a fault, skip to the next TIME_HIGH word whose time base follows
            the last good one (see :data:`RESYNC_WINDOW_US`) and go on from there, recording what
            was skipped in :attr:`skipped`, instead of skipping the faulty word alone.
        source: name of the stream (file path) for messages.
        base_offset: byte offset of the stream's first byte in its file (header length), so
            errors and chunk offsets are file offsets.
        endianness: EVT 2.1 only: ``"little"`` (default) or ``"legacy"`` (halves swapped, IMX636).
        max_events: most events per decoded piece (bounds memory).
    """

    def __init__(
        self,
        encoding: str,
        *,
        width: int | None = None,
        height: int | None = None,
        t_offset_us: int = 0,
        strict: bool = True,
        source: str | None = None,
        base_offset: int = 0,
        endianness: str = "little",
        max_events: int = 1 << 20,
        resync: bool = False,
    ) -> None:
        self.encoding = check_encoding(encoding, source)
        if endianness not in ("little", "legacy"):
            raise FormatError(f"unknown EVT 2.1 endianness {endianness!r}", path=source)
        self.width = width
        self.height = height
        self.t_offset_us = int(t_offset_us)
        self.strict = strict
        self.source = source
        self.endianness = endianness
        self.max_events = max(int(max_events), 64)
        self.faults = 0
        self.resync = resync and not strict
        self.skipped: list[SkippedRange] = []
        self._resync_from: tuple[int, str] | None = None  # (file offset, reason) while skipping
        self._word = WORD_BYTES[encoding]
        self._state = np.zeros(16, dtype=np.int64)
        self._state[7] = 1  # EVT 3.0 starts in CD mode
        self._tail = b""
        self._fed = base_offset  # file offset just past the last byte fed
        self._triggers = np.empty(1 << 14, dtype=TRIGGER_DTYPE)  # written before read: no zero fill

    @property
    def offset(self) -> int:
        """File offset of the first byte not yet decoded (start of a pending partial word)."""
        return self._fed - len(self._tail)

    def decode(self, data: bytes | bytearray | memoryview, *, trim: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Decode the next bytes of the stream; return (events, triggers) of every whole word.

        ``trim=False`` returns views of the decoding buffer, which may be several times larger than
        the events (worst case: vector words): faster for results that are used and dropped.
        """
        pieces = list(self.pieces(data, trim=trim))
        if not pieces:
            return empty_events(), empty_triggers()
        if len(pieces) == 1:
            return pieces[0][0], pieces[0][1]
        return np.concatenate([p[0] for p in pieces]), np.concatenate([p[1] for p in pieces])

    def pieces(
        self, data: bytes | bytearray | memoryview, *, trim: bool = True
    ) -> Iterator[tuple[np.ndarray, np.ndarray, int]]:
        """Decode the next bytes in bounded pieces: yield (events, triggers, file offset of the piece).

        With ``trim`` a piece that fills less than half its buffer is copied out of it (bounded memory
        for pieces that are kept).

        A fault in strict mode raises after the pieces before it were yielded.
        """
        start_offset = self.offset
        buf = memoryview(data).cast("B")
        self._fed += len(buf)
        if self._tail:
            buf = memoryview(self._tail + bytes(buf))
        n_words = len(buf) // self._word
        self._tail = bytes(buf[n_words * self._word :])
        if n_words == 0:
            return
        run = self._kernel_runner(buf, n_words)
        i = 0 if self._resync_from is None else self._resync_point(buf, 0, n_words, start_offset)
        while i < n_words:
            capacity = min(self.max_events, (n_words - i) * EVENTS_PER_WORD[self.encoding] + 64)
            events = np.empty(capacity + 1, dtype=EVENT_DTYPE)
            i_next, n, nt, status = run(i, *event_views(events))
            if n or nt:
                keep_view = not trim or 2 * n >= capacity or capacity <= _SMALL_BUFFER
                piece = events[:n] if keep_view else events[:n].copy()
                yield piece, self._triggers[:nt].copy(), start_offset + i * self._word
            if status in (tb.BAD_WORD, tb.OUT_OF_SENSOR):
                offset = start_offset + i_next * self._word
                reason = self._fault(status, buf, i_next, offset)
                i_next += 1
                if self.resync:
                    self._resync_from = (offset, reason)
                    i_next = self._resync_point(buf, i_next, n_words, start_offset)
            i = i_next

    @property
    def events_lost_at_most(self) -> int:
        """Upper bound on the events in the stretches skipped so far (:attr:`skipped`)."""
        return sum(r.events_at_most for r in self.skipped)

    def _resync_point(self, buf: memoryview, i: int, n_words: int, start_offset: int) -> int:
        """While resynchronising: the index (>= ``i``) of the TIME_HIGH word to go on from, or
        ``n_words`` if none in this buffer; a found one closes the skipped range."""
        high = self._high_words(buf, n_words)
        shift, bits = TIME_HIGH_BITS[self.encoding]
        top = 12 if self.encoding == "evt3" else 28  # the type: the top 4 bits of the (high) word
        types = high[i:] >> top
        marks = np.flatnonzero(types == 8) + i
        bad = np.flatnonzero(np.isin(types, RESERVED_TYPES[self.encoding])) + i
        period, window = 1 << bits, max(RESYNC_WINDOW_US >> shift, 1)
        last = int(self._state[1]) >> shift  # absolute units (loops included)
        values = (high[marks] & (period - 1)).astype(np.int64)
        absolute, prev = [], last
        for v in values:  # the decoder's own unwrapping over the TIME_HIGH words skipped
            prev = unwrap_units(prev, int(v), bits)
            absolute.append(prev)
        for k, j in enumerate(marks):
            nxt = marks[k + 1 : k + 3]
            clean = len(nxt) == 2 and not np.any((bad > j) & (bad < nxt[-1]))
            chain = absolute[k : k + 3]
            follows = clean and all(0 <= b - a <= window for a, b in zip(chain, chain[1:]))
            if self._state[0] == 0 or 0 <= absolute[k] - last <= window or follows:
                if self._state[0]:  # the time base goes on from the word resynchronised on
                    self._state[1] = absolute[k] << shift
                    self._state[2] = absolute[k] >> bits
                self._end_skip(start_offset + int(j) * self._word)
                return int(j)
        return n_words

    def _high_words(self, buf: memoryview, n_words: int) -> np.ndarray:
        if self.encoding == "evt21":
            halves = np.frombuffer(buf, dtype="<u4", count=2 * n_words)
            return halves[1::2] if self.endianness == "little" else halves[0::2]
        return np.frombuffer(buf, dtype="<u2" if self.encoding == "evt3" else "<u4", count=n_words)

    def _end_skip(self, end: int) -> None:
        """Close the range being skipped at file offset ``end``; decoding goes on from there."""
        if self._resync_from is None:
            return
        start, reason = self._resync_from
        self._resync_from = None
        self._state[7] = 0  # EVT 3.0: no event until the next EVT_ADDR_Y gives y again
        n_events = (end - start) // self._word * EVENTS_PER_WORD[self.encoding]
        self.skipped.append(SkippedRange(start, end, n_events, reason))
        where = f"{self.source}, " if self.source else ""
        warnings.warn(
            f"{where}bytes {start}-{end}: {reason}; skipped to the next valid time base "
            f"(at most {n_events} events lost)",
            FormatWarning,
            stacklevel=4,
        )

    def finish(self) -> None:
        """End of stream: a pending partial word means the stream was cut inside a word; a range still
        being skipped ends at the end of the stream."""
        if self._resync_from is not None:
            self._end_skip(self._fed - len(self._tail))
        if self._tail:
            n = len(self._tail)
            self._tail = b""
            self._report(
                f"stream ends inside a {self._word}-byte {NAMES[self.encoding]} word "
                f"({n} trailing bytes; truncated file?)",
                self._fed - n,
                outcome="kept the events before it" if self.resync else "skipped",  # a reader's words, as before
            )

    def _kernel_runner(self, buf: memoryview, n_words: int):  # noqa: ANN202
        width = SENSOR_LIMIT if self.width is None else int(self.width)
        height = SENSOR_LIMIT if self.height is None else int(self.height)
        tr, state, off = self._triggers, self._state, self.t_offset_us
        if self.encoding == "evt21":
            halves = np.frombuffer(buf, dtype="<u4", count=2 * n_words)
            high, low = (halves[1::2], halves[0::2]) if self.endianness == "little" else (halves[0::2], halves[1::2])
            return lambda i, tt, xyp: decode_evt21(high, low, i, state, tt, xyp, tr, width, height, off)
        words = np.frombuffer(buf, dtype="<u2" if self.encoding == "evt3" else "<u4", count=n_words)
        kernel = decode_evt3 if self.encoding == "evt3" else decode_evt2
        return lambda i, tt, xyp: kernel(words, i, state, tt, xyp, tr, width, height, off)

    def _fault(self, status: int, buf: memoryview, index: int, offset: int) -> str:
        word = bytes(buf[index * self._word : (index + 1) * self._word])
        value = int.from_bytes(word, "little")
        if self.encoding == "evt21" and self.endianness == "legacy":
            value = ((value & 0xFFFFFFFF) << 32) | (value >> 32)
        typ = value >> (4 * (2 * self._word) - 4)
        if status == tb.BAD_WORD:
            what = f"corrupt {NAMES[self.encoding]} word 0x{value:0{2 * self._word}x}: reserved type 0x{typ:x}"
        else:
            what = (
                f"corrupt {NAMES[self.encoding]} word 0x{value:0{2 * self._word}x}: event outside the "
                f"{self.width}x{self.height} sensor"
            )
        self._report(what, offset, quiet=self.resync)  # resync: said once per skipped range, when it closes
        return what

    def _report(self, message: str, offset: int, quiet: bool = False, outcome: str = "skipped") -> None:
        self.faults += 1
        if self.strict:
            raise FormatError(message, path=self.source, offset=offset)
        if quiet:
            return
        where = f"{self.source}, byte {offset}" if self.source else f"byte {offset}"
        warnings.warn(f"{where}: {message}; {outcome}", FormatWarning, stacklevel=3)


_ENCODE_ERRORS = {
    tb.NEGATIVE_TIME: "time {t} µs is before the stream's time offset {off} µs",
    tb.TIME_JUMP_BACK: "time steps back to {t} µs across a {name} time loop, which the format cannot carry",
    tb.BAD_VALUE: "value out of range for {name} or the {w}x{h} sensor",
}


class Encoder:
    """Incremental encoder of events (and triggers) into one EVT 2.0 or EVT 3.0 byte stream.

    Args:
        encoding: ``"evt2"`` or ``"evt3"``.
        t_offset_us: time subtracted before encoding, a multiple of the format's loop (2**34 or
            2**24 µs). None: the loop of the first time encoded (see :attr:`t_offset_us`).
        width, height: sensor size; events outside it are refused.
        target: name of the output (file path) for messages.
    """

    def __init__(
        self,
        encoding: str,
        *,
        t_offset_us: int | None = None,
        width: int | None = None,
        height: int | None = None,
        target: str | None = None,
    ) -> None:
        if encoding not in ("evt2", "evt3"):
            raise FormatError(f"cannot encode {encoding!r} (encoders: evt2, evt3)", path=target)
        self.encoding = encoding
        self.loop_us = LOOP_US[encoding]
        if t_offset_us is not None and t_offset_us % self.loop_us:
            raise FormatError(f"t_offset_us must be a multiple of {self.loop_us} µs for {encoding}", path=target)
        self._t_offset = t_offset_us
        self.width = SENSOR_LIMIT if width is None else int(width)
        self.height = SENSOR_LIMIT if height is None else int(height)
        self.target = target
        self._state = np.zeros(16, dtype=np.int64)
        self._state[2] = -1
        self._count = 0

    @property
    def t_offset_us(self) -> int | None:
        """Offset subtracted from times (None until the first time is seen and none was given)."""
        return self._t_offset

    def encode(self, events: np.ndarray, triggers: np.ndarray | None = None) -> bytes:
        """Return the stream bytes for ``events`` (EVENT_DTYPE) and ``triggers`` (TRIGGER_DTYPE)."""
        t, x, y, p = _columns(events, ("t", "x", "y", "p"), EVENT_DTYPE)
        return self.encode_columns(t, x, y, p, triggers=triggers)

    def encode_columns(
        self, t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, triggers: np.ndarray | None = None
    ) -> bytes:
        """:meth:`encode` for events given as columns (t int64, x/y uint16, p uint8).

        Contiguous columns encode about twice as fast as the strided fields of an event array.
        """
        ev = (t, x, y, p)
        tr = _columns(triggers if triggers is not None else empty_triggers(), ("t", "channel", "edge"), TRIGGER_DTYPE)
        n_ev, n_tr = len(ev[0]), len(tr[0])
        if n_ev + n_tr == 0:
            return b""
        if self._t_offset is None:
            t0 = min(
                int(ev[0][0]) if n_ev else np.iinfo(np.int64).max, int(tr[0][0]) if n_tr else np.iinfo(np.int64).max
            )
            self._t_offset = (t0 // self.loop_us) * self.loop_us
        kernel, dtype = (encode_evt3, "<u2") if self.encoding == "evt3" else (encode_evt2, "<u4")
        out = np.empty(3 * n_ev + 4 * n_tr + 64, dtype=dtype)
        parts = []
        i = j = 0
        while True:
            i, j, k, status = kernel(*ev, i, *tr, j, self._state, out, self._t_offset, self.width, self.height)
            parts.append(out[:k].tobytes())
            if status == tb.OK:
                break
            if status != tb.FULL:
                self._raise(status, ev, tr, i, j)
        self._count += n_ev
        return b"".join(parts)

    def _raise(self, status: int, ev: tuple, tr: tuple, i: int, j: int) -> None:
        is_trigger = j < len(tr[0]) and (i >= len(ev[0]) or tr[0][j] < ev[0][i])
        if is_trigger:
            what, values = f"trigger {j}", {k: int(c[j]) for k, c in zip(("t", "channel", "edge"), tr)}
        else:
            what, values = f"event {self._count + i}", {k: int(c[i]) for k, c in zip(("t", "x", "y", "p"), ev)}
        message = _ENCODE_ERRORS[status].format(
            t=values["t"], off=self._t_offset, name=NAMES[self.encoding], w=self.width, h=self.height
        )
        raise FormatError(f"cannot encode {what} {values}: {message}", path=self.target)


def _columns(array: np.ndarray, names: tuple[str, ...], dtype: np.dtype) -> tuple[np.ndarray, ...]:
    """The fields of a structured array, cast to ``dtype``'s field types where they differ."""
    missing = [name for name in names if array.dtype.names is None or name not in array.dtype.names]
    if missing:
        raise FormatError(f"array has no field(s) {missing}; expected fields {names}")
    return tuple(np.asarray(array[name], dtype=dtype[name]) for name in names)


def make_decoder(encoding: str, **options: object) -> Decoder:
    """Return a streaming :class:`Decoder` for ``encoding`` (options as in :class:`Decoder`)."""
    return Decoder(encoding, **options)  # type: ignore[arg-type]


def make_encoder(encoding: str, **options: object) -> Encoder:
    """Return a streaming :class:`Encoder` for ``encoding`` (options as in :class:`Encoder`)."""
    return Encoder(encoding, **options)  # type: ignore[arg-type]
