"""What the fake camera SDKs stream (tests only): a flapping line as events, encoded as real EVT bytes.

The fake modules (``neuromorphic_drivers``, ``metavision_hal``, ``dv_processing``) import this file
as a top-level module (``tests/fakes`` is put on ``sys.path`` by the fixtures).
"""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.events import TRIGGER_DTYPE
from flagtrack.drivers.formats import make_encoder
from flagtrack.drivers.sim.quickline import QuickLineParams, WavyFlag, line_events


def flapping_source(
    width: int,
    height: int,
    duration_us: int,
    seed: int = 0,
    noise_rate_hz: float = 20_000.0,
    trigger_period_us: int = 10_000,
) -> tuple[np.ndarray, np.ndarray]:
    """Events of a flag flapping across the sensor plus noise, and external-trigger edges (channel 0).

    Returns:
        (events EVENT_DTYPE, triggers TRIGGER_DTYPE), time-sorted, times from 0 µs.
    """
    flag = WavyFlag(length=0.45 * width, root=(0.2 * width, 0.5 * height), frequency_hz=15.0)
    params = QuickLineParams(events_per_px2=1.0, noise_rate_hz=noise_rate_hz)
    events = np.concatenate(list(line_events(flag, 0, duration_us, width, height, params, seed=seed)))
    t = np.arange(trigger_period_us // 2, duration_us, trigger_period_us // 2, dtype=np.int64)
    triggers = np.zeros(len(t), dtype=TRIGGER_DTYPE)
    triggers["t"] = t
    triggers["edge"] = np.arange(len(t)) % 2 == 0
    return events, triggers


def encode(
    encoding: str, events: np.ndarray, triggers: np.ndarray, width: int, height: int, legacy: bool = False
) -> bytes:
    """The byte stream a camera in ``encoding`` (evt3, evt2, evt21) sends for these events (time offset 0).

    ``legacy``: EVT 2.1 in the IMX636 layout (the 32-bit halves of each word swapped).
    """
    if encoding == "evt21":
        return encode_evt21(events, triggers, legacy)
    encoder = make_encoder(encoding, t_offset_us=0, width=width, height=height)
    return encoder.encode(events, triggers)


def encode_evt21(events: np.ndarray, triggers: np.ndarray, legacy: bool = False) -> bytes:
    """EVT 2.1: TIME_HIGH words, one single-pixel vector per event, trigger words (little or legacy layout)."""
    t = np.concatenate([events["t"], triggers["t"]])
    kind = np.concatenate([np.zeros(len(events), np.uint8), np.ones(len(triggers), np.uint8)])
    index = np.concatenate([np.arange(len(events)), np.arange(len(triggers))])
    order = np.lexsort((kind, t))  # stable in time; events before triggers at equal times
    words, last_high = [], -1
    for i in order:
        ti = int(t[i])
        if ti >> 6 != last_high:
            last_high = ti >> 6
            words.append(((0x8 << 28) | (last_high & 0xFFFFFFF), 0))
        low_t = ti & 63
        if kind[i] == 0:
            e = events[index[i]]
            x, y, p = int(e["x"]), int(e["y"]), int(e["p"])
            high = ((1 if p else 0) << 28) | (low_t << 22) | ((x & ~31) << 11) | y
            words.append((high, 1 << (x & 31)))
        else:
            tr = triggers[index[i]]
            words.append(((0xA << 28) | (low_t << 22) | (int(tr["channel"]) << 8) | int(tr["edge"]), 0))
    out = bytearray()
    for high, low in words:
        first, second = (high, low) if legacy else (low, high)
        out += first.to_bytes(4, "little") + second.to_bytes(4, "little")
    return bytes(out)


class ByteFeed:
    """Hands out a byte stream in buffers of random sizes, cutting words and vectors anywhere.

    Args:
        data: the whole stream.
        seed: random seed of the buffer sizes.
        max_bytes: largest buffer.
        stall_after_bytes: stop delivering (as a camera that stops) after this many bytes.
    """

    def __init__(self, data: bytes, seed: int = 0, max_bytes: int = 6000, stall_after_bytes: int | None = None) -> None:
        self.data = data
        self.rng = np.random.default_rng(seed)
        self.max_bytes = max_bytes
        self.limit = len(data) if stall_after_bytes is None else min(stall_after_bytes, len(data))
        self.delivered = 0

    @property
    def exhausted(self) -> bool:
        return self.delivered >= self.limit

    def next(self) -> bytes | None:
        """The next buffer (1..max_bytes bytes), or None when nothing is left to deliver."""
        if self.exhausted:
            return None
        size = int(self.rng.integers(1, self.max_bytes + 1))
        chunk = self.data[self.delivered : min(self.delivered + size, self.limit)]
        self.delivered += len(chunk)
        return chunk
