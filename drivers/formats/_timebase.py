"""Time-base bookkeeping shared by the EVT encoders and decoders (numba kernels).

Prophesee EVT streams carry the high part of the time in TIME_HIGH words of ``raw_bits`` bits
(EVT 2.0/2.1: 28 bits of 64 µs; EVT 3.0: 12 bits of 4096 µs), so the time base wraps every
``2**raw_bits`` units (4 h 46 min for EVT 2.x, 16.777216 s for EVT 3.0). Decoders unwrap it as the
maker's decoders do: a new TIME_HIGH that is lower than the current one by at least
``max - LOOP_THRESHOLD_UNITS`` is a wrap; any smaller step back is kept as the camera sent it.
Encoders therefore cross a wrap only through the raw values ``max`` then ``0``, which every rule
(OpenEB's standalone threshold rule and its EVT 2.1 exact-max rule) reads as one wrap.

Status codes returned by every kernel of this package are defined here.
"""

from __future__ import annotations

from flagtrack.daemon.core.jit import njit

LOOP_THRESHOLD_UNITS = 10
"""OpenEB's LoopThreshold, in TIME_HIGH units."""

OK = 0
"""Every input word (or element) was consumed."""
FULL = 1
"""The output buffer is full; call again from the returned position."""
BAD_WORD = 2
"""Decoder: reserved word type at the returned position."""
OUT_OF_SENSOR = 3
"""Decoder: event outside the sensor geometry at the returned position."""
NEGATIVE_TIME = 4
"""Encoder: time before the stream's time offset."""
TIME_JUMP_BACK = 5
"""Encoder: a step back in time that the format cannot carry (across a wrap, or a whole loop)."""
BAD_VALUE = 6
"""Encoder: coordinate, polarity or trigger channel out of the format's range."""


@njit(cache=True, nogil=True)
def unwrap_threshold(base_us: int, n_loop: int, raw: int, shift: int, raw_bits: int) -> tuple[int, int]:
    """OpenEB standalone rule: return the new (base_us, n_loop) after a TIME_HIGH of value ``raw``."""
    loop_us = 1 << (raw_bits + shift)
    max_base_us = ((1 << raw_bits) - 1) << shift
    new_base = (raw << shift) + n_loop * loop_us
    if base_us > new_base and base_us - new_base >= max_base_us - (LOOP_THRESHOLD_UNITS << shift):
        new_base += loop_us
        n_loop += 1
    return new_base, n_loop


@njit(cache=True, nogil=True)
def next_high_step(cur_units: int, started: int, target_units: int, raw_bits: int) -> int:
    """Absolute time-high units of the next TIME_HIGH word on the way from ``cur`` to ``target``.

    Within one loop the target is reached in one word (forward or back); a forward move into a
    later loop goes through ``max`` of the current loop, then ``0`` of the next, loop by loop.
    """
    period = 1 << raw_bits
    target_loop = target_units >> raw_bits
    if started == 0:
        cur_loop = 0
        cur_raw = -1
    else:
        cur_loop = cur_units >> raw_bits
        cur_raw = cur_units & (period - 1)
    if target_loop == cur_loop:
        return target_units
    if cur_raw != period - 1:
        return cur_loop * period + period - 1
    return (cur_loop + 1) * period


@njit(cache=True, nogil=True)
def step_back_allowed(cur_units: int, target_units: int, raw_bits: int) -> bool:
    """True if moving the time base back from ``cur`` to ``target`` decodes as a step back."""
    if target_units >> raw_bits != cur_units >> raw_bits:
        return False
    max_raw = (1 << raw_bits) - 1
    return cur_units - target_units < max_raw - LOOP_THRESHOLD_UNITS
