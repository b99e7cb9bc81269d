"""EVT 2.0 and EVT 2.1 word loops (numba).

EVT 2.0: little-endian 32-bit words, type in bits 28-31: CD_OFF 0x0 / CD_ON 0x1 (time low 6 bits
22-27, x bits 11-21, y bits 0-10), EV_TIME_HIGH 0x8 (time bits 6-33 in bits 0-27), EXT_TRIGGER 0xA
(time low bits 22-27, channel bits 8-12, edge bit 0), OTHERS 0xE, CONTINUED 0xF; other types are
reserved. Semantics follow OpenEB's standalone EVT 2.0 decoder: words before the first TIME_HIGH
are skipped, t = base + low, and the 34-bit base is unwrapped with OpenEB's threshold rule.

EVT 2.1: 64-bit words made of two 32-bit halves. The high half holds what an EVT 2.0 word holds
(type, time low, x, y; TIME_HIGH and EXT_TRIGGER as in EVT 2.0) and the low half a 32-bit validity
mask: bit b set means an event at x + b. In the default ("little") layout the low half comes
first in the file; in the "legacy" layout (IMX636 EVKs, ``endianness=legacy``) the high half
comes first. The caller passes the two halves as separate strided views, so one kernel serves
both. Time wraps follow OpenEB's EVT 2.1 decoder (a wrap only from the maximum to zero).

Decoder state (int64[16]): 0 base set, 1 base µs, 2 loops. Encoder state: 0 started, 1 base µs.
"""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.jit import njit
from flagtrack.drivers.formats._timebase import (
    BAD_VALUE,
    BAD_WORD,
    FULL,
    NEGATIVE_TIME,
    OK,
    OUT_OF_SENSOR,
    TIME_JUMP_BACK,
    next_high_step,
    step_back_allowed,
    unwrap_threshold,
)


@njit(cache=True, nogil=True)
def _reserved_evt2(typ: int) -> bool:
    return (2 <= typ <= 7) or typ == 9 or (11 <= typ <= 13)


@njit(cache=True, nogil=True)
def _skip_to_time_high(high, i, shift):
    """OpenEB skips every word before the first TIME_HIGH: (index of it or len, status)."""
    while i < len(high):
        typ = (np.int64(high[i]) >> shift) & 0xF
        if typ == 8:
            return i, OK
        if _reserved_evt2(typ):
            return i, BAD_WORD
        i += 1
    return i, OK


@njit(cache=True, nogil=True)
def decode_evt2(words, start, state, tt, xyp, tr, width, height, t_offset):
    """Decode ``words[start:]`` into events (``tt``/``xyp`` views, see the EVT 3.0 kernel) and triggers.

    Returns (next word, n events, n triggers, status).
    """
    base_set = state[0]
    base = state[1] + t_offset
    n_loop = state[2]
    n = 0
    nt = 0
    status = OK
    i = start
    nw = len(words)
    if base_set == 0:
        i, status = _skip_to_time_high(words, i, 28)
        base_set = 1 if i < nw and status == OK else 0
    while i < nw and status == OK:
        limit = min(nw, i + len(tt) - n, i + len(tr) - nt)  # at most one event or trigger a word
        if limit == i:
            status = FULL
            break
        while i < limit:
            w = np.int64(words[i])
            typ = w >> 28
            if typ <= 1:
                x = (w >> 11) & 0x7FF
                y = w & 0x7FF
                if (x >= width) | (y >= height):
                    status = OUT_OF_SENSOR
                    break
                tt[n] = base + ((w >> 22) & 63)
                xyp[n] = x | (y << 16) | (typ << 32)
                n += 1
            elif typ == 8:
                new_base, n_loop = unwrap_threshold(base - t_offset, n_loop, w & 0xFFFFFFF, 6, 28)
                base = new_base + t_offset
            elif typ == 10:
                r = tr[nt]
                r.t = base + ((w >> 22) & 63)
                r.channel = (w >> 8) & 0x1F
                r.edge = w & 1
                nt += 1
            elif _reserved_evt2(typ):
                status = BAD_WORD
                break
            i += 1
    state[0] = base_set
    state[1] = base - t_offset
    state[2] = n_loop
    return i, n, nt, status


@njit(cache=True, nogil=True)
def decode_evt21(high, low, start, state, tt, xyp, tr, width, height, t_offset):
    """Decode EVT 2.1 words from their 32-bit halves; return as :func:`decode_evt2`."""
    base_set = state[0]
    base = state[1]
    n_loop = state[2]
    period = np.int64(1) << 34
    max_base = np.int64((1 << 28) - 1) << 6
    n = 0
    nt = 0
    ev_room = len(tt) - 32
    tr_room = len(tr)
    status = OK
    i = start
    nw = len(high)
    if base_set == 0:
        i, status = _skip_to_time_high(high, i, 28)
    while i < nw and status == OK:
        if n > ev_room or nt >= tr_room:
            status = FULL
            break
        w = np.int64(high[i])
        typ = w >> 28
        if typ <= 1:
            x = (w >> 11) & 0x7FF
            y = w & 0x7FF
            t = base + ((w >> 22) & 63) + t_offset
            valid = np.int64(low[i])
            k = 0
            for b in range(32):
                if (valid >> b) & 1:
                    tt[n + k] = t
                    xyp[n + k] = (x + b) | (y << 16) | (typ << 32)
                    k += 1
                    if x + b >= width:
                        status = OUT_OF_SENSOR
            if y >= height:
                status = OUT_OF_SENSOR
            if status != OK:
                break
            n += k
        elif typ == 8:
            new_high = (w & 0xFFFFFFF) << 6
            last_high = base - n_loop * period
            if new_high < last_high and last_high - new_high >= max_base:
                n_loop += 1
            base = new_high + n_loop * period
            base_set = 1
        elif typ == 10:
            r = tr[nt]
            r.t = base + ((w >> 22) & 63) + t_offset
            r.channel = (w >> 8) & 0x1F
            r.edge = w & 1
            nt += 1
        elif _reserved_evt2(typ):
            status = BAD_WORD
            break
        i += 1
    state[0] = base_set
    state[1] = base
    state[2] = n_loop
    return i, n, nt, status


@njit(cache=True, nogil=True)
def encode_evt2(ev_t, ev_x, ev_y, ev_p, i, tr_t, tr_c, tr_e, j, state, out, t_offset, width, height):
    """Encode events from ``i`` and triggers from ``j`` (merged by time) as EVT 2.0 into ``out``.

    Returns (next event, next trigger, words written, status) as the EVT 3.0 encoder does.
    """
    started = state[0]
    cur = state[1]
    n_ev = len(ev_t)
    n_tr = len(tr_t)
    cap = len(out) - 4
    k = 0
    status = OK
    while i < n_ev or j < n_tr:
        if k > cap:
            status = FULL
            break
        is_trigger = j < n_tr and (i >= n_ev or tr_t[j] < ev_t[i])
        t = tr_t[j] if is_trigger else ev_t[i]
        target = t - t_offset
        if target < 0:
            status = NEGATIVE_TIME
            break
        units = target >> 6
        if started == 0 or units != cur >> 6:
            if started and units < cur >> 6 and not step_back_allowed(cur >> 6, units, 28):
                status = TIME_JUMP_BACK
                break
            while (started == 0 or units != cur >> 6) and k <= cap:
                step = next_high_step(cur >> 6, started, units, 28)
                out[k] = 0x80000000 | (step & 0xFFFFFFF)
                k += 1
                cur = step << 6
                started = 1
            if units != cur >> 6:
                status = FULL
                break
        low = target & 63
        if is_trigger:
            if tr_c[j] > 31 or tr_e[j] > 1:
                status = BAD_VALUE
                break
            out[k] = 0xA0000000 | (low << 22) | (np.int64(tr_c[j]) << 8) | tr_e[j]
            k += 1
            j += 1
            continue
        x = np.int64(ev_x[i])
        y = np.int64(ev_y[i])
        p = np.int64(ev_p[i])
        if x >= width or y >= height or p > 1:
            status = BAD_VALUE
            break
        out[k] = (p << 28) | (low << 22) | (x << 11) | y
        k += 1
        i += 1
    state[0] = started
    state[1] = cur
    return i, j, k, status
