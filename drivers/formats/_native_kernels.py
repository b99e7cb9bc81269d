"""Word scans that cut a camera's own EVT 2.0/3.0 stream into packets without decoding its events.

Each scan walks the words once, follows only the state a decoder needs to start mid-stream (the
time base and its loops, the time, and for EVT 3.0 the row word and the vector base) and counts
events, ON events and triggers. It cuts before the first word whose time reaches a later slot of
``slot_us`` (by the running maximum of the time, as the packetizer does), or before an event word
once the open packet holds ``max_events``. For every cut it writes one row of ``cuts``:

    0 word index of the cut, 1 horizon of the packet it closes (µs), 2 events, 3 ON events,
    4 triggers, 5 first time of the packet closed (µs, -1 if none), 6 loops of the time base at
    the cut, 7-10 the state words that make the next packet decodable alone (-1: none): TIME_HIGH,
    TIME_LOW, row word (EVT_ADDR_Y/EM_ADDR_Y), VECT_BASE_X (EVT 2.0: TIME_HIGH only).

Scan state (int64[16]): 0 base set, 1 base µs (loops included), 2 loops, 3 time µs, 4 running
maximum of the time, 5 open packet's slot, 6 events, 7 ON, 8 triggers, 9 first time, 10 row word,
11 vector x base, 12 vector polarity, 13 vector base seen, 14 CD mode (EVT 3.0).
Times are the decoders' (OpenEB's rules), without ``t_offset`` (a file's ``% t_offset_us``): see
``_evt3_kernels``/``_evt2_kernels``; slots are of the times plus ``t_offset``.
"""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.jit import njit
from flagtrack.drivers.formats._timebase import unwrap_threshold

N_CUT_FIELDS = 11


@njit(cache=True, nogil=True)
def _close(state, cuts, k, i, horizon, loop_us, raw_shift):
    """Write cut row ``k`` at word ``i`` and start a new open packet."""
    cuts[k, 0] = i
    cuts[k, 1] = horizon
    cuts[k, 2] = state[6]
    cuts[k, 3] = state[7]
    cuts[k, 4] = state[8]
    cuts[k, 5] = state[9]
    cuts[k, 6] = state[2]
    if state[0]:
        cuts[k, 7] = (state[1] - state[2] * loop_us) >> raw_shift
        low = state[3] - state[1]
        cuts[k, 8] = low if 0 <= low < 4096 else -1
    else:
        cuts[k, 7] = -1
        cuts[k, 8] = -1
    cuts[k, 9] = state[10]
    cuts[k, 10] = ((state[12] << 11) | (state[11] & 0x7FF)) if state[13] else -1
    state[6] = 0
    state[7] = 0
    state[8] = 0
    state[9] = -1


@njit(cache=True, nogil=True)
def _time_step(state, cuts, k, i, t, slot_us, t_offset, max_cuts, loop_us, raw_shift):
    """The time becomes ``t`` at word ``i``: cut there if it opens a later slot (slots of the time
    plus ``t_offset``). Returns (k, full)."""
    latest = max(state[4], t)
    slot = (latest + t_offset) // slot_us
    if slot > state[5]:
        if state[5] >= 0:
            if k >= max_cuts:
                return k, True
            _close(state, cuts, k, i, slot * slot_us - 1 - t_offset, loop_us, raw_shift)
            k += 1
        state[5] = slot
    state[4] = latest
    state[3] = t
    return k, False


@njit(cache=True, nogil=True)
def scan_evt3(words, state, slot_us, t_offset, max_events, cuts):
    """Scan EVT 3.0 ``words`` (uint16) from ``state``; return (words consumed, cuts written)."""
    loop_us = 1 << 24
    max_cuts = cuts.shape[0]
    k = 0
    i = 0
    nw = len(words)
    while i < nw:
        w = np.int64(words[i])
        typ = w >> 12
        if typ == 8:
            base, n_loop = unwrap_threshold(state[1], state[2], w & 0xFFF, 12, 12)
            if state[0] == 0:
                state[0] = 1
            state[1] = base
            state[2] = n_loop
            k, full = _time_step(state, cuts, k, i, base, slot_us, t_offset, max_cuts, loop_us, 12)
            if full:
                break
        elif state[0] == 0:
            pass  # decoders skip every word before the first TIME_HIGH
        elif typ == 6:
            k, full = _time_step(state, cuts, k, i, state[1] + (w & 0xFFF), slot_us, t_offset, max_cuts, loop_us, 12)
            if full:
                break
        elif typ == 0 or typ == 1:
            state[10] = w
            state[14] = 1 if typ == 0 else 0
        elif typ == 3:
            state[11] = w & 0x7FF
            state[12] = (w >> 11) & 1
            state[13] = 1
        elif typ == 2 or typ == 4 or typ == 5:
            if state[14]:
                if state[6] >= max_events and state[5] >= 0:
                    if k >= max_cuts:
                        break
                    _close(state, cuts, k, i, state[4] - 1, loop_us, 12)
                    k += 1
                if typ == 2:
                    state[6] += 1
                    state[7] += (w >> 11) & 1
                else:
                    nbits = 12 if typ == 4 else 8
                    mask = w & ((1 << nbits) - 1)
                    count = 0
                    while mask:
                        mask &= mask - 1
                        count += 1
                    state[6] += count
                    state[7] += count * state[12]
                if state[9] < 0:
                    state[9] = state[3]
            if typ == 4:
                state[11] += 12
            elif typ == 5:
                state[11] += 8
        elif typ == 10:
            state[8] += 1
        i += 1
    return i, k


@njit(cache=True, nogil=True)
def scan_evt2(words, state, slot_us, t_offset, max_events, cuts):
    """Scan EVT 2.0 ``words`` (uint32) from ``state``; return (words consumed, cuts written)."""
    loop_us = 1 << 34
    max_cuts = cuts.shape[0]
    k = 0
    i = 0
    nw = len(words)
    while i < nw:
        w = np.int64(words[i])
        typ = w >> 28
        if typ == 8:
            base, n_loop = unwrap_threshold(state[1], state[2], w & 0xFFFFFFF, 6, 28)
            if state[0] == 0:
                state[0] = 1
            state[1] = base
            state[2] = n_loop
            k, full = _time_step(state, cuts, k, i, base, slot_us, t_offset, max_cuts, loop_us, 6)
            if full:
                break
            state[3] = base
        elif state[0] == 0:
            pass
        elif typ <= 1 or typ == 10:
            t = state[1] + ((w >> 22) & 63)
            if typ <= 1 and state[6] >= max_events and state[5] >= 0:
                if k >= max_cuts:
                    break
                _close(state, cuts, k, i, state[4] - 1, loop_us, 6)
                k += 1
            k, full = _time_step(state, cuts, k, i, t, slot_us, t_offset, max_cuts, loop_us, 6)
            if full:
                break
            state[3] = state[1]  # an EVT 2.0 time low belongs to its word only
            if typ <= 1:
                state[6] += 1
                state[7] += typ
                if state[9] < 0:
                    state[9] = t
            else:
                state[8] += 1
        i += 1
    return i, k
