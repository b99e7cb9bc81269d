"""Cut a camera's own EVT 2.0/3.0 bytes into packets on word boundaries, without decoding events.

Each packet is the camera's words, untouched, after a few state words (its *preamble*: EVT 3.0
TIME_HIGH, TIME_LOW, the row word and the vector base; EVT 2.0 TIME_HIGH) that let it decode alone;
``t_offset_us`` counts the time base's loops before it, as for re-encoded packets. The packets'
bodies, preambles left out, concatenate into exactly the bytes received. Counts (events, ON events,
triggers) come from the word scan. See docs/formats.md ("Native packets").
"""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.errors import FormatError
from flagtrack.drivers.formats._native_kernels import N_CUT_FIELDS, scan_evt2, scan_evt3
from flagtrack.drivers.formats.codec import LOOP_US
from flagtrack.drivers.formats.packets import Packet, PacketParams

NATIVE_ENCODINGS = ("evt3", "evt2")
_WORD = {"evt3": (2, "<u2"), "evt2": (4, "<u4")}
_MAX_CUTS = 256


class NativeCutter:
    """Cuts a stream of native bytes into packets whose time slot has closed.

    Args:
        encoding: ``evt3`` or ``evt2``.
        params: packet limits (``packet_us`` of camera time, ``max_events``).
        t_offset_us: time added to the stream's (a RAW file's ``% t_offset_us``; 0 for a camera).
    """

    def __init__(self, encoding: str, params: PacketParams = PacketParams(), t_offset_us: int = 0) -> None:
        if encoding not in NATIVE_ENCODINGS:
            raise FormatError(f"cannot cut {encoding!r} natively (native: evt3, evt2)")
        self.encoding = encoding
        self.params = params
        self._word_bytes, self._dtype = _WORD[encoding]
        self._scan = scan_evt3 if encoding == "evt3" else scan_evt2
        self.t_offset_us = int(t_offset_us)
        self._state = np.zeros(16, dtype=np.int64)
        self._state[4] = np.iinfo(np.int64).min
        self._state[5] = self._state[9] = self._state[10] = -1
        self._cuts = np.zeros((_MAX_CUTS, N_CUT_FIELDS), dtype=np.int64)
        self._open = bytearray()  # words of the open packet
        self._open_preamble = b""
        self._open_loops = 0
        self._tail = b""  # bytes of a word not complete yet
        self.horizon_us = -1

    def push(self, data: bytes | bytearray | memoryview) -> list[Packet]:
        """Add bytes as received; return the packets they close."""
        buf = self._tail + bytes(data) if self._tail else bytes(data)
        n_words = len(buf) // self._word_bytes
        self._tail = buf[n_words * self._word_bytes :]
        words = np.frombuffer(buf, dtype=self._dtype, count=n_words)
        packets: list[Packet] = []
        start = 0
        while start < n_words:
            done, n_cuts = self._scan(
                words[start:], self._state, self.params.packet_us, self.t_offset_us, self.params.max_events, self._cuts
            )
            previous = start
            for row in self._cuts[:n_cuts]:
                cut = start + int(row[0])
                self._open += buf[previous * self._word_bytes : cut * self._word_bytes]
                packets.append(self._packet(row))
                self._open_preamble = self._preamble(row)
                self._open_loops = int(row[6])
                previous = cut
            self._open += buf[previous * self._word_bytes : (start + done) * self._word_bytes]
            start += done
        return packets

    def flush(self) -> list[Packet]:
        """End of stream: the open packet (its horizon its last time), if it holds anything."""
        if not self._open and not self._open_preamble:
            return []
        state = self._state
        row = np.zeros(N_CUT_FIELDS, dtype=np.int64)
        row[1] = max(int(state[4]), self.horizon_us - self.t_offset_us)
        row[2], row[3], row[4], row[5] = state[6], state[7], state[8], state[9]
        packet = self._packet(row)
        self._open_preamble = b""
        return [packet] if packet.n_events or packet.n_triggers or len(packet.data) > packet.preamble_bytes else []

    def _packet(self, row: np.ndarray) -> Packet:
        body = bytes(self._open)
        self._open.clear()
        horizon = max(int(row[1]) + self.t_offset_us, self.horizon_us)
        self.horizon_us = horizon
        first = int(row[5]) + self.t_offset_us if row[5] >= 0 else horizon
        return Packet(
            data=self._open_preamble + body,
            t_first_us=min(first, horizon),
            t_last_us=horizon,
            n_events=int(row[2]),
            n_on=int(row[3]),
            n_triggers=int(row[4]),
            t_offset_us=self.t_offset_us + self._open_loops * LOOP_US[self.encoding],
            preamble_bytes=len(self._open_preamble),
        )

    def _preamble(self, row: np.ndarray) -> bytes:
        """The state words that make the packet starting at this cut decodable alone."""
        high, low, row_word, vector = (int(v) for v in row[7:11])
        if high < 0:
            return b""
        if self.encoding == "evt2":
            return np.array([(0x8 << 28) | high], dtype="<u4").tobytes()
        words = [0x8000 | high]
        if low >= 0:
            words.append(0x6000 | low)
        if row_word >= 0:
            words.append(row_word)
        if vector >= 0:
            words.append(0x3000 | vector)
        return np.array(words, dtype="<u2").tobytes()
