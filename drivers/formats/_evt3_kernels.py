"""EVT 3.0 word loops (numba): a streaming decoder and a streaming encoder.

EVT 3.0 is a stream of little-endian 16-bit words whose top 4 bits give the type: EVT_ADDR_Y 0x0
(y, sets the CD state), EM_ADDR_Y 0x1, EVT_ADDR_X 0x2 (one event: x, polarity), VECT_BASE_X 0x3
(x base and polarity of the next vectors), VECT_12 0x4 / VECT_8 0x5 (validity masks of 12/8
consecutive pixels from the x base, which then advances by 12/8), EVT_TIME_LOW 0x6 (low 12 bits of
the time), CONTINUED_4 0x7, EVT_TIME_HIGH 0x8 (high 12 bits; the time becomes the new base),
EXT_TRIGGER 0xA (edge bit 0, channel bits 8-11), OTHERS 0xE, CONTINUED_12 0xF; 0x9, 0xB-0xD are
reserved. Semantics follow OpenEB's standalone EVT 3.0 decoder exactly: words before the first
TIME_HIGH are skipped, TIME_LOW sets time = base + low even when that steps back, and the 24-bit
base is unwrapped with OpenEB's threshold rule.

Events are stored through two strided int64 views of the EVENT_DTYPE output (13-byte records):
``tt`` on the time and ``xyp`` on x, y, p (bytes 8-12) plus the first 3 bytes of the next record,
which the next store of ``tt`` overwrites; so one event costs two stores (see ``codec.event_views``).

Decoder state (int64[16]): 0 base set, 1 base µs, 2 loops, 3 current time µs, 4 y, 5 x base,
6 vector polarity, 7 CD (1) or EM (0). Encoder state: 0 started, 1 decoder's time µs, 2 last y.
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

MAX_EVENTS_PER_WORD = 12


@njit(cache=True, nogil=True)
def decode_evt3(words, start, state, tt, xyp, tr, width, height, t_offset):
    """Decode ``words[start:]`` into events (``tt``/``xyp`` views) and triggers ``tr``.

    Returns (next word, n events, n triggers, status).
    """
    base_set = state[0]
    base = state[1]
    n_loop = state[2]
    cur = state[3] + t_offset
    y = state[4]
    x_base = state[5]
    pol = state[6]
    is_cd = state[7]
    n = 0
    nt = 0
    ev_room = len(tt) - MAX_EVENTS_PER_WORD
    tr_room = len(tr)
    status = OK
    i = start
    nw = len(words)
    while base_set == 0 and i < nw:  # OpenEB skips every word before the first TIME_HIGH
        typ = words[i] >> 12
        if typ == 8:
            base_set = 1
        elif typ == 9 or typ == 11 or typ == 12 or typ == 13:
            status = BAD_WORD
            break
        else:
            i += 1
    x_limit = width if is_cd else 0  # ADDR_X words count only in CD mode (after EVT_ADDR_Y)
    y_bits = y << 16
    while i < nw and status == OK:
        if n > ev_room or nt >= tr_room:
            status = FULL
            break
        w = np.int64(words[i])
        typ = w >> 12
        if typ == 2:
            x = w & 0x7FF
            if x < x_limit:
                tt[n] = cur
                xyp[n] = x | y_bits | (((w >> 11) & 1) << 32)
                n += 1
            elif is_cd:
                status = OUT_OF_SENSOR
                break
        elif typ == 0:
            y = w & 0x7FF
            y_bits = y << 16
            is_cd = 1
            x_limit = width
            if y >= height:
                status = OUT_OF_SENSOR
                break
        elif typ == 6:
            cur = base + (w & 0xFFF) + t_offset
        elif typ == 3:
            x_base = w & 0x7FF
            pol = (w >> 11) & 1
        elif typ == 4 or typ == 5:
            nbits = 12 if typ == 4 else 8
            mask = w & ((1 << nbits) - 1)
            if is_cd:
                k = 0
                for b in range(nbits):
                    if (mask >> b) & 1:
                        tt[n + k] = cur
                        xyp[n + k] = (x_base + b) | y_bits | (pol << 32)
                        k += 1
                        if x_base + b >= width:
                            status = OUT_OF_SENSOR
                if status != OK:
                    break
                n += k
            x_base += nbits
        elif typ == 8:
            base, n_loop = unwrap_threshold(base, n_loop, w & 0xFFF, 12, 12)
            cur = base + t_offset
        elif typ == 10:
            r = tr[nt]
            r.t = cur
            r.channel = (w >> 8) & 0xF
            r.edge = w & 1
            nt += 1
        elif typ == 1:
            is_cd = 0
            x_limit = 0
        elif typ == 7 or typ == 14 or typ == 15:
            pass
        else:
            status = BAD_WORD
            break
        i += 1
    state[0] = base_set
    state[1] = base
    state[2] = n_loop
    state[3] = cur - t_offset
    state[4] = y
    state[5] = x_base
    state[6] = pol
    state[7] = is_cd
    return i, n, nt, status


@njit(cache=True, nogil=True)
def _vector_run(ev_t, ev_x, ev_y, ev_p, i, n_ev):
    """Length of the run of events from ``i`` that one VECT_12 can carry (same t, y, p; x rising)."""
    j = i + 1
    while (
        j < n_ev
        and j - i < 12
        and ev_t[j] == ev_t[i]
        and ev_y[j] == ev_y[i]
        and ev_p[j] == ev_p[i]
        and ev_x[j] > ev_x[j - 1]
        and np.int64(ev_x[j]) - np.int64(ev_x[i]) < 12
    ):
        j += 1
    return j - i


@njit(cache=True, nogil=True)
def encode_evt3(ev_t, ev_x, ev_y, ev_p, i, tr_t, tr_c, tr_e, j, state, out, t_offset, width, height):
    """Encode events from ``i`` and triggers from ``j`` (merged by time) into ``out``.

    Returns (next event, next trigger, words written, status); on an error status the returned
    indices name the offending element.
    """
    started = state[0]
    cur = state[1]
    last_y = state[2]
    n_ev = len(ev_t)
    n_tr = len(tr_t)
    cap = len(out) - 8
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
        units = target >> 12
        if started == 0 or units != cur >> 12:
            if started and units < cur >> 12 and not step_back_allowed(cur >> 12, units, 12):
                status = TIME_JUMP_BACK
                break
            while (started == 0 or units != cur >> 12) and k <= cap:
                step = next_high_step(cur >> 12, started, units, 12)
                out[k] = 0x8000 | (step & 0xFFF)
                k += 1
                cur = step << 12
                started = 1
            if units != cur >> 12:
                status = FULL
                break
        if target != cur:
            out[k] = 0x6000 | (target & 0xFFF)
            k += 1
            cur = target
        if is_trigger:
            if tr_c[j] > 15 or tr_e[j] > 1:
                status = BAD_VALUE
                break
            out[k] = 0xA000 | (np.int64(tr_c[j]) << 8) | tr_e[j]
            k += 1
            j += 1
            continue
        x = np.int64(ev_x[i])
        y = np.int64(ev_y[i])
        p = np.int64(ev_p[i])
        if x >= width or y >= height or p > 1:
            status = BAD_VALUE
            break
        if y != last_y:
            out[k] = y
            k += 1
            last_y = y
        run = _vector_run(ev_t, ev_x, ev_y, ev_p, i, n_ev)
        if run >= 3:
            mask = np.int64(0)
            for q in range(i, i + run):
                mask |= 1 << (np.int64(ev_x[q]) - x)
            out[k] = 0x3000 | (p << 11) | x
            out[k + 1] = 0x4000 | mask
            k += 2
            i += run
        else:
            out[k] = 0x2000 | (p << 11) | x
            k += 1
            i += 1
    state[0] = started
    state[1] = cur
    state[2] = last_y
    return i, j, k, status
