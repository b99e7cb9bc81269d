"""Integer CSV rows to and from bytes (numba): 4 comma-separated integers per line."""

from __future__ import annotations

import numpy as np

from flagtrack.daemon.core.jit import njit

OK = 0
FULL = 1
BAD = 2


@njit(cache=True, nogil=True)
def parse_rows(buf, pos, out, n_cols):
    """Parse lines of ``n_cols`` integers from ``buf[pos:]`` into rows of ``out`` (int64, (n, n_cols)).

    Blank lines are skipped, spaces and tabs around numbers and a CR before LF are allowed.
    Returns (position after the last whole line parsed, rows, status, byte index of a fault).
    """
    n = 0
    end = len(buf)
    while pos < end:
        if n >= out.shape[0]:
            return pos, n, FULL, pos
        line_start = pos
        col = 0
        while True:
            while pos < end and (buf[pos] == 32 or buf[pos] == 9):
                pos += 1
            if col == 0 and (pos >= end or buf[pos] == 10 or buf[pos] == 13):
                break  # blank line
            neg = False
            if pos < end and buf[pos] == 45:
                neg = True
                pos += 1
            digits = 0
            value = 0
            while pos < end and 48 <= buf[pos] <= 57 and digits < 19:
                value = value * 10 + (buf[pos] - 48)
                pos += 1
                digits += 1
            if digits == 0 or (pos < end and 48 <= buf[pos] <= 57):
                return line_start, n, BAD, pos
            out[n, col] = -value if neg else value
            col += 1
            while pos < end and (buf[pos] == 32 or buf[pos] == 9):
                pos += 1
            if col < n_cols:
                if pos >= end or buf[pos] != 44:
                    return line_start, n, BAD, pos
                pos += 1
            else:
                break
        if pos < end and buf[pos] == 13:
            pos += 1
        if pos < end and buf[pos] != 10:
            return line_start, n, BAD, pos
        pos += 1
        if col == n_cols:
            n += 1
    return min(pos, end), n, OK, pos


@njit(cache=True, nogil=True)
def _put_int(out, k, value):
    if value < 0:
        out[k] = 45
        k += 1
        value = -value
    start = k
    while True:
        out[k] = 48 + value % 10
        k += 1
        value //= 10
        if value == 0:
            break
    i, j = start, k - 1
    while i < j:
        out[i], out[j] = out[j], out[i]
        i += 1
        j -= 1
    return k


@njit(cache=True, nogil=True)
def format_rows(c0, c1, c2, c3, out):
    """Write rows ``c0,c1,c2,c3\\n`` into ``out`` (uint8, at least 64 bytes a row); return bytes used."""
    k = 0
    for i in range(len(c0)):
        k = _put_int(out, k, np.int64(c0[i]))
        out[k] = 44
        k = _put_int(out, k + 1, np.int64(c1[i]))
        out[k] = 44
        k = _put_int(out, k + 1, np.int64(c2[i]))
        out[k] = 44
        k = _put_int(out, k + 1, np.int64(c3[i]))
        out[k] = 10
        k += 1
    return k
