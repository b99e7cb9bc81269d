"""Compiled batch encoding of self-contained packets (one call for every packet a push closes).

Each packet is encoded exactly as a fresh :class:`~flagtrack.drivers.formats.codec.Encoder` would
encode it, with the time offset of the loop holding its earliest event or trigger; doing them all in
one compiled call removes the per-packet Python work (encoder set-up, buffers, column checks), which
cost more than the encoding itself on 1 ms packets.
"""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.jit import njit
from flagtrack.drivers.formats._evt2_kernels import encode_evt2
from flagtrack.drivers.formats._evt3_kernels import encode_evt3
from flagtrack.drivers.formats._timebase import OK


@njit(cache=True, nogil=True)
def packet_words(n_events: np.ndarray, n_triggers: np.ndarray) -> int:
    """Words of output room for packets of these sizes (the encoder's usual bound; time jumps of
    several loops or jitter across time-base steps can need more)."""
    total = 0
    for q in range(len(n_events)):
        total += 3 * n_events[q] + 4 * n_triggers[q] + 64
    return total


@njit(cache=True, nogil=True)
def encode_packets(
    evt3,
    t,
    x,
    y,
    p,
    starts,
    stops,
    horizons,
    tr_t,
    tr_c,
    tr_e,
    tr_starts,
    tr_stops,
    loop_us,
    width,
    height,
    out,
    out_ends,
    t_offsets,
    n_on,
):
    """Encode packet q from events ``starts[q]:stops[q]`` and triggers ``tr_starts[q]:tr_stops[q]``.

    Packet q's words are ``out[out_ends[q-1]:out_ends[q]]``; its time offset is the start of the
    ``loop_us`` loop of its earliest time (``horizons[q]`` if it is empty), and ``n_on`` counts its
    ON events (both set even for a packet that fails). Returns (packets encoded, status): on another
    status than OK, packet ``packets encoded`` failed: it did not fit ``out`` (sized by
    :func:`packet_words`, which rare streams exceed) or holds a bad event; the caller encodes it
    alone with an encoder that grows its output and names bad events.
    """
    state = np.zeros(16, dtype=np.int64)
    k0 = 0
    for q in range(len(starts)):
        i0, i1, j0, j1 = starts[q], stops[q], tr_starts[q], tr_stops[q]
        t_events = horizons[q]  # the earliest event (the horizon if none), then trigger
        t_triggers = horizons[q]
        on = 0
        for i in range(i0, i1):
            t_events = min(t_events, t[i]) if i > i0 else t[i]
            on += 1 if p[i] != 0 else 0
        for j in range(j0, j1):
            t_triggers = min(t_triggers, tr_t[j]) if j > j0 else tr_t[j]
        t_first = min(t_events, t_triggers)
        offset = (max(t_first, 0) // loop_us) * loop_us
        t_offsets[q] = offset
        n_on[q] = on
        if i1 > i0 or j1 > j0:
            state[:] = 0
            state[2] = -1
            if evt3:
                _, _, k, status = encode_evt3(
                    t[i0:i1],
                    x[i0:i1],
                    y[i0:i1],
                    p[i0:i1],
                    0,
                    tr_t[j0:j1],
                    tr_c[j0:j1],
                    tr_e[j0:j1],
                    0,
                    state,
                    out[k0:],
                    offset,
                    width,
                    height,
                )
            else:
                _, _, k, status = encode_evt2(
                    t[i0:i1],
                    x[i0:i1],
                    y[i0:i1],
                    p[i0:i1],
                    0,
                    tr_t[j0:j1],
                    tr_c[j0:j1],
                    tr_e[j0:j1],
                    0,
                    state,
                    out[k0:],
                    offset,
                    width,
                    height,
                )
            if status != OK:
                return q, status
            k0 += k
        out_ends[q] = k0
    return len(starts), OK


@njit(cache=True, nogil=True)
def slot_runs(t, running_max, packet_us, run_starts, run_slots, run_maxima):
    """Cut events into runs of one packet slot: slot = (running maximum of t) // ``packet_us``.

    ``running_max`` is the maximum before ``t[0]`` (small steps back in time stay in the slot of the
    latest time). Writes run q's first index, slot and running maximum at its last event; returns
    the number of runs.
    """
    n_runs = 0
    slot_end = running_max  # the running maximum only grows: a new slot starts when it reaches slot_end
    for i in range(len(t)):
        before = running_max
        running_max = max(running_max, t[i])
        if n_runs == 0 or running_max >= slot_end:  # one division per run, not per event
            s = running_max // packet_us
            slot_end = (s + 1) * packet_us
            if n_runs > 0:
                run_maxima[n_runs - 1] = before
            run_starts[n_runs] = i
            run_slots[n_runs] = s
            n_runs += 1
    if n_runs > 0:
        run_maxima[n_runs - 1] = running_max
    return n_runs
